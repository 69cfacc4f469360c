// The .hci influence cache, format 1.1 (reads 1.0): a sectioned container (core/sectioned_file.h) with
//
//   offset  size  field
//   0       8     magic "\x89HCINFL\n"
//   24      8     cell count n
//   32      8     entry count m
//   40      8     grid structure hash (Grid::structureHash): the key; a cache of another tree is refused
//   48      8     grid content hash (Grid::contentHash) of the grid it was built from: informative
//   56      4     kernel id (kernel.h)
//   64      8     sigma, double
//   72      8     truncation R, double
//   80      4     longest list
//   84      36    reserved, zero
//
// Sections: OFFSETS (kind 1: u64[n + 1], offsets[0] = 0, non-decreasing, offsets[n] = m) and
// INDICES (kind 2: u32[m], each < n, every cell in its own list). Both mmap-ready (64-byte aligned).
//
// Versions: 1.0 the layout above; 1.1 adds the container's block checksums (a CRC-32 per 1 MiB,
// sectioned_file.h), which a reader that reads part of a cache checks for just that part.
#include <cstring>
#include <filesystem>

#include "heightcast/core/bytes.h"
#include "heightcast/core/error.h"
#include "heightcast/core/sectioned_file.h"
#include "file_layouts.h"
#include "heightcast/influence/influence.h"

namespace hc::influence {
namespace {

enum : uint32_t { kOffsets = 1, kIndices = 2 };
const FileFormat kFormat{{'\x89', 'H', 'C', 'I', 'N', 'F', 'L', '\n'},
                         1,
                         1,
                         "heightcast influence cache (.hci)",
                         {kOffsets, kIndices},
                         /*blockChecksumsSince=*/1};

namespace off {
constexpr size_t cellCount = 24, entryCount = 32, structureHash = 40, contentHash = 48, kernelId = 56, sigma = 64,
                 truncation = 72, longest = 80, reserved = 84, reservedEnd = 120;
}

std::string hex(uint64_t v) {
    char b[24];
    std::snprintf(b, sizeof b, "%016llx", static_cast<unsigned long long>(v));
    return b;
}

}  // namespace

namespace detail {

const FileFormat& influenceCacheFormat() { return kFormat; }

std::vector<FileSection> influenceCacheLayout(uint64_t cells, uint64_t entries) {
    return {{kOffsets, 0, 0, (cells + 1) * 8, 0}, {kIndices, 0, 0, entries * 4, 0}};
}

std::vector<std::byte> influenceCacheHeader(uint64_t cells, uint64_t entries, uint64_t longest,
                                            const KernelParams& params, uint64_t structureHash, uint64_t contentHash) {
    std::vector<std::byte> head(kFileHeaderBytes, std::byte{0});
    bytes::store(head, off::cellCount, cells);
    bytes::store(head, off::entryCount, entries);
    bytes::store(head, off::structureHash, structureHash);
    bytes::store(head, off::contentHash, contentHash);
    bytes::store(head, off::kernelId, params.kernelId);
    bytes::store(head, off::sigma, params.sigma);
    bytes::store(head, off::truncation, params.truncation);
    bytes::store(head, off::longest, static_cast<uint32_t>(longest));
    return head;
}

}  // namespace detail

void writeInfluenceCache(const InfluenceLists& lists, const std::string& path) {
    const auto offsets = lists.offsets();
    const auto indices = lists.indices();
    SectionedFileWriter out(path, kFormat, detail::influenceCacheLayout(lists.cellCount(), lists.entryCount()));
    out.append(0, std::as_bytes(offsets));
    out.append(1, std::as_bytes(indices));
    out.commit(detail::influenceCacheHeader(lists.cellCount(), lists.entryCount(), lists.stats().maxLength,
                                            lists.params(), lists.gridStructureHash(), lists.gridContentHash()));
}

InfluenceLists readInfluenceCache(const std::string& path, const Grid& grid, const KernelParams& params) {
    SectionedFileReader file(path, kFormat);
    file.verifyAll();  // the whole cache is walked below: every checksum first, as before block checksums
    const std::byte* h = file.header();
    for (size_t i = off::reserved; i < off::reservedEnd; ++i)
        if (h[i] != std::byte{0}) file.fail(i, "reserved header byte is not zero");
    const uint64_t n = bytes::load<uint64_t>(h + off::cellCount), m = bytes::load<uint64_t>(h + off::entryCount);
    KernelParams stored;
    stored.kernelId = bytes::load<uint32_t>(h + off::kernelId);
    stored.sigma = bytes::load<double>(h + off::sigma);
    stored.truncation = bytes::load<double>(h + off::truncation);
    const uint64_t structure = bytes::load<uint64_t>(h + off::structureHash),
                   content = bytes::load<uint64_t>(h + off::contentHash);
    // Declared counts against the bytes present, before any size is computed from them (issue 11: 2^62
    // entries times 4 wrapped to 0, passed the section size check, and the list walk read past the file).
    const uint64_t fileBytes = file.mapping()->bytes().size();
    if (n >= fileBytes / 8)
        file.fail(off::cellCount, "header declares " + std::to_string(n) + " cells, more than the " +
                                      std::to_string(fileBytes) + "-byte file holds (8 bytes of OFFSETS each)");
    if (m > fileBytes / 4)
        file.fail(off::entryCount, "header declares " + std::to_string(m) + " entries, more than the " +
                                       std::to_string(fileBytes) + "-byte file holds (4 bytes of INDICES each)");

    // Whose cache is it? Say exactly what differs.
    if (structure != grid.structureHash() || n != grid.cellCount())
        throw Error(path + ": stale or foreign cache: built for a grid of " + std::to_string(n) +
                    " cells with structure hash " + hex(structure) + ", this grid has " +
                    std::to_string(grid.cellCount()) + " cells and " + hex(grid.structureHash()));
    if (stored.kernelId != params.kernelId)
        throw Error(path + ": cache built for kernel " + std::to_string(stored.kernelId) + ", wanted " +
                    std::to_string(params.kernelId));
    if (stored.sigma != params.sigma || stored.truncation != params.truncation)
        throw Error(path + ": cache built for sigma " + std::to_string(stored.sigma) + ", R " +
                    std::to_string(stored.truncation) + "; wanted sigma " + std::to_string(params.sigma) + ", R " +
                    std::to_string(params.truncation));

    const FileSection* offs = nullptr;
    const FileSection* idx = nullptr;
    for (const FileSection& s : file.sections()) {
        if (s.kind == kOffsets) offs = &s;
        if (s.kind == kIndices) idx = &s;
    }
    if (!offs || !idx) file.failFile("lacks its OFFSETS or INDICES section");
    // n and m are bounded by the file size above: these products cannot wrap.
    if (offs->bytes != (n + 1) * 8)
        file.fail(offs->offset,
                  "OFFSETS holds " + std::to_string(offs->bytes) + " bytes, expected " + std::to_string((n + 1) * 8));
    if (idx->bytes != m * 4)
        file.fail(idx->offset,
                  "INDICES holds " + std::to_string(idx->bytes) + " bytes, expected " + std::to_string(m * 4));
    // 64-byte aligned in a page-aligned mapping: the spans are properly aligned for u64 and u32.
    std::span<const uint64_t> o(reinterpret_cast<const uint64_t*>(file.data(*offs).data()), n + 1);
    std::span<const uint32_t> ix(reinterpret_cast<const uint32_t*>(file.data(*idx).data()), m);
    if (o[0] != 0 || o[n] != m) file.fail(offs->offset, "OFFSETS do not start at 0 and end at the entry count");
    for (uint64_t k = 0; k < n; ++k) {
        if (o[k + 1] < o[k]) file.fail(offs->offset + 8 * (k + 1), "OFFSETS decrease at cell " + std::to_string(k));
        // o[n] == m alone does not bound the lists before it (0, 100, 5 with m = 5 would read 95 indices past the end).
        if (o[k + 1] > m)
            file.fail(offs->offset + 8 * (k + 1),
                      "OFFSETS exceed the entry count " + std::to_string(m) + " at cell " + std::to_string(k));
        bool self = false;
        for (uint64_t e = o[k]; e < o[k + 1]; ++e) {
            if (ix[e] >= n) file.fail(idx->offset + 4 * e, "index " + std::to_string(ix[e]) + " is not a cell");
            self |= ix[e] == k;
        }
        if (!self) file.fail(offs->offset + 8 * k, "cell " + std::to_string(k) + " is missing from its own list");
    }
    return InfluenceLists(stored, structure, content, o, ix, file.mapping());
}

std::string defaultCachePath(const std::string& gridPath) {
    std::filesystem::path p(gridPath);
    p.replace_extension(".hci");
    return p.string();
}

InfluenceLists loadOrBuildCache(const Grid& grid, const KernelParams& params, const std::string& cachePath,
                                unsigned threads, bool progress, std::string& note) {
    std::error_code ec;
    if (std::filesystem::exists(cachePath, ec)) {
        try {
            InfluenceLists lists = readInfluenceCache(cachePath, grid, params);
            note = "using influence cache " + cachePath;
            return lists;
        } catch (const Error& e) {
            note = std::string(e.what()) + ": rebuilt";
        }
    } else {
        note = "no influence cache at " + cachePath + ": built";
    }
    InfluenceLists lists = buildInfluenceLists(grid, params, threads, progress);
    writeInfluenceCache(lists, cachePath);
    return lists;
}

}  // namespace hc::influence
