// heightcast/influence/pyramid.h: the surface pyramid (docs/design.md section 4) and its .hcp file.
//
// The exact smooth surface (surface.h) sampled on dyadic lattices aligned with the finest-cell lattice:
// level t has spacing h_t = finestCellM * 2^t, and its sample (i, j) lies at local (i h_t, j h_t), a corner
// of the finest cells. Samples come in tiles of kPyramidTileSide^2: tile (ti, tj) of level t holds samples
// i in [ti S, ti S + S), j likewise, and covers the quadtree node of level t + log2(S) whose corner key is
// mortonEncode(ti S 2^t, tj S 2^t) (the tile's "key"; for a domain smaller than one tile, the whole domain).
//
// Stored only where the surface has detail at that scale: a tile of level t is kept where the kernel of a cell no
// larger than h_t (level <= t) reaches it: the square of half-side R sigma c about the cell's centre meets the tile's
// node (the cell's own tile among them), and the node meets some cell (else every sample would be NaN). A cascade's
// texels there are copies, where a rule of "the node holds such a cell" would leave those beside it, across a tile
// edge from a river of fine cells, to the kernels (docs/benchmarks.md, "Tiles where a fine cell's kernel reaches"). The
// top level (one tile covers the domain) is kept wherever there are cells, so every point over a cell has a coarsest
// sample; a tile's parent is always kept (the same cell's reach meets the parent's node). Storage therefore follows
// the cells (about 4/3 samples per cell where the tiles are full, plus the reach's band), not the area at the finest
// spacing.
//
// Channels, per sample (float32; NaN where the surface is undefined: holes and outside the domain):
//   Elevation   the smooth terrain z (section 4)
//   WaterLevel  level(p), the wet cells' weighted level (section 12); NaN where no wet cell weighs
//   WetShare    sum of wet weights / sum of all weights, in [0, 1]; water is drawn where it is at least
//               kWetShareMin and WaterLevel > Elevation (surface.h)
// The water channels exist only for a grid with a water_depth layer.
//
// Water pyramids (a scenario of several water steps, docs/design.md section 6): the terrain and the tree are the same
// in every step, so only the first step's pyramid is whole (the base, 3 channels); each later step's holds its two
// water channels (WaterLevel, WetShare, in that order) in the tiles where its water is drawn at some sample
// (waterPyramidOf). A reader takes the elevation from the base and the water from the step's pyramid; a tile of the
// base that the step's pyramid lacks draws no water in that step. Every tile of a water pyramid is a tile of its base.
//
// Bound: each tile records, per channel, parentErrorM: the largest |sample - bilinear interpolation of the
// parent level's samples| over the tile's samples where all are defined. It is what a reader gives up at
// this tile's points by reading the coarser level instead (measured, not estimated); 0 on the top level.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "heightcast/grid/grid.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/kernel.h"

namespace hc {
class MappedFile;
}

namespace hc::influence {

constexpr int kPyramidTileLog2 = 4;
constexpr int kPyramidTileSide = 1 << kPyramidTileLog2;  // samples per tile side
constexpr size_t kPyramidTileSamples = size_t(kPyramidTileSide) * kPyramidTileSide;
// The samples a reader keeps resident after checking them (readSurfacePyramid): up to 3 GiB (the pyramid of about 600 M
// cells), a renderer stays under 4 GB and its moving frames read tiles already mapped (releasing them made a flight
// over 419 M cells 25 % slower, the pages faulted back one by one); above, a renderer's memory follows the tiles it
// reads, not the grid.
constexpr uint64_t kPyramidResidentBytes = uint64_t(3) << 30;

enum class PyramidChannel : int { Elevation = 0, WaterLevel = 1, WetShare = 2 };

class SurfacePyramid {
public:
    struct Level {
        int level = 0;                   // t: spacing finestCellM * 2^t
        int tileSide = 0;                // samples per tile side (kPyramidTileSide, less when the domain is smaller)
        std::span<const uint64_t> keys;  // tile keys, ascending
        std::span<const float> parentErrorM;  // [tile * channels + channel]
        std::span<const float> samples;       // [(tile * channels + channel) * tileSide^2 + j * tileSide + i]
        size_t tileCount() const { return keys.size(); }
        // Index of the tile with this key, or -1.
        long findTile(uint64_t key) const;
    };

    double finestCellM = 1;
    int rootLevel = 0;
    int channels = 1;  // 1 (elevation), 3 (with water), or 2: a water pyramid (water level, wet share; above)
    KernelParams params;
    uint64_t structureHash = 0, contentHash = 0;  // of the grid it samples
    std::vector<Level> levels;                    // index t = level t, 0 .. top

    int topLevel() const { return int(levels.size()) - 1; }
    double spacingM(int t) const { return finestCellM * double(uint64_t{1} << t); }
    bool waterOnly() const { return channels == 2; }
    // Where channel c lies in a tile (its plane index), or -1 when this pyramid does not hold it.
    int channelIndex(PyramidChannel c) const;
    // The sample at lattice point (i, j) of level t, or nullopt where no tile of level t is stored there or the
    // pyramid has no such channel (a stored NaN, undefined surface, comes back as NaN).
    std::optional<float> sample(int t, uint64_t i, uint64_t j, PyramidChannel c) const;
    // The tile of level t holding lattice point (i, j), or -1.
    long tileAt(int t, uint64_t i, uint64_t j) const;
    // Storage: samples and bytes (keys, bounds, samples) over all levels.
    uint64_t sampleCount() const;
    uint64_t bytes() const;

    // Reads the samples of one level at lattice points near each other, remembering the tile of the last read (a
    // read in that tile costs no search: tileAt is a binary search over the level's tiles) and the last tiles met
    // along two rows of tiles (a table of kRemembered, by tile column and row parity): rows of texels walk the same
    // tiles 16 times, and a stencil alternates between neighbouring tiles. One per thread.
    class Cursor {
    public:
        Cursor(const SurfacePyramid& p, int t);
        // The first channel's sample at lattice point (i, j), with channel index c (channelIndex) at [c * plane()],
        // or nullptr where no tile of this level is stored there.
        const float* find(uint64_t i, uint64_t j) {
            if ((i >> shift_) != tileI_ || (j >> shift_) != tileJ_) seek(i, j);
            return tile_ ? tile_ + ((j & (side_ - 1)) << shift_) + (i & (side_ - 1)) : nullptr;
        }
        size_t side() const { return side_; }
        size_t plane() const { return side_ * side_; }
        // The first sample of the tile the last find() returned a sample of (its address less that tile's).
        const float* tile() const { return tile_; }

    private:
        void seek(uint64_t i, uint64_t j);          // remembers the tile holding (i, j)
        static constexpr size_t kRemembered = 256;  // 128 tile columns (a 1024-texel row spans 64) x 2 row parities
        struct Remembered {
            uint64_t tileI = ~uint64_t{0}, tileJ = ~uint64_t{0};
            const float* tile = nullptr;
        };
        const SurfacePyramid& p_;
        int t_;
        size_t side_;  // a power of two (the domain's side is one)
        int shift_;
        uint64_t tileI_ = ~uint64_t{0}, tileJ_ = ~uint64_t{0};
        const float* tile_ = nullptr;    // the remembered tile's first sample, nullptr if not stored
        std::vector<Remembered> table_;  // kRemembered entries once a second tile is sought
    };

    // Owned storage (built) or a mapped file (read) behind the spans.
    struct Storage;
    std::shared_ptr<const Storage> storage;
};

// Samples the exact surface of `grid` (kernel `params`) into a pyramid, on `threads` workers (0 = all
// cores), with terminal progress if asked. Each tile evaluates its samples against the cells whose kernels
// reach it (gathered once per tile, narrowed per block of 4 x 4 samples), in double, without influence lists.
// Throws hc::Error for invalid parameters.
SurfacePyramid buildSurfacePyramid(const Grid& grid, const KernelParams& params, unsigned threads = 0,
                                   bool progress = false);
// The water pyramid of a whole one (3 channels; above): its water channels and their parent errors, in the tiles with
// a sample where water is drawn (the water rule of surface.h: wet share >= kWetShareMin, level above the elevation).
// Throws hc::Error for a pyramid without water channels.
SurfacePyramid waterPyramidOf(const SurfacePyramid& whole);
// The same as waterPyramidOf(buildSurfacePyramid(grid, ...)), bit for bit, for a grid with water, sampling only the
// tiles a wet cell's kernel reaches (and one tile around them): the others hold no wet weight, so no water. What
// hc-influence builds for a scenario's later steps: the cost follows the water, not the grid. Throws hc::Error for a
// grid without water.
SurfacePyramid buildWaterPyramid(const Grid& grid, const KernelParams& params, unsigned threads = 0,
                                 bool progress = false);

// The error of drawing channel c as the bilinear interpolant of level t's samples, per level t [m]: an estimate from
// the tiles' measured parent errors (Level::parentErrorM), over the whole domain. Between two levels the difference
// of their interpolants is piecewise bilinear on the finer lattice, so it is largest at a finer sample, where it is
// that sample's parent error: |f - B_t| <= |f - B_(t-1)| + max parentErrorM(t - 1), down to level 0, whose own error
// is taken as level 0's parent errors (a quarter of them for a surface smooth at that spacing, but the kernels of the
// finest cells put detail at it: pyramid_errors.cpp). Without the samples' float32 rounding (the caller's: it knows the
// heights). Not a proof (the parent errors are measured at samples, and level 0's own error is estimated):
// --verify-error measures the real error beside it. Empty for a pyramid without c.
std::vector<double> bilinearErrorByLevelM(const SurfacePyramid& pyramid, PyramidChannel c);
// The same per region: the tiles' parent errors kept for each square of a grid of regions over the domain (up to
// 2^kRegionsLog2 a side), so that the error over a box comes from the tiles near it: a view of flat ground gets the
// flat ground's error, not that of mountains elsewhere in the grid. byLevelM chains, per level t, the largest parent
// error of the regions that the box, widened by level t's spacing (the samples of the patches a point of the box
// reads), meets; over the whole domain it is bilinearErrorByLevelM. Empty for a pyramid without channel c.
class RegionalLevelErrors {
public:
    static constexpr int kRegionsLog2 = 6;
    RegionalLevelErrors() = default;
    RegionalLevelErrors(const SurfacePyramid& pyramid, PyramidChannel c);
    bool empty() const { return levels_ == 0; }
    // Over the box [x0, x1] x [y0, y1] of local metres: per level [m], as bilinearErrorByLevelM.
    std::vector<double> byLevelM(double x0, double y0, double x1, double y1) const;

private:
    std::pair<int, int> regionsOver(double a, double b) const;
    int levels_ = 0, side_ = 0;
    double regionM_ = 0, finestCellM_ = 0;
    std::vector<float> parentMax_;  // [(t * side + j) * side + i]: the largest parent error of level t's tiles there
};

// The .hcp file: written atomically; read memory-mapped, validated (checksums, sizes, keys ascending and
// inside the domain) and checked to belong to `grid` with `params` (like the .hci cache); a water pyramid (2 channels)
// is read for a grid with water. Throws hc::Error.
void writeSurfacePyramid(const SurfacePyramid& pyramid, const std::string& path);
SurfacePyramid readSurfacePyramid(const std::string& path, const Grid& grid, const KernelParams& params);
// The same for a grid file not read whole (GridRegionReader): its geometry and the hashes its header stores.
SurfacePyramid readSurfacePyramid(const std::string& path, const GridFileInfo& grid, const KernelParams& params);
// Both: `grid` gives the geometry and layers (its cells are not read), the hashes are the grid's.
// Samples of more than `residentBytes` in all are checked without staying resident (SectionedFileReader::
// checkReleasing): a reader then holds the tiles it touches, not the file, and pages them back in as it reads them.
SurfacePyramid readSurfacePyramid(const std::string& path, const Grid& grid, uint64_t structureHash,
                                  uint64_t contentHash, const KernelParams& params,
                                  uint64_t residentBytes = kPyramidResidentBytes);

// Whether the file at `path` is a pyramid built for `grid` (the hashes of the step GridFileInfo selects) with `params`,
// from its header alone (nothing else read or validated; false for a missing or unreadable file): for choosing a path
// before reading it, which readSurfacePyramid then checks whole.
bool pyramidBelongsTo(const std::string& path, const GridFileInfo& grid, const KernelParams& params);

// The pyramid path a tool uses by default: the grid's path with its extension replaced by ".hcp".
// A grid of several water steps has one pyramid per step (the water channels differ): grid.step0007.hcp for step 7.
std::string defaultPyramidPath(const std::string& gridPath, size_t step = 0, size_t stepCount = 1);

}  // namespace hc::influence
