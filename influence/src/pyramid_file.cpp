// influence/src/pyramid_file.cpp: the .hcp surface pyramid file, format 1.0: a sectioned container
// (core/sectioned_file.h) with
//
//   offset  size  field
//   0       8     magic "\x89HCPYRA\n"
//   24      8     grid structure hash (Grid::structureHash): a pyramid of another tree is refused
//   32      8     grid content hash (Grid::contentHash): samples depend on the values too, so it must match
//   40      8     finest cell size [m], double
//   48      1     root level
//   49      1     channels (1: elevation; 3: elevation, water level, wet share; 2: water level, wet share, a step's
//                 water pyramid: pyramid.h)
//   50      1     tile side log2
//   51      1     level count (top level + 1)
//   52      4     kernel id (kernel.h)
//   56      4     reserved, zero
//   64      8     sigma, double
//   72      8     truncation R, double
//   80      40    reserved, zero
//
// Sections, three per level t (index = t): KEYS (kind 1: u64 tile keys, ascending), ERRORS (kind 2: f32
// parentErrorM [tile * channels + channel]) and SAMPLES (kind 3: f32 [(tile * channels + channel) * side^2
// + j * side + i]); side = min(2^log2, 2^(root - t)). All mmap-ready (64-byte aligned).
#include <bit>
#include <cmath>
#include <cstring>

#include "heightcast/core/bytes.h"
#include "heightcast/core/error.h"
#include "heightcast/core/sectioned_file.h"
#include "file_layouts.h"
#include "pyramid_storage.h"

namespace hc::influence {
namespace {

enum : uint32_t { kKeys = 1, kErrors = 2, kSamples = 3 };
const FileFormat kFormat{{'\x89', 'H', 'C', 'P', 'Y', 'R', 'A', '\n'},
                         1,
                         0,
                         "heightcast surface pyramid (.hcp)",
                         {kKeys, kErrors, kSamples},
                         0};  // block checksums from the first version (core/sectioned_file.h)

namespace off {
constexpr size_t structureHash = 24, contentHash = 32, finestCellM = 40, rootLevel = 48, channels = 49, tileLog2 = 50,
                 levelCount = 51, kernelId = 52, reserved0 = 56, sigma = 64, truncation = 72, reserved1 = 80,
                 reservedEnd = 120;
}

}  // namespace

namespace detail {

const FileFormat& pyramidFileFormat() { return kFormat; }

std::vector<FileSection> pyramidFileLayout(const std::vector<uint64_t>& tiles, const std::vector<int>& sides,
                                           int channels) {
    std::vector<FileSection> layout;
    for (size_t t = 0; t < tiles.size(); ++t) {
        const uint64_t n = tiles[t], plane = uint64_t(sides[t]) * uint64_t(sides[t]);
        layout.push_back({kKeys, uint32_t(t), 0, n * 8, 0});
        layout.push_back({kErrors, uint32_t(t), 0, n * uint64_t(channels) * 4, 0});
        layout.push_back({kSamples, uint32_t(t), 0, n * uint64_t(channels) * plane * 4, 0});
    }
    return layout;
}

std::vector<std::byte> pyramidFileHeader(const SurfacePyramid& p) {
    std::vector<std::byte> head(kFileHeaderBytes, std::byte{0});
    bytes::store(head, off::structureHash, p.structureHash);
    bytes::store(head, off::contentHash, p.contentHash);
    bytes::store(head, off::finestCellM, p.finestCellM);
    bytes::store(head, off::rootLevel, uint8_t(p.rootLevel));
    bytes::store(head, off::channels, uint8_t(p.channels));
    bytes::store(head, off::tileLog2, uint8_t(kPyramidTileLog2));
    bytes::store(head, off::levelCount, uint8_t(p.levels.size()));
    bytes::store(head, off::kernelId, p.params.kernelId);
    bytes::store(head, off::sigma, p.params.sigma);
    bytes::store(head, off::truncation, p.params.truncation);
    return head;
}

}  // namespace detail

void writeSurfacePyramid(const SurfacePyramid& p, const std::string& path) {
    std::vector<uint64_t> tiles;
    std::vector<int> sides;
    for (const SurfacePyramid::Level& L : p.levels) tiles.push_back(L.tileCount()), sides.push_back(L.tileSide);
    SectionedFileWriter out(path, kFormat, detail::pyramidFileLayout(tiles, sides, p.channels));
    for (size_t t = 0; t < p.levels.size(); ++t) {
        out.append(3 * t, std::as_bytes(p.levels[t].keys));
        out.append(3 * t + 1, std::as_bytes(p.levels[t].parentErrorM));
        out.append(3 * t + 2, std::as_bytes(p.levels[t].samples));
    }
    out.commit(detail::pyramidFileHeader(p));
}

bool pyramidBelongsTo(const std::string& path, const GridFileInfo& grid, const KernelParams& params) {
    try {
        const SectionedFileReader file(path, kFormat);
        const std::byte* h = file.header();
        return bytes::load<uint64_t>(h + off::structureHash) == grid.structureHash &&
               bytes::load<uint64_t>(h + off::contentHash) == grid.contentHash &&
               bytes::load<uint32_t>(h + off::kernelId) == params.kernelId &&
               bytes::load<double>(h + off::sigma) == params.sigma &&
               bytes::load<double>(h + off::truncation) == params.truncation;
    } catch (const Error&) {
        return false;
    }
}

SurfacePyramid readSurfacePyramid(const std::string& path, const Grid& grid, const KernelParams& params) {
    return readSurfacePyramid(path, grid, grid.structureHash(), grid.contentHash(), params);
}

SurfacePyramid readSurfacePyramid(const std::string& path, const GridFileInfo& grid, const KernelParams& params) {
    return readSurfacePyramid(path, grid.shape, grid.structureHash, grid.contentHash, params);
}

SurfacePyramid readSurfacePyramid(const std::string& path, const Grid& grid, uint64_t structureHash,
                                  uint64_t contentHash, const KernelParams& params, uint64_t residentBytes) {
    SectionedFileReader file(path, kFormat);
    const std::byte* h = file.header();
    for (size_t i : {off::reserved0, off::reserved0 + 1, off::reserved0 + 2, off::reserved0 + 3})
        if (h[i] != std::byte{0}) file.fail(i, "reserved header byte is not zero");
    for (size_t i = off::reserved1; i < off::reservedEnd; ++i)
        if (h[i] != std::byte{0}) file.fail(i, "reserved header byte is not zero");
    SurfacePyramid p;
    p.structureHash = bytes::load<uint64_t>(h + off::structureHash);
    p.contentHash = bytes::load<uint64_t>(h + off::contentHash);
    p.finestCellM = bytes::load<double>(h + off::finestCellM);
    p.rootLevel = int(bytes::load<uint8_t>(h + off::rootLevel));
    p.channels = int(bytes::load<uint8_t>(h + off::channels));
    const int tileLog2 = int(bytes::load<uint8_t>(h + off::tileLog2));
    const int levelCount = int(bytes::load<uint8_t>(h + off::levelCount));
    p.params.kernelId = bytes::load<uint32_t>(h + off::kernelId);
    p.params.sigma = bytes::load<double>(h + off::sigma);
    p.params.truncation = bytes::load<double>(h + off::truncation);

    // Whose pyramid is it? Say exactly what differs.
    if (p.structureHash != structureHash || p.contentHash != contentHash)
        throw Error(path +
                    ": stale or foreign surface pyramid: built for another grid (or other values on this grid's tree)");
    if (p.params.kernelId != params.kernelId || p.params.sigma != params.sigma ||
        p.params.truncation != params.truncation)
        throw Error(path + ": surface pyramid built for sigma " + std::to_string(p.params.sigma) + ", R " +
                    std::to_string(p.params.truncation) + "; wanted sigma " + std::to_string(params.sigma) + ", R " +
                    std::to_string(params.truncation));
    // The grid's geometry, field by field (a file whose hashes match may still declare another root level,
    // from which every size below would be computed).
    if (p.rootLevel != grid.rootLevel)
        file.fail(off::rootLevel,
                  "root level " + std::to_string(p.rootLevel) + ", the grid's is " + std::to_string(grid.rootLevel));
    if (p.finestCellM != grid.finestCellM) file.fail(off::finestCellM, "finest cell size differs from the grid's");
    // The rest of the shape must be what this reader builds.
    const bool water = grid.findLayer("water_depth") >= 0;
    if (water ? p.channels != 3 && p.channels != 2 : p.channels != 1)
        file.fail(off::channels, "declares " + std::to_string(p.channels) + " channels, expected " +
                                     (water ? "3 (or 2: water only)" : "1"));
    if (tileLog2 != kPyramidTileLog2)
        file.fail(off::tileLog2, "tile side 2^" + std::to_string(tileLog2) + ", this reader uses 2^" +
                                     std::to_string(kPyramidTileLog2));
    if (levelCount != std::max(0, p.rootLevel - kPyramidTileLog2) + 1)
        file.fail(off::levelCount, "declares " + std::to_string(levelCount) + " levels, a root level of " +
                                       std::to_string(p.rootLevel) + " has " +
                                       std::to_string(std::max(0, p.rootLevel - kPyramidTileLog2) + 1));

    std::vector<const FileSection*> found(size_t(levelCount) * 3, nullptr);
    for (const FileSection& s : file.sections()) {
        if (s.kind < kKeys || s.kind > kSamples) continue;  // a newer minor's section: skipped
        if (s.index >= uint32_t(levelCount))
            file.fail(s.offset, "section for level " + std::to_string(s.index) + ", beyond the top");
        const FileSection*& slot = found[size_t(s.index) * 3 + (s.kind - 1)];
        if (slot)
            file.fail(s.offset,
                      "second section of kind " + std::to_string(s.kind) + " for level " + std::to_string(s.index));
        slot = &s;
    }
    p.levels.resize(size_t(levelCount));
    uint64_t sampleBytes = 0;
    for (int t = 0; t < levelCount; ++t)
        if (const FileSection* samples = found[size_t(t) * 3 + 2]) sampleBytes += samples->bytes;
    for (int t = 0; t < levelCount; ++t) {
        const FileSection* keys = found[size_t(t) * 3];
        const FileSection* errors = found[size_t(t) * 3 + 1];
        const FileSection* samples = found[size_t(t) * 3 + 2];
        if (!keys || !errors || !samples)
            file.failFile("lacks a KEYS, ERRORS or SAMPLES section for level " + std::to_string(t));
        SurfacePyramid::Level& L = p.levels[size_t(t)];
        L.level = t;
        L.tileSide = std::min(kPyramidTileSide, 1 << (p.rootLevel - t));
        if (keys->bytes % 8)
            file.fail(keys->offset, "KEYS of level " + std::to_string(t) + " is not a whole number of u64");
        const uint64_t n = keys->bytes / 8, ch = uint64_t(p.channels),
                       plane = uint64_t(L.tileSide) * uint64_t(L.tileSide);
        // n <= file size / 8, so these products cannot wrap.
        if (errors->bytes != n * ch * 4)
            file.fail(errors->offset, "ERRORS of level " + std::to_string(t) + " holds " +
                                          std::to_string(errors->bytes) + " bytes, expected " +
                                          std::to_string(n * ch * 4));
        if (samples->bytes != n * ch * plane * 4)
            file.fail(samples->offset, "SAMPLES of level " + std::to_string(t) + " holds " +
                                           std::to_string(samples->bytes) + " bytes, expected " +
                                           std::to_string(n * ch * plane * 4));
        // 64-byte aligned in a page-aligned mapping: the spans are properly aligned. The samples, the bulk of the file,
        // are checked without staying resident above residentBytes (pyramid.h).
        if (sampleBytes > residentBytes) file.checkReleasing(*samples);
        L.keys = {reinterpret_cast<const uint64_t*>(file.data(*keys).data()), n};
        L.parentErrorM = {reinterpret_cast<const float*>(file.data(*errors).data()), n * ch};
        L.samples = {reinterpret_cast<const float*>(file.data(*samples).data()), n * ch * plane};
        const int nodeLevel = t + std::countr_zero(unsigned(L.tileSide));
        const uint64_t span = mortonSpan(nodeLevel), domain = mortonSpan(p.rootLevel);
        for (uint64_t k = 0; k < n; ++k) {
            if (L.keys[k] % span || L.keys[k] >= domain)
                file.fail(keys->offset + 8 * k, "tile key " + std::to_string(L.keys[k]) + " is not a level-" +
                                                    std::to_string(nodeLevel) + " node of the domain");
            if (k && L.keys[k] <= L.keys[k - 1]) file.fail(keys->offset + 8 * k, "tile keys do not ascend");
        }
        for (uint64_t k = 0; k < n * ch; ++k)
            if (!(L.parentErrorM[k] >= 0)) file.fail(errors->offset + 4 * k, "parent error is negative or NaN");
    }
    auto storage = std::make_shared<SurfacePyramid::Storage>();
    storage->mapping = file.mapping();
    p.storage = std::move(storage);
    return p;
}

}  // namespace hc::influence
