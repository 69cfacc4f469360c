// render/src/approximate_internal.h: what the files of the approximation pass share (private to render/src/):
// approximate.cpp (the per-cascade driver: the last frame's texels, the stages, the blocks out of core),
// approximate_copy.cpp (texels copied from the surface pyramid), approximate_interpolate.cpp (texels interpolated
// from a coarser pyramid level: PyramidInterpolator) and approximate_sum.cpp (the Gaussian RBF sum).
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <unordered_map>
#include <vector>

#include "heightcast/grid/grid_file.h"
#include "heightcast/grid/morton.h"
#include "heightcast/influence/pyramid.h"
#include "heightcast/influence/surface.h"
#include "heightcast/render/water_rule.h"
#include "heightcast/render/detail/frame.h"

namespace hc::render::detail {

// The texels to evaluate, per row at most two spans: the row's visible span less the part copied from the
// last frame (visible there too: one span, as both rows' spans are intervals).
struct Todo {
    TexelSpan a, b;
    TexelSpan& span(int k) { return k == 0 ? a : b; }
};

// An inclusive range of texel columns and rows.
struct TexelRange {
    int i0, i1, j0, j1;
};

// ---- Texels copied from the surface pyramid (approximate_copy.cpp) ----

// copyPyramidTexels()'s inputs: the cascade, its textures and spans, and where the copies go.
struct PyramidCopy {
    const Scene& scene;
    const Cascade& c;
    CascadeTextures& tex;
    double waterMinDepthM;
    int interpolateLevels;
    unsigned threads;
    std::vector<Todo>& todo;           // each span shrinks to the texels not filled
    std::vector<uint8_t>& copiedMask;  // n^2, zero: the texels filled are marked
    PyramidTiles* tiles;               // nullptr: the copies written into tex; else marked there, left to the caller
};

// Copies into tex the texels of `todo` whose centres are samples of a tile the surface pyramid holds at the
// cascade's level (texelM is that level's spacing and the corner lies on its lattice: cascades.h), applying the
// water rule of surface.h to the water channels as the kernel path does; with interpolateLevels > 0, texels finer
// than the levels stored around them are interpolated from a coarser one (PyramidInterpolator). Each span of `todo`
// shrinks to the texels it could not fill, from the first to the last of them, and `copiedMask` (n^2, zero) marks
// the filled texels, so that the kernel path skips those left inside a span (a row with holes at both ends keeps its
// whole span: 23 % of a far cascade's texels at 105 M cells, all of them copies). Out of core, texels in a tile whose
// node holds no cell (EmptyTiles) are marked too, left "no surface": the interpolator would look for coarser samples
// there in vain (1.4 us a texel: 8.5 ms of a fresh frame at 105 M cells, for 6 k texels over holes). Returns the
// texels copied, adds the texels interpolated to work.pyramidInterpolated (the most levels up to
// work.pyramidInterpolatedUp) and sets work.pyramidLevel to the pyramid level used (-1: none fits the cascade). With
// `tiles`, the copies are marked there (PyramidTiles: each worker sets its texels' bits, no list to merge) instead of
// written or counted (the caller counts what it copies), and each span shrinks to the texels written here
// (interpolated) or left to the kernels, from the first to the last (the interpolated ones marked in copiedMask, so the
// kernels skip them). With `tiles` and a cascade below level 0, the texels of blocks whose level-0 tiles are all stored
// and alike (PyramidTiles::Block) are left to the caller to interpolate: marked in copiedMask, counted as interpolated,
// their blocks listed in `tiles`.
uint64_t copyPyramidTexels(const PyramidCopy& in, ApproximationWork& work);

// Out of core: whether the pyramid tile (level t, its lattice: copyPyramidTexels) holding lattice point (gi, gj) lies
// outside the domain or in a quadtree node that holds no cell at all. The surface is undefined at every texel there (a
// hole, or outside the data), so there is nothing to copy, interpolate or sum. Counting a node's cells takes two
// binary searches over the file's codes, next to each other; each tile is asked once. Where one tile covers the
// domain there is no node to ask, and nothing is said empty.
class EmptyTiles {
public:
    EmptyTiles(const GridRegionReader& file, int t) : file_(file), t_(t) {
        const int root = file.shape().rootLevel;
        asks_ = t >= 0 && t + influence::kPyramidTileLog2 <= root;
        if (asks_) last_ = (uint64_t{1} << (root - t)) - 1;  // the lattice's last index inside the domain
    }
    bool asks() const { return asks_; }
    bool operator()(uint64_t gi, uint64_t gj) {
        if (!asks_) return false;
        if (gi > last_ || gj > last_) return true;
        const uint64_t ti = gi >> influence::kPyramidTileLog2, tj = gj >> influence::kPyramidTileLog2;
        auto [it, fresh] = empty_.try_emplace(ti << 32 | tj, false);
        if (fresh) {
            const int shift = t_ + influence::kPyramidTileLog2;
            it->second = file_.cellsInNode(mortonEncode(uint32_t(ti << shift), uint32_t(tj << shift)), shift) == 0;
        }
        return it->second;
    }

private:
    const GridRegionReader& file_;
    int t_;
    bool asks_ = false;
    uint64_t last_ = 0;
    std::unordered_map<uint64_t, bool> empty_;  // per tile (ti << 32 | tj)
};

// ---- Texels interpolated from a coarser pyramid level (approximate_interpolate.cpp) ----

// Fills texels finer than every pyramid level stored around them (pyramid.h keeps level t only where the kernel of a
// cell as fine as its spacing reaches) by bicubic (Catmull-Rom) interpolation of the nearest coarser level whose
// samples around the texel are all stored, at most `maxUp` levels above the cascade's, and where no cell finer than
// that level's spacing lies within a kernel's reach of the samples: then the surface is smooth at that spacing (a sum
// of Gaussians at least one spacing wide, kernel.h). Such cells lie only in the stored tiles of the level below; their
// positions come from the grid's codes in those tiles' nodes (in memory or from the file), kept per worker in a table
// of recent tiles. Undefined samples (holes), a water level defined at some samples only (a flood's edge) and finer
// cells near are left to the kernels: such texels are not filled, as where no such level is stored.
//
// Separably, row by row: a texel row lies at one height between two rows of samples, so each column of 4 samples is
// blended vertically once per texel row (and kept in a small cache), and a texel blends 4 columns. A texel of level
// t + up's stencil shares its columns with the 2^up texels beside it. One per worker; rows are asked in any order.
class PyramidInterpolator {
public:
    PyramidInterpolator(const Scene& scene, const influence::SurfacePyramid& p, const influence::SurfacePyramid* water,
                        int t, int maxUp);

    struct Value {
        float z, level, share;  // level NaN: dry
        int up;                 // levels above the cascade's
    };

    // Interpolates lattice points gi0 .. gi0 + count - 1 of row gj of the cascade's level: out[k] where filled[k].
    // Each point takes the first level, going up, where the samples of its stencil's non-zero weights are all stored;
    // it is refused (left to the kernels) where one of them is undefined, where wet and dry columns meet, where the
    // stencil would leave the domain, or where no level up to maxUp has them. A level's columns are taken once for the
    // run, from the column cache.
    void run(uint64_t gi0, int count, uint64_t gj, Value* out, uint8_t* filled);

private:
    // A column of samples blended vertically: some not stored at that level (missing), some undefined (a hole) or a
    // flood's edge (some wet, some dry: undefined too, for the texel's purpose), all dry, or all wet.
    enum Kind : uint8_t { kMissing, kUndefined, kDry, kWet };
    struct Column {
        uint64_t i = ~uint64_t{0}, stamp = 0;
        Kind kind = kMissing;
        double z = 0, level = 0, share = 0;
    };
    static constexpr size_t kColumns = 8;  // cached columns per level: a texel uses 4 neighbouring ones
    static constexpr size_t kFineTiles = 512, kRowMasks = 256;  // table sizes (powers of two; a row spans < 128 tiles)
    struct Level {
        bool stored = false;  // false: below level 0
        std::vector<influence::SurfacePyramid::Cursor> samples,
            water;                                             // by tile parity: a stencil spans up to 2 x 2 tiles
        std::vector<influence::SurfacePyramid::Cursor> finer;  // the level below, by tile parity
        int finerLevel = 0, finerShift = 0;                    // its level, log2 of its tile side
        // The last stored tiles of the level below met (a table by tile column and row parity, as the pyramid's
        // Cursor keeps), each with its fine cells: bit i of row j set when a cell of that level or finer lies between
        // its samples (i, j) and (i + 1, j + 1). A tile dropped from the table is read again when asked again.
        struct FineTile {
            int64_t tx = -1, ty = -1;
            std::array<uint16_t, 16> rows{};
        };
        std::vector<FineTile> fineCells = std::vector<FineTile>(kFineTiles);
        // For the current row of samples (rowJ): per tile column of the level below (a table by column), the OR of
        // its fine cells' rows that a kernel from the row's stencil reaches.
        struct RowMask {
            int64_t tx = -1;
            uint64_t rowJ = ~uint64_t{0};
            uint32_t bits = 0;
        };
        std::vector<RowMask> rowMask = std::vector<RowMask>(kRowMasks);
        int64_t reach = 2;  // samples of this level a finer cell's kernel reaches beyond it
        size_t side = 0, plane = 0;
        int shift = 0;
        std::vector<std::array<double, 4>> weights;  // [fraction]
        uint64_t rowJ = ~uint64_t{0}, rowF = 0, stamp = 1;
        std::array<Column, kColumns> cache;
    };

    const Column& column(Level& L, uint64_t i, const std::array<double, 4>& wy);
    bool fineCellNear(Level& L, int64_t x0, int64_t x1);
    const std::array<uint16_t, 16>& tileCells(Level& L, int64_t tx, int64_t ty);

    const Scene& scene_;
    std::vector<uint8_t> state_;   // run(): per point, pending, done or refused
    std::vector<Column> columns_;  // run(): the columns of one level for the run
    std::vector<uint64_t> codes_;  // out of core: a node's codes read from the file
    const influence::SurfacePyramid* water_;
    bool channels3_;
    std::vector<Level> levels_;
};

// An interpolated texel into tex at `at`, with the water rule (water_rule.h) as the kernel path applies it.
inline void writeInterpolated(const PyramidInterpolator::Value& v, size_t at, float minDepth, CascadeTextures& tex) {
    tex.terrain.h[at] = v.z;
    if (std::isnan(v.level) || !water::wetShare(v.share)) return;
    const float d = v.level - v.z;
    if (water::holdsDepth(d)) tex.depth[at] = d;
    if (water::drawsWater(d, minDepth)) tex.water.h[at] = v.level;
}

// ---- The Gaussian RBF sum (approximate_sum.cpp) ----

// The cells the approximation sums over: the scene's own (in memory) or a region's (out of core).
struct CellData {
    const Grid& grid;
    const influence::InfluenceLists& lists;
    const std::vector<Scene::CellKernel>& kernels;
    int waterLayer;  // grid layer of water_depth, or -1
};

// The texels left to evaluate are listed cell by cell. Their bounding box's cells (Grid::cellsInBox) serve a
// fresh cascade, whose visible texels fill 25-100 % of that box. A moving camera leaves thin strips along the
// cascade's edges, whose bounding box is still the whole cascade: listing its cells would examine every cell
// under the cascade (about 2 M in Wachau's far cascade) for a few thousand texels. Below one texel to evaluate
// in kSparseTodo of the box, each texel's cell is located instead (Grid::locate, a binary search over the cells),
// so the work follows the texels. Fresh cascades without a pyramid (above 1/4) always list the box, and a moving
// camera's strips (0.1-1 % of the box in hc-bench's fly-through) are always located. Between them lie fresh cascades
// whose texels the pyramid mostly filled: Petzenkirchen's far cascade left 55 k texels to sum in a box of 817 k,
// whose listing examined 570 k cells in 17-21 ms; 4 (not 16, as first set) has them located.
constexpr uint64_t kSparseTodo = 4;

// Appends to `cells` (sorted, each once) the cells whose half-open squares hold a texel centre `need`ed in r:
// the cells the box listing would keep (a cell holding no texel to evaluate is skipped there too).
void cellsUnderTexels(const Grid& g, const Cascade& c, const std::vector<uint8_t>& need, const TexelRange& r,
                      unsigned threads, std::vector<uint32_t>& cells);

// Sums the kernels at the texels of `todo` inside range r that `need` it (not copied from the pyramid), whose centres
// lie in `cells` (sorted), each cell's texels over its influence list. Adds the kernel evaluations to *gaussians.
void sumTexels(const CellData& data, const Cascade& c, const std::vector<Todo>& todo, const std::vector<uint8_t>& need,
               const TexelRange& r, const std::vector<uint32_t>& cells, CascadeTextures& tex, double waterMinDepthM,
               unsigned threads, uint64_t* gaussiansOut);

}  // namespace hc::render::detail
