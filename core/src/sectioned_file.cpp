#include "heightcast/core/sectioned_file.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <functional>
#include <new>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "heightcast/core/atomic_file.h"
#include "heightcast/core/checksum.h"
#include "heightcast/core/bytes.h"
#include "heightcast/core/error.h"

namespace hc {
namespace {

namespace off {
constexpr size_t major = 8, minor = 10, headerBytes = 12, fileBytes = 16, sectionCount = 60, tableCrc = 120,
                 headerCrc = 124;
}

// Sections from this size on are written past the page cache.
constexpr uint64_t kDirectRunBytes = uint64_t{16} << 20;

uint64_t alignUp(uint64_t v) { return (v + kFileSectionAlign - 1) / kFileSectionAlign * kFileSectionAlign; }

// The block checksum table's own fields (sectioned_file.h).
constexpr uint64_t kBlockTableHead = 8;
constexpr uint64_t kMinBlockBytes = 4096, kMaxBlockBytes = uint64_t{1} << 30;

uint64_t blockCount(uint64_t bytes, uint64_t blockBytes) { return bytes / blockBytes + (bytes % blockBytes != 0); }

}  // namespace

struct SectionedFileReader::Checks {
    struct Section {
        uint64_t blockBytes = 0;  // the whole section for a file without block checksums
        uint64_t blocks = 0;
        const std::byte* crcs = nullptr;  // its block CRCs in the mapping; nullptr: the table CRC, one block
        uint64_t firstBit = 0;            // its first block's bit in `checked`
    };
    std::vector<Section> sections;
    std::unique_ptr<std::atomic<uint64_t>[]> checked;  // one bit per block, set once its CRC matched
    std::atomic<uint64_t> bytesChecked{0};
};

namespace {
std::atomic<bool> heapFiles{false};  // readFilesIntoHeap
}  // namespace

void readFilesIntoHeap(bool on) { heapFiles.store(on, std::memory_order_relaxed); }

MappedFile::MappedFile(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw Error(path + ": no such file");
    if (std::filesystem::is_directory(path, ec)) throw Error(path + ": is a directory, not a file");
    int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw Error(path + ": cannot open for reading: " + std::strerror(errno));
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        ::close(fd);
        throw Error(path + ": not a regular file");
    }
    size_ = static_cast<size_t>(st.st_size);
    if (size_ > 0 && heapFiles.load(std::memory_order_relaxed)) {  // readFilesIntoHeap (the fuzz targets)
        auto* p = static_cast<std::byte*>(::operator new (size_, std::align_val_t{kFileSectionAlign}));
        for (size_t done = 0; done < size_;) {
            const ssize_t n = ::pread(fd, p + done, size_ - done, static_cast<off_t>(done));
            if (n <= 0) {
                ::operator delete (p, std::align_val_t{kFileSectionAlign});
                ::close(fd);
                throw Error(path + ": cannot read");
            }
            done += static_cast<size_t>(n);
        }
        data_ = p;
        heap_ = true;
    } else if (size_ > 0) {
        void* p = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd, 0);
        if (p == MAP_FAILED) {
            int err = errno;
            ::close(fd);
            throw Error(path + ": cannot map into memory: " + std::strerror(err));
        }
        data_ = static_cast<const std::byte*>(p);
    }
    ::close(fd);
}

void MappedFile::releasePages() const {
    if (data_ && !heap_) ::madvise(const_cast<std::byte*>(data_), size_, MADV_DONTNEED);  // advice: nothing if refused
}

void MappedFile::releasePages(uint64_t offset, uint64_t bytes) const {
    const uint64_t page = uint64_t(::sysconf(_SC_PAGESIZE));
    const uint64_t begin = (offset + page - 1) / page * page,
                   end = std::min<uint64_t>(offset + bytes, size_) / page * page;
    if (data_ && !heap_ && end > begin)
        ::madvise(const_cast<std::byte*>(data_) + begin, end - begin, MADV_DONTNEED);  // advice: nothing if refused
}

MappedFile::~MappedFile() {
    if (data_ && heap_)
        ::operator delete (const_cast<std::byte*>(data_), std::align_val_t{kFileSectionAlign});
    else if (data_)
        ::munmap(const_cast<std::byte*>(data_), size_);
}

void SectionedFileReader::fail(uint64_t offset, const std::string& what) const {
    throw Error(path_ + ": at byte offset " + std::to_string(offset) + ": " + what);
}
void SectionedFileReader::failFile(const std::string& what) const { throw Error(path_ + ": " + what); }

SectionedFileReader::SectionedFileReader(const std::string& path, const FileFormat& format)
    : path_(path), map_(std::make_shared<MappedFile>(path)) {
    const auto bytes = map_->bytes();
    const uint64_t size = bytes.size();
    const std::byte* h = bytes.data();
    if (size < kFileHeaderBytes)
        failFile("truncated: " + std::to_string(size) + " bytes, the header alone is " +
                 std::to_string(kFileHeaderBytes) + " (not a " + format.what + " file?)");
    if (std::memcmp(h, format.magic.data(), 8) != 0) fail(0, std::string("bad magic: not a ") + format.what + " file");
    const auto major = bytes::load<uint16_t>(h + off::major);
    minor_ = bytes::load<uint16_t>(h + off::minor);
    const std::string version = std::to_string(major) + "." + std::to_string(minor_);
    if (major > format.major)
        fail(off::major, "format version " + version + " is newer than this reader (" + std::to_string(format.major) +
                             "." + std::to_string(format.minor) + "); upgrade heightcast to read it");
    if (major != format.major) fail(off::major, "unknown format version " + version);
    if (bytes::load<uint32_t>(h + off::headerCrc) != crc32(std::span(h, off::headerCrc)))
        fail(off::headerCrc, "header checksum mismatch (corrupt header)");
    if (bytes::load<uint32_t>(h + off::headerBytes) != kFileHeaderBytes)
        fail(off::headerBytes, "header size " + std::to_string(bytes::load<uint32_t>(h + off::headerBytes)) +
                                   " is not " + std::to_string(kFileHeaderBytes));
    const uint64_t declared = bytes::load<uint64_t>(h + off::fileBytes);
    if (declared != size)
        fail(off::fileBytes, "header declares " + std::to_string(declared) + " bytes but the file has " +
                                 std::to_string(size) + (size < declared ? " (truncated)" : " (trailing data)"));
    const uint32_t count = bytes::load<uint32_t>(h + off::sectionCount);
    const uint64_t tableEnd = kFileHeaderBytes + uint64_t{count} * kFileSectionEntryBytes;
    if (count > 4096 || tableEnd > size)
        fail(off::sectionCount, "section table of " + std::to_string(count) + " entries runs past the end of the file");
    if (bytes::load<uint32_t>(h + off::tableCrc) != crc32(std::span(h + kFileHeaderBytes, tableEnd - kFileHeaderBytes)))
        fail(kFileHeaderBytes, "section table checksum mismatch (corrupt section table)");
    uint64_t cursor = tableEnd;
    std::vector<FileSection> all;
    for (uint32_t s = 0; s < count; ++s) {
        const uint64_t at = entryOffset(s);
        FileSection e;
        e.kind = bytes::load<uint32_t>(h + at);
        e.index = bytes::load<uint32_t>(h + at + 4);
        e.offset = bytes::load<uint64_t>(h + at + 8);
        e.bytes = bytes::load<uint64_t>(h + at + 16);
        e.crc = bytes::load<uint32_t>(h + at + 24);
        if (bytes::load<uint32_t>(h + at + 28) != 0) fail(at + 28, "reserved section-table field is not zero");
        if (e.offset % kFileSectionAlign != 0 || e.offset < cursor || e.offset > size || e.bytes > size - e.offset)
            fail(at + 8, "section " + std::to_string(s) + " (offset " + std::to_string(e.offset) + ", " +
                             std::to_string(e.bytes) + " bytes) is misplaced or runs past the end of the file");
        for (uint64_t p = cursor; p < e.offset; ++p)
            if (h[p] != std::byte{0}) fail(p, "padding byte is not zero");
        bool known = e.kind == kFileBlockChecksumsKind;
        for (uint32_t k : format.knownKinds) known |= k == e.kind;
        if (!known && minor_ <= format.minor) fail(at, "unknown section kind " + std::to_string(e.kind));
        if (e.kind == kFileBlockChecksumsKind && s + 1 != count) fail(at, "block checksums are not the last section");
        cursor = e.offset + e.bytes;
        all.push_back(e);
    }
    if (cursor != size) fail(cursor, "data after the last section");

    // The block checksum table: small, checked whole here; then each section's table CRC must equal its
    // blocks' CRCs combined, so a reader of an older minor (table CRCs) and this one agree on every file.
    const bool hasBlocks = !all.empty() && all.back().kind == kFileBlockChecksumsKind;
    if (!hasBlocks && minor_ >= format.blockChecksumsSince)
        fail(kFileHeaderBytes,
             "format version " + version + " requires a block checksum section, and the file has none");
    checks_ = std::make_unique<Checks>();
    uint64_t bits = 0;
    if (hasBlocks) {
        const FileSection t = all.back();
        all.pop_back();
        const uint64_t tableAt = entryOffset(all.size());
        if (crc32(std::span(h + t.offset, t.bytes)) != t.crc)
            fail(t.offset, "checksum mismatch in the block checksum section (corrupt data)");
        if (t.bytes < kBlockTableHead)
            fail(tableAt + 16, "block checksum section of " + std::to_string(t.bytes) + " bytes is too short");
        blockBytes_ = bytes::load<uint32_t>(h + t.offset);
        if (!std::has_single_bit(blockBytes_) || blockBytes_ < kMinBlockBytes || blockBytes_ > kMaxBlockBytes)
            fail(t.offset, "block size " + std::to_string(blockBytes_) + " is not a power of two from 4 KiB to 1 GiB");
        if (bytes::load<uint32_t>(h + t.offset + 4) != 0)
            fail(t.offset + 4, "reserved block-checksum field is not zero");
        // Each count is at most size / 4 KiB: the sum cannot wrap.
        uint64_t crcBytes = kBlockTableHead;
        for (const FileSection& e : all) crcBytes += 4 * blockCount(e.bytes, blockBytes_);
        if (crcBytes != t.bytes)
            fail(tableAt + 16, "block checksum section holds " + std::to_string(t.bytes) +
                                   " bytes, the sections' blocks need " + std::to_string(crcBytes));
        const std::byte* crcs = h + t.offset + kBlockTableHead;
        for (size_t s = 0; s < all.size(); ++s) {
            const FileSection& e = all[s];
            Checks::Section c{blockBytes_, blockCount(e.bytes, blockBytes_), crcs, bits};
            uint32_t combined = 0;
            for (uint64_t b = 0; b < c.blocks; ++b)
                combined = crc32Combine(combined, bytes::load<uint32_t>(crcs + 4 * b),
                                        std::min(blockBytes_, e.bytes - b * blockBytes_));
            if (combined != e.crc)
                fail(entryOffset(s) + 24,
                     "section " + std::to_string(s) + "'s checksum disagrees with its block checksums");
            crcs += 4 * c.blocks;
            bits += c.blocks;
            checks_->sections.push_back(c);
        }
    } else {
        for (size_t s = 0; s < all.size(); ++s) {
            const FileSection& e = all[s];
            if (e.bytes == 0 && e.crc != 0)
                fail(e.offset, "checksum mismatch in section " + std::to_string(s) + " (corrupt data)");
            checks_->sections.push_back({e.bytes, e.bytes > 0 ? 1u : 0u, nullptr, bits});
            bits += e.bytes > 0;
        }
    }
    checks_->checked = std::make_unique<std::atomic<uint64_t>[]>(bits / 64 + 1);
    sections_ = std::move(all);
}

SectionedFileReader::~SectionedFileReader() = default;

void SectionedFileReader::checkBlock(size_t s, uint64_t b) const {
    const Checks::Section& c = checks_->sections[s];
    const uint64_t bit = c.firstBit + b;
    std::atomic<uint64_t>& word = checks_->checked[bit / 64];
    const uint64_t mask = uint64_t{1} << (bit % 64);
    if (word.load(std::memory_order_acquire) & mask) return;
    const FileSection& e = sections_[s];
    const uint64_t from = b * c.blockBytes, bytes = std::min(c.blockBytes, e.bytes - from);
    const uint32_t want = c.crcs ? bytes::load<uint32_t>(c.crcs + 4 * b) : e.crc;
    if (crc32(map_->bytes().subspan(e.offset + from, bytes)) != want) {
        if (c.crcs)
            fail(e.offset + from, "checksum mismatch in section " + std::to_string(s) + ", block " + std::to_string(b) +
                                      " (" + std::to_string(bytes) + " bytes) (corrupt data)");
        fail(e.offset, "checksum mismatch in section " + std::to_string(s) + " (corrupt data)");
    }
    if (!(word.fetch_or(mask, std::memory_order_acq_rel) & mask))
        checks_->bytesChecked.fetch_add(bytes, std::memory_order_relaxed);
}

std::span<const std::byte> SectionedFileReader::read(const FileSection& s, uint64_t offset, uint64_t bytes) const {
    // std::less: a total order even for a pointer into another reader's table.
    if (sections_.empty() || std::less<const FileSection*>{}(&s, sections_.data()) ||
        std::less<const FileSection*>{}(&sections_.back(), &s))
        failFile("internal error: a section of another file");
    const auto index = static_cast<size_t>(&s - sections_.data());
    if (offset > s.bytes || bytes > s.bytes - offset)
        fail(s.offset, "a read of " + std::to_string(bytes) + " bytes at " + std::to_string(offset) +
                           " runs past section " + std::to_string(index) + " (" + std::to_string(s.bytes) + " bytes)");
    if (bytes > 0) {
        const uint64_t blockBytes = checks_->sections[index].blockBytes;
        for (uint64_t b = offset / blockBytes, last = (offset + bytes - 1) / blockBytes; b <= last; ++b)
            checkBlock(index, b);
    }
    return map_->bytes().subspan(s.offset + offset, bytes);
}

void SectionedFileReader::checkReleasing(const FileSection& s) const {
    const uint64_t chunk = uint64_t(64) << 20;
    for (uint64_t at = 0; at < s.bytes; at += chunk) {
        const uint64_t n = std::min(chunk, s.bytes - at);
        read(s, at, n);
        map_->releasePages(s.offset + at, n);
    }
}

void SectionedFileReader::verifyAll() const {
    for (const FileSection& s : sections_) data(s);
}

uint64_t SectionedFileReader::bytesChecked() const { return checks_->bytesChecked.load(std::memory_order_relaxed); }

struct SectionedFileWriter::Impl {
    Impl(const std::string& p, const FileFormat& f) : out(p), format(f) {}
    AtomicFileWriter out;
    FileFormat format;
    std::vector<FileSection> sections;
    std::vector<uint64_t> written;                 // bytes appended so far, per section
    std::vector<std::vector<uint32_t>> blockCrcs;  // per section: CRC of each complete block so far
    std::vector<uint32_t> partialCrc;              // per section: CRC of its block being appended
    bool blockTable = false;  // the format's minor has block checksums: the writer adds them as a last section
    size_t tableEntries = 0;
    uint64_t end = 0;  // end of the last placed section
};

SectionedFileWriter::SectionedFileWriter(const std::string& path, const FileFormat& format,
                                         std::vector<FileSection> layout, size_t laterSections)
    : impl_(std::make_unique<Impl>(path, format)) {
    impl_->blockTable = format.minor >= format.blockChecksumsSince;
    impl_->tableEntries = layout.size() + laterSections + impl_->blockTable;
    uint64_t cursor = kFileHeaderBytes + impl_->tableEntries * kFileSectionEntryBytes;
    for (FileSection& s : layout) {
        s.offset = alignUp(cursor);
        s.crc = 0;
        cursor = s.offset + s.bytes;
    }
    impl_->end = cursor;
    impl_->sections = std::move(layout);
    impl_->written.assign(impl_->sections.size(), 0);
    impl_->blockCrcs.resize(impl_->sections.size());
    impl_->partialCrc.assign(impl_->sections.size(), 0);
}

SectionedFileWriter::~SectionedFileWriter() = default;
const std::string& SectionedFileWriter::path() const { return impl_->out.path(); }
const FileSection& SectionedFileWriter::section(size_t s) const { return impl_->sections.at(s); }

void SectionedFileWriter::append(size_t s, std::span<const std::byte> bytes) {
    Impl& w = *impl_;
    FileSection& sec = w.sections.at(s);
    if (bytes.size() > sec.bytes - w.written[s])
        throw Error(path() + ": section " + std::to_string(s) + " overflows its declared size");
    // Sections written front to back: a long one past the page cache (AtomicFileWriter::writeRun).
    if (sec.bytes >= kDirectRunBytes)
        w.out.writeRun(s, sec.offset + w.written[s], bytes);
    else
        w.out.writeAt(sec.offset + w.written[s], bytes);
    // Block CRCs as the data passes (the section's own CRC is combined from them at commit).
    while (!bytes.empty()) {
        const uint64_t inBlock = w.written[s] % kFileBlockBytes;
        const size_t take = static_cast<size_t>(std::min<uint64_t>(bytes.size(), kFileBlockBytes - inBlock));
        w.partialCrc[s] = crc32(bytes.first(take), w.partialCrc[s]);
        w.written[s] += take;
        bytes = bytes.subspan(take);
        if (w.written[s] % kFileBlockBytes == 0) {
            w.blockCrcs[s].push_back(w.partialCrc[s]);
            w.partialCrc[s] = 0;
        }
    }
    if (w.written[s] == sec.bytes) w.out.flushRun(s);
}

void SectionedFileWriter::addSection(uint32_t kind, uint32_t index, std::span<const std::byte> bytes) {
    Impl& w = *impl_;
    if (w.sections.size() >= w.tableEntries) throw Error(path() + ": more sections than the table holds");
    FileSection s{kind, index, alignUp(w.end), bytes.size(), 0};
    w.sections.push_back(s);
    w.written.push_back(0);
    w.blockCrcs.emplace_back();
    w.partialCrc.push_back(0);
    w.end = s.offset + s.bytes;
    append(w.sections.size() - 1, bytes);
}

FilePlacement SectionedFileWriter::placement() const {
    return {impl_->out.path(), impl_->out.temporaryPath(), impl_->sections};
}

void SectionedFileWriter::addPieces(std::span<const FilePiece> pieces) {
    Impl& w = *impl_;
    for (const FilePiece& p : pieces) {
        if (p.section >= w.sections.size())
            throw Error(path() + ": a part names section " + std::to_string(p.section) + ", which it does not have");
        const size_t s = p.section;
        const FileSection& sec = w.sections[s];
        if (p.offset != w.written[s])
            throw Error(path() + ": a part of section " + std::to_string(s) + " starts at byte " +
                        std::to_string(p.offset) + ", where " + std::to_string(w.written[s]) +
                        " bytes are written so far");
        if (p.bytes > sec.bytes - w.written[s])
            throw Error(path() + ": section " + std::to_string(s) + " overflows its declared size");
        if (p.bytes == 0 || p.offset % kFileBlockBytes + p.bytes > kFileBlockBytes || p.crc > UINT32_MAX)
            throw Error(path() + ": a part's piece of section " + std::to_string(s) + " at byte " +
                        std::to_string(p.offset) + " is empty, crosses a checksum block or has no CRC-32");
        // As append() does with the bytes themselves.
        w.partialCrc[s] = crc32Combine(w.partialCrc[s], uint32_t(p.crc), p.bytes);
        w.written[s] += p.bytes;
        if (w.written[s] % kFileBlockBytes == 0) {
            w.blockCrcs[s].push_back(w.partialCrc[s]);
            w.partialCrc[s] = 0;
        }
    }
}

std::vector<std::byte> FilePlacement::encode() const {
    std::vector<std::byte> out(24 + path.size() + temporaryPath.size() + 32 * sections.size());
    size_t at = 0;
    auto put = [&](uint64_t v) { bytes::store(out, at, v), at += 8; };
    auto putText = [&](const std::string& t) {
        put(t.size());
        std::memcpy(out.data() + at, t.data(), t.size());
        at += t.size();
    };
    putText(path);
    putText(temporaryPath);
    put(sections.size());
    for (const FileSection& e : sections) {
        bytes::store(out, at, e.kind), bytes::store(out, at + 4, e.index);
        bytes::store(out, at + 8, e.offset), bytes::store(out, at + 16, e.bytes);
        bytes::store(out, at + 24, uint64_t{e.crc});
        at += 32;
    }
    return out;
}

FilePlacement FilePlacement::decode(std::span<const std::byte> in) {
    FilePlacement p;
    size_t at = 0;
    auto need = [&](uint64_t n) {
        if (n > in.size() - at) throw Error("a file placement of " + std::to_string(in.size()) + " bytes is cut short");
    };
    auto get = [&] {
        need(8);
        const uint64_t v = bytes::load<uint64_t>(in.data() + at);
        at += 8;
        return v;
    };
    auto getText = [&] {
        const uint64_t n = get();
        need(n);
        std::string t(reinterpret_cast<const char*>(in.data() + at), n);
        at += n;
        return t;
    };
    p.path = getText();
    p.temporaryPath = getText();
    const uint64_t n = get();
    need(n * 32);
    for (uint64_t k = 0; k < n; ++k, at += 32) {
        FileSection e;
        e.kind = bytes::load<uint32_t>(in.data() + at), e.index = bytes::load<uint32_t>(in.data() + at + 4);
        e.offset = bytes::load<uint64_t>(in.data() + at + 8), e.bytes = bytes::load<uint64_t>(in.data() + at + 16);
        e.crc = uint32_t(bytes::load<uint64_t>(in.data() + at + 24));
        p.sections.push_back(e);
    }
    if (at != in.size()) throw Error("a file placement has " + std::to_string(in.size() - at) + " bytes too many");
    return p;
}

SectionedFilePart::SectionedFilePart(FilePlacement placement) : placement_(std::move(placement)) {
    fd_ = ::open(placement_.temporaryPath.c_str(), O_RDWR | O_CLOEXEC);
    if (fd_ < 0)
        throw Error(placement_.path + ": cannot open the temporary " + placement_.temporaryPath +
                    " that rank 1 writes (" + std::strerror(errno) +
                    "): under mpirun the output's folder must be one that every rank sees");
}

SectionedFilePart::~SectionedFilePart() {
    if (fd_ >= 0) ::close(fd_);  // the temporary is the writer's: it removes it unless it commits
}

void SectionedFilePart::writeAt(size_t s, uint64_t at, std::span<const std::byte> bytes) {
    if (fd_ < 0) throw Error(placement_.path + ": a part written after it was finished");
    if (s >= placement_.sections.size())
        throw Error(placement_.path + ": a part of section " + std::to_string(s) + ", which is not placed");
    const FileSection& sec = placement_.sections[s];
    if (at > sec.bytes || bytes.size() > sec.bytes - at)
        throw Error(placement_.path + ": a part overflows section " + std::to_string(s));
    uint64_t offset = sec.offset + at;
    for (std::span<const std::byte> left = bytes; !left.empty();) {
        const ssize_t n = ::pwrite(fd_, left.data(), left.size(), static_cast<off_t>(offset));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0)
            throw Error(placement_.path + ": write failed (" + placement_.temporaryPath + "): " + std::strerror(errno));
        left = left.subspan(size_t(n));
        offset += uint64_t(n);
    }
    // The CRC of each block's piece; a run that continues the last piece within its block extends it.
    while (!bytes.empty()) {
        const uint64_t inBlock = at % kFileBlockBytes;
        const size_t take = static_cast<size_t>(std::min<uint64_t>(bytes.size(), kFileBlockBytes - inBlock));
        FilePiece* last = pieces_.empty() ? nullptr : &pieces_.back();
        if (last && last->section == s && last->offset + last->bytes == at && inBlock != 0) {
            last->crc = crc32(bytes.first(take), uint32_t(last->crc));
            last->bytes += take;
        } else {
            pieces_.push_back({uint32_t(s), 0, at, take, crc32(bytes.first(take))});
        }
        at += take;
        bytes = bytes.subspan(take);
    }
}

void SectionedFilePart::readAt(size_t s, uint64_t at, std::span<std::byte> out) const {
    if (fd_ < 0) throw Error(placement_.path + ": a part read after it was finished");
    if (s >= placement_.sections.size())
        throw Error(placement_.path + ": a part of section " + std::to_string(s) + ", which is not placed");
    const FileSection& sec = placement_.sections[s];
    if (at > sec.bytes || out.size() > sec.bytes - at)
        throw Error(placement_.path + ": a read past section " + std::to_string(s));
    uint64_t offset = sec.offset + at;
    for (std::span<std::byte> left = out; !left.empty();) {
        const ssize_t n = ::pread(fd_, left.data(), left.size(), static_cast<off_t>(offset));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0)
            throw Error(placement_.path + ": cannot read back " + placement_.temporaryPath + ": " +
                        (n == 0 ? "it ends early" : std::strerror(errno)));
        left = left.subspan(size_t(n));
        offset += uint64_t(n);
    }
}

std::vector<FilePiece> SectionedFilePart::finish() {
    if (fd_ < 0) throw Error(placement_.path + ": a part finished twice");
    const int fd = fd_;
    fd_ = -1;
    const bool synced = ::fsync(fd) == 0;
    const int err = errno;
    if (::close(fd) != 0 || !synced)
        throw Error(placement_.path + ": cannot flush " + placement_.temporaryPath + ": " +
                    std::strerror(synced ? errno : err));
    return std::move(pieces_);
}

void SectionedFileWriter::commit(std::vector<std::byte> header) {
    Impl& w = *impl_;
    const size_t dataSections = w.tableEntries - w.blockTable;
    if (w.sections.size() != dataSections)
        throw Error(path() + ": " + std::to_string(w.sections.size()) + " sections of " + std::to_string(dataSections));
    // Each section's CRC is its block CRCs combined (the last block may be short).
    auto finishBlocks = [&](size_t s) {
        if (w.written[s] != w.sections[s].bytes)
            throw Error(path() + ": section " + std::to_string(s) + " has " + std::to_string(w.written[s]) +
                        " of its " + std::to_string(w.sections[s].bytes) + " bytes");
        if (w.written[s] % kFileBlockBytes != 0) w.blockCrcs[s].push_back(w.partialCrc[s]);
        uint32_t crc = 0;
        for (size_t b = 0; b < w.blockCrcs[s].size(); ++b)
            crc = crc32Combine(crc, w.blockCrcs[s][b],
                               std::min<uint64_t>(kFileBlockBytes, w.written[s] - b * kFileBlockBytes));
        w.sections[s].crc = crc;
    };
    for (size_t s = 0; s < dataSections; ++s) finishBlocks(s);
    if (w.blockTable) {
        std::vector<std::byte> table(8, std::byte{0});
        bytes::store(table, 0, kFileBlockBytes);
        for (size_t s = 0; s < dataSections; ++s)
            for (uint32_t crc : w.blockCrcs[s]) {
                table.resize(table.size() + 4);
                bytes::store(table, table.size() - 4, crc);
            }
        addSection(kFileBlockChecksumsKind, 0, table);
        finishBlocks(dataSections);
    }
    // Zero padding between sections: the gaps were never written (a sparse hole), make them explicit.
    uint64_t cursor = kFileHeaderBytes + w.sections.size() * kFileSectionEntryBytes;
    const std::vector<std::byte> zeros(kFileSectionAlign, std::byte{0});
    for (const FileSection& s : w.sections) {
        if (s.offset > cursor) w.out.writeAt(cursor, std::span(zeros).first(s.offset - cursor));
        cursor = s.offset + s.bytes;
    }
    header.resize(kFileHeaderBytes + w.sections.size() * kFileSectionEntryBytes, std::byte{0});
    std::memcpy(header.data(), w.format.magic.data(), 8);
    bytes::store(header, off::major, w.format.major);
    bytes::store(header, off::minor, w.format.minor);
    bytes::store(header, off::headerBytes, kFileHeaderBytes);
    bytes::store(header, off::fileBytes, cursor);
    bytes::store(header, off::sectionCount, static_cast<uint32_t>(w.sections.size()));
    for (size_t s = 0; s < w.sections.size(); ++s) {
        const size_t at = kFileHeaderBytes + s * kFileSectionEntryBytes;
        bytes::store(header, at, w.sections[s].kind);
        bytes::store(header, at + 4, w.sections[s].index);
        bytes::store(header, at + 8, w.sections[s].offset);
        bytes::store(header, at + 16, w.sections[s].bytes);
        bytes::store(header, at + 24, w.sections[s].crc);
        bytes::store(header, at + 28, uint32_t{0});
    }
    bytes::store(header, off::tableCrc, crc32(std::span(header).subspan(kFileHeaderBytes)));
    bytes::store(header, off::headerCrc, crc32(std::span(header).first(off::headerCrc)));
    w.out.writeAt(0, header);
    w.out.commit();
}

}  // namespace hc
