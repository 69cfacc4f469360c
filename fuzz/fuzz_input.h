// fuzz/fuzz_input.h: what every file-format fuzz target shares.
//
// Crafted files with VALID checksums are the threat (issue 11): a reader that trusts a count because its
// CRC matches is the bug. A fuzzer that mutates bytes almost never keeps the CRCs right, so it would only
// ever test the CRC check. fixContainer() therefore rewrites, before parsing, what the container derives
// from the rest: the declared file size, the block checksums (where their section fits), every section's CRC
// (where its placement is in the file), the section table's CRC and the header CRC. The CRC and size checks themselves
// are covered by the unit tests (every flipped byte, every truncation); the fuzzer explores everything behind them.
#pragma once

#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <algorithm>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "heightcast/core/bytes.h"
#include "heightcast/core/checksum.h"
#include "heightcast/core/sectioned_file.h"

namespace hc::fuzz {

// Every target that includes this reads files into exact-size heap blocks (readFilesIntoHeap), set before the first
// input: AddressSanitizer then sees a read past a file's end.
inline const bool kHeapFiles = (hc::readFilesIntoHeap(true), true);

// A last section of the container's block-checksum kind whose size fits the sections before it gets their
// block CRCs rewritten (its block size and zero field as they are), so mutations reach past the block checks.
inline void fixBlockChecksums(std::vector<std::byte>& b, uint32_t count) {
    if (count == 0) return;
    const uint64_t size = b.size();
    auto entry = [&](uint32_t s, size_t field) {
        return bytes::load<uint64_t>(b.data() + kFileHeaderBytes + size_t{s} * kFileSectionEntryBytes + field);
    };
    const size_t last = kFileHeaderBytes + size_t{count - 1} * kFileSectionEntryBytes;
    if (bytes::load<uint32_t>(b.data() + last) != kFileBlockChecksumsKind) return;
    const uint64_t at = entry(count - 1, 8), length = entry(count - 1, 16);
    if (at > size || length > size - at || length < 8) return;
    const uint64_t blockBytes = bytes::load<uint32_t>(b.data() + at);
    if (blockBytes < 4096 || (blockBytes & (blockBytes - 1)) != 0) return;
    uint64_t need = 8;
    for (uint32_t s = 0; s + 1 < count; ++s) {
        const uint64_t offset = entry(s, 8), n = entry(s, 16);
        if (offset > size || n > size - offset) return;
        need += 4 * ((n + blockBytes - 1) / blockBytes);
    }
    if (need != length) return;
    uint64_t crcAt = at + 8;
    for (uint32_t s = 0; s + 1 < count; ++s)
        for (uint64_t from = 0, offset = entry(s, 8), n = entry(s, 16); from < n; from += blockBytes, crcAt += 4)
            bytes::store<uint32_t>(
                b, crcAt, crc32(std::span<const std::byte>(b.data() + offset + from, std::min(blockBytes, n - from))));
}

// Offsets of the container's header (core/sectioned_file.h).
inline void fixContainer(std::vector<std::byte>& b) {
    if (b.size() < kFileHeaderBytes) return;
    const uint64_t size = b.size();
    bytes::store<uint64_t>(b, 16, size);
    const uint32_t count = bytes::load<uint32_t>(b.data() + 60);
    const uint64_t tableEnd = kFileHeaderBytes + uint64_t{count} * kFileSectionEntryBytes;
    if (count <= 4096 && tableEnd <= size) {
        fixBlockChecksums(b, count);
        for (uint32_t s = 0; s < count; ++s) {
            const size_t at = kFileHeaderBytes + size_t{s} * kFileSectionEntryBytes;
            const uint64_t offset = bytes::load<uint64_t>(b.data() + at + 8),
                           length = bytes::load<uint64_t>(b.data() + at + 16);
            if (offset <= size && length <= size - offset)
                bytes::store<uint32_t>(b, at + 24, crc32(std::span<const std::byte>(b.data() + offset, length)));
        }
        bytes::store<uint32_t>(
            b, 120, crc32(std::span<const std::byte>(b.data() + kFileHeaderBytes, tableEnd - kFileHeaderBytes)));
    }
    bytes::store<uint32_t>(b, 124, crc32(std::span<const std::byte>(b.data(), 124)));
}

// The readers take a path and map the file: an in-memory file (memfd) gives them one without touching a
// disk, reached through /proc/self/fd. One per process; rewritten for every input.
class MemoryFile {
public:
    MemoryFile() : fd_(::memfd_create("hc_fuzz", 0)), path_("/proc/self/fd/" + std::to_string(fd_)) {
        if (fd_ < 0) std::abort();
    }
    const std::string& write(std::span<const std::byte> bytes) {
        if (::ftruncate(fd_, 0) != 0 ||
            ::pwrite(fd_, bytes.data(), bytes.size(), 0) != static_cast<ssize_t>(bytes.size()))
            std::abort();
        return path_;
    }

private:
    int fd_;
    std::string path_;
};

}  // namespace hc::fuzz
