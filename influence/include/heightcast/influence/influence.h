// heightcast/influence/influence.h: influencing-cell lists and their .hci cache.
//
// The influence list of cell k is exactly the set of cells i whose kernel disk (radius
// R sigma c_i around i's centre, kernel.h) reaches into k's closed square with a positive weight:
// then, for any point p in cell k, the sum over k's list equals the sum over all cells. The lists
// depend only on the grid's tree (Grid::structureHash), sigma, R and the kernel, so a cache is
// built once and reused for every water time step on the same tree.
//
// Storage is CSR: offsets[k] .. offsets[k + 1] index into indices (u32 cell indices). Lists hold
// each level's cells in Morton order, coarser levels after finer ones.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "heightcast/grid/grid.h"
#include "heightcast/influence/kernel.h"

namespace hc {
class MappedFile;
}

namespace hc::influence {

class InfluenceLists {
public:
    InfluenceLists() = default;
    InfluenceLists(KernelParams params, uint64_t structureHash, uint64_t contentHash, std::vector<uint64_t> offsets,
                   std::unique_ptr<uint32_t[]> indices, size_t entryCount);
    // A view into a mapped cache file (kept alive by `mapping`).
    InfluenceLists(KernelParams params, uint64_t structureHash, uint64_t contentHash, std::span<const uint64_t> offsets,
                   std::span<const uint32_t> indices, std::shared_ptr<const MappedFile> mapping);

    size_t cellCount() const { return offsets_.empty() ? 0 : offsets_.size() - 1; }
    uint64_t entryCount() const { return indices_.size(); }
    std::span<const uint32_t> list(size_t cell) const {
        return indices_.subspan(offsets_[cell], offsets_[cell + 1] - offsets_[cell]);
    }
    std::span<const uint64_t> offsets() const { return offsets_; }
    std::span<const uint32_t> indices() const { return indices_; }
    const KernelParams& params() const { return params_; }
    uint64_t gridStructureHash() const { return structureHash_; }
    uint64_t gridContentHash() const { return contentHash_; }  // of the grid it was built from (informative)

    struct Stats {
        double meanLength = 0;
        uint64_t p99Length = 0, maxLength = 0;
        uint64_t bytes = 0;  // offsets + indices
    };
    Stats stats() const;

private:
    KernelParams params_;
    uint64_t structureHash_ = 0, contentHash_ = 0;
    std::vector<uint64_t> ownedOffsets_;
    std::unique_ptr<uint32_t[]> ownedIndices_;  // not a vector: filled in parallel, never zero-filled first
    std::shared_ptr<const MappedFile> mapping_;
    std::span<const uint64_t> offsets_;
    std::span<const uint32_t> indices_;
};

// Does cell i influence cell k? The exact rule the lists implement (tests compare against it).
bool influences(const Grid& grid, const KernelParams& params, size_t i, size_t k);

// Builds every list, on `threads` workers (0 = all cores), with terminal progress if asked.
// Throws hc::Error for invalid parameters or a grid of 2^32 cells or more.
InfluenceLists buildInfluenceLists(const Grid& grid, const KernelParams& params, unsigned threads = 0,
                                   bool progress = false);

// ---- the .hci cache file ----

// Writes atomically. Layout in influence/src/cache_file.cpp (header comment).
void writeInfluenceCache(const InfluenceLists& lists, const std::string& path);

// Maps and fully validates a cache (checksums, offsets, indices) and checks it belongs to `grid`
// with `params`: a cache of another tree, kernel, sigma or R is refused with a message saying what
// differs. Throws hc::Error.
InfluenceLists readInfluenceCache(const std::string& path, const Grid& grid, const KernelParams& params);

// The cache path a tool uses by default: the grid's path with its extension replaced by ".hci".
std::string defaultCachePath(const std::string& gridPath);

// Where influence lists pay off by default: hc-influence builds them, and hc-export reads a cache beside the grid, for
// grids of up to this many cells (at about kListBytesPerCell, 1 GB of lists). Above it the lists cost more memory than
// a machine may have and more time to read than the regions of the grid that a tool needs: the tools read the grid out
// of core and the renderers take their texels from the surface pyramid.
constexpr uint64_t kListsDefaultMaxCells = 4'500'000;
constexpr double kListBytesPerCell = 220;  // the mean of the lists at R 3.5, sigma 1 (docs/benchmarks.md)

// What tools do: read `cachePath` if it is valid for (grid, params); otherwise build the lists and
// write them there, and say why in `note` ("no cache at X: built", "X is stale (...): rebuilt").
InfluenceLists loadOrBuildCache(const Grid& grid, const KernelParams& params, const std::string& cachePath,
                                unsigned threads, bool progress, std::string& note);

}  // namespace hc::influence
