// ingest/src/build_internal.h: what the files of the quadtree build share (private to ingest/): build.cpp (the
// algorithm: the merge rule, the tiles' pyramids and the passes of Builder::run), build_on_ranks.cpp (its
// distribution over the ranks of mpirun) and build_grid.cpp (the entry points, buildGrid and buildGridFile, and the
// water steps' merge masks and depths per cell). build.cpp's first comment describes the build as a whole.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "heightcast/core/error.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/timer.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/ingest/build.h"

namespace hc::ingest::detail {

constexpr int kTileLevelMax = 6;  // 64 x 64 pixel tiles: a pyramid fits in L2

struct Node {
    std::array<float, 1> mean{}, lo{}, hi{};  // elevation
    bool leaf = false;                        // a single cell covers the whole node
};

// Which quadtree nodes the water steps let merge: per level 1..maxLevel, a byte per node (node (x, y) of level l covers
// pixels [x 2^l, (x + 1) 2^l) east and likewise north of the south-west corner). Starts all allowed.
// Over the whole raster, or (a rank's, under mpirun) over its own windows only up to level fineTop and the whole raster
// above it: a rank forbids merges in its own nodes, and above the tiles every rank merges every node (Builder::run).
class MergeMask {
public:
    MergeMask(size_t width, size_t height, int maxLevel) : levels_(size_t(maxLevel) + 1) {
        for (int l = 1; l <= maxLevel; ++l) levels_[size_t(l)].push_back(Level::over(0, 0, width, height, l));
    }
    // Over `windows` (rectangles of pixels whose corners lie on the lattice of 2^windowLevel) for levels up to fineTop;
    // windowOf: per node of 2^windowLevel (windowNx a row) the window holding it, or -1.
    MergeMask(size_t width, size_t height, int maxLevel, int fineTop, const std::vector<std::array<size_t, 4>>& windows,
              int windowLevel, std::vector<int32_t> windowOf, size_t windowNx)
        : levels_(size_t(maxLevel) + 1),
          fineTop_(fineTop),
          windowLevel_(windowLevel),
          windowOf_(std::move(windowOf)),
          windowNx_(windowNx) {
        for (int l = 1; l <= maxLevel; ++l) {
            if (l > fineTop) {
                levels_[size_t(l)].push_back(Level::over(0, 0, width, height, l));
                continue;
            }
            for (const auto& [x0, y0, w, h] : windows) levels_[size_t(l)].push_back(Level::over(x0, y0, w, h, l));
        }
    }
    bool allowed(int level, size_t x, size_t y) const {
        const Level* L = find(level, x, y);
        if (!L) return true;  // not this rank's node: never forbidden here
        return x - L->x0 < L->nx && y - L->y0 < L->ny && L->ok[(y - L->y0) * L->nx + (x - L->x0)];
    }
    void forbid(int level, size_t x, size_t y) {
        Level* L = const_cast<Level*>(find(level, x, y));
        if (L && x - L->x0 < L->nx && y - L->y0 < L->ny) L->ok[(y - L->y0) * L->nx + (x - L->x0)] = 0;
    }
    // A level of the whole raster's bytes, and the merges another mask of the same raster forbids there forbidden here.
    const std::vector<uint8_t>& level(int l) const { return levels_[size_t(l)].at(0).ok; }
    void forbidAlso(int l, std::span<const uint8_t> other) {
        std::vector<uint8_t>& ok = levels_[size_t(l)].at(0).ok;
        if (other.size() != ok.size()) throw Error("internal: merge masks of different sizes");
        for (size_t i = 0; i < ok.size(); ++i) ok[i] &= other[i];
    }

private:
    struct Level {
        size_t x0 = 0, y0 = 0, nx = 0, ny = 0;  // in nodes of its level
        std::vector<uint8_t> ok;
        static Level over(size_t px0, size_t py0, size_t w, size_t h, int l) {
            const size_t side = size_t{1} << l;
            Level L{px0 >> l, py0 >> l, (w + side - 1) >> l, (h + side - 1) >> l, {}};
            L.ok.assign(L.nx * L.ny, 1);
            return L;
        }
    };
    const Level* find(int level, size_t x, size_t y) const {
        const std::vector<Level>& ls = levels_[size_t(level)];
        if (level > fineTop_ || windowOf_.empty()) return &ls[0];
        const size_t px = x << level, py = y << level, node = (py >> windowLevel_) * windowNx_ + (px >> windowLevel_);
        if (node >= windowOf_.size() || (px >> windowLevel_) >= windowNx_ || windowOf_[node] < 0) return nullptr;
        return &ls[size_t(windowOf_[node])];
    }
    std::vector<std::vector<Level>> levels_;  // per level: the whole raster, or one per window
    int fineTop_ = std::numeric_limits<int>::max(), windowLevel_ = 0;
    std::vector<int32_t> windowOf_;
    size_t windowNx_ = 0;
};

// A rectangle of the working raster's pixels that the build reads: the whole raster, or under mpirun with a raster
// read window by window (RasterWindows), one of the windows of this rank's share. (x0, y0): its south-west pixel in
// finest coordinates (x east, y north of the raster's south-west corner); rows stored north-up, like Raster's.
struct Block {
    size_t x0 = 0, y0 = 0, w = 0, h = 0;
    const float* values = nullptr;
    const float* rounding = nullptr;  // Raster::roundingM, or nullptr
    size_t index(size_t ix, size_t iy) const { return (y0 + h - 1 - iy) * w + (ix - x0); }
};

// build_grid.cpp.
void restrictByStep(const Block& d, double tolerance, int maxLevel, unsigned threads, MergeMask& mask);

// Cells on their way to the sink: one batch at a time, so the grid never has to be in memory.
struct Batch {
    std::vector<uint64_t> codes;
    std::vector<std::vector<float>> values;
};

struct Stats {
    double maxDev = 0, sumSq = 0;
    uint64_t pixels = 0, wetCells = 0;
    std::vector<uint64_t> perLevel;
    uint64_t firstCell = 0, ownCells = 0;  // this rank's cells: indices [firstCell, firstCell + ownCells) of the file's
};

// A unit's measurements (Builder::measureCell), added into its worker's Stats when the unit is done.
struct Tally {
    double maxDev = 0, sumSq = 0;
    uint64_t pixels = 0;
    std::array<uint64_t, 64> perLevel{};
};

class Builder {
public:
    // `terrain` gives the geometry, and the pixels unless `windows` reads them (RasterWindows: each rank then reads
    // only the windows of its share).
    Builder(const Raster& terrain, const RasterWindows* windows, const MergeMask* mask, const BuildOptions& opt,
            int rootLevel, int maxLevel)
        : t_(terrain),
          windows_(windows),
          mask_(mask),
          opt_(opt),
          layers_(1),
          rootLevel_(rootLevel),
          maxLevel_(maxLevel),
          tileLevel_(std::min(rootLevel, kTileLevelMax)),
          tile_(size_t{1} << tileLevel_),
          ntx_((terrain.width + tile_ - 1) / tile_),
          nty_((terrain.height + tile_ - 1) / tile_) {
        // Share nodes: never finer than a tile or the coarsest cell (so every unit of pass C lies in one), and at most
        // 4^11 of them over the root square (the share table stays small).
        shareLevel_ = std::min(rootLevel_, std::max({tileLevel_, maxLevel_, rootLevel_ - 11}));
        const size_t side = size_t{1} << shareLevel_;
        nbx_ = (terrain.width + side - 1) / side;
        nby_ = (terrain.height + side - 1) / side;
    }

    // Builds the tree and hands its cells, in Morton order, to the sink. Returns the measurements.
    Stats run(CellSink& sink);

    // After run(), with water steps read window by window (RasterWindows::readStep): step k's depths over each block of
    // this rank (its windows, as the terrain's), kept in `storage`, and the one holding a pixel.
    std::vector<Block> stepBlocks(size_t k, std::vector<std::vector<float>>& storage, bool first) const;
    // The bathtub at `level` over this rank's blocks (collective: every rank calls it, blocks or not): the depths that
    // load_water.cpp's bathtub gives the whole raster, in `storage`, one vector a block.
    void bathtubBlocks(double level, std::vector<std::vector<float>>& storage) const;
    size_t blockIndexAt(size_t ix, size_t iy) const { return size_t(&blockAt(ix, iy) - blocks_.data()); }

private:
    // run()'s state, stage to stage (build.cpp: the passes; build_on_ranks.cpp: the shares and what goes between the
    // ranks): this rank's place among them, the tiles' roots and leaf counts, the coarse levels above them, the units.
    struct Unit {
        size_t x, y;  // node coordinates at its level
        int level;    // absolute level; tileLevel_ means "a tile"
        size_t offset;
    };
    struct RunState {
        unsigned threads = 0;
        int rank = 0, rankCount = 1;
        bool root = true;
        std::vector<uint64_t> cuts;   // the shares: rank r's share nodes are codes [cuts[r], cuts[r + 1])
        std::vector<size_t> myTiles;  // pass A's tiles of this rank
        // One process building in pieces (RasterWindows::heldPixelsMax): piece i is share nodes [pieces[i],
        // pieces[i + 1]), its pixels held in pass A and again in pass C. Empty: the share's pixels held at once.
        std::vector<uint64_t> pieces;
        uint64_t pixelsRead = 0;  // pixels this rank read (windows_; a build in pieces: its first reads)
        size_t windowsRead = 0;   // likewise, the windows
        std::vector<std::vector<std::vector<Node>>> scratch;  // per worker: a tile's pyramid
        std::vector<Node> roots;                              // per tile (ty * ntx + tx): its pyramid's root
        std::vector<uint32_t> leafCount;                      // per tile: its cells
        std::vector<uint8_t>
            merged;  // per tile of this rank: whether any pixels merged (else its cells are its pixels)
        std::vector<std::vector<Node>> coarse;        // pass B: the levels from the tiles' up to the root
        std::vector<std::pair<size_t, size_t>> dims;  // their sizes in nodes
        std::vector<Unit> units;                      // pass C: in Morton order
        size_t total = 0;                             // the cells of all units
        size_t myU0 = 0, myU1 = 0;                    // this rank's units
        size_t offsetOf(size_t u) const { return u < units.size() ? units[u].offset : total; }
        size_t myCells() const { return offsetOf(myU1) - offsetOf(myU0); }
    };
    // build.cpp: the passes.
    void buildTileRoots(RunState& rs, Progress& progress);
    void buildCoarseLevels(RunState& rs) const;
    void walkUnits(RunState& rs) const;
    Stats writeUnits(RunState& rs, CellSink& sink, GridFilePart* part, std::vector<double>& unitSumSq,
                     Progress& progress);
    void fillBatch(RunState& rs, size_t u0, size_t u1, Batch& batch, std::vector<Stats>& acc,
                   std::vector<double>& unitSumSq, Progress& progress) const;
    // build_on_ranks.cpp: the shares, and what goes between the ranks.
    void takeShare(RunState& rs);
    void maskOwnNodes(bool root);
    void gatherTileRoots(RunState& rs) const;
    void findOwnUnits(RunState& rs) const;
    // The first unit at or after share node `code` (units.size() past the last).
    size_t firstUnitAt(const RunState& rs, uint64_t code) const;
    std::unique_ptr<GridFilePart> openPart(const RunState& rs, CellSink& sink) const;
    void logShare(const RunState& rs, const Stopwatch& rankStart) const;
    std::vector<std::byte> hashInTurn(const RunState& rs, CellSink& sink, GridFilePart* part) const;

    // The block holding pixel (ix, iy) of the raster.
    const Block& blockAt(size_t ix, size_t iy) const {
        const int32_t b = blockOf_[(iy >> shareLevel_) * nbx_ + (ix >> shareLevel_)];
        if (b < 0)
            throw Error("internal: pixel " + std::to_string(ix) + ", " + std::to_string(iy) +
                        " lies outside this rank's share");
        return blocks_[size_t(b)];
    }

    // Pixel at finest coordinates (ix east, iy north) from the SW corner, of block b (which holds it if it is inside
    // the raster); false if none.
    bool pixel(const Block& b, size_t ix, size_t iy, Node& n) const;

    // The share nodes (quadtree nodes of shareLevel_, in Morton order over the root square) of ranks 0 .. N - 1:
    // rank r takes codes [cut[r], cut[r + 1]), runs of about equal area inside the raster.
    std::vector<uint64_t> shareCuts(int rankCount) const;
    // Pass A's tiles (index ty * ntx + tx) inside share nodes [c0, c1).
    std::vector<size_t> tilesOf(uint64_t c0, uint64_t c1) const;
    // This rank's pixels: the whole raster, or (windows_) the windows of share nodes [c0, c1), read in maximal
    // aligned squares, in place of those held before. `first`: their first read (RasterWindows::read); `progress`: a
    // bar of its own. Returns the pixels read.
    uint64_t holdPixels(uint64_t c0, uint64_t c1, bool first, bool progress);
    // The valid pixels held.
    uint64_t validHeld() const;
    // One process reading by windows, no water steps, a raster over RasterWindows::heldPixelsMax: the pieces
    // (RunState::pieces) of share nodes [c0, c1); else none.
    std::vector<uint64_t> piecesOf(uint64_t c0, uint64_t c1, int rankCount) const;

    // The merge rule (build.h); (x, y) is the parent node at `level`, for the water steps' mask.
    Node merge(const Node& a, const Node& b, const Node& c, const Node& d, int level, size_t x, size_t y) const;

    // Builds tile (tx, ty)'s pyramid into scratch[level]; returns the root.
    const Node& buildTile(size_t tx, size_t ty, std::vector<std::vector<Node>>& scratch) const;

    // The cells of a built tile pyramid (its leaves whose parent is no leaf).
    size_t countLeaves(const std::vector<std::vector<Node>>& scratch) const;
    // Where emitTile writes and measures: the batch from `at` on, the worker's statistics, whether to paint the trace,
    // and the unit's sum of squared deviations (its cells in Morton order, each cell's pixels in rows).
    struct Emit {
        Batch& batch;
        size_t at;
        bool paint;
        Tally tally{};  // on the worker's stack: no cache line shared with another worker's
    };
    // Writes a tile's cells in Morton order, each measured (measureCell); returns how many. Its cells are the leaves of
    // its built pyramid `scratch`, or with none (a tile that merged no pixels) its valid pixels.
    size_t emitTile(size_t tx, size_t ty, const std::vector<std::vector<Node>>* scratch, Emit& out) const;
    // Whether a built tile pyramid merged any pixels.
    bool anyMerged(const std::vector<std::vector<Node>>& scratch) const;

    void writeCell(Batch& b, size_t at, size_t ix, size_t iy, int level, const Node& n) const;

    // The guarantee, measured: every valid pixel under the cell of `level` at (ix0, iy0) (in block px) against its
    // stored value, into t (the squared deviations added one by one, so that their sum has the same bits however the
    // cells are split).
    void measureCell(const Block& px, size_t ix0, size_t iy0, int level, float stored, Tally& t,
                     bool paintElevations) const;
    // Under mpirun every rank writes its own cells into rank 0's file (GridFilePart); then a rank other than 0 sends
    // its part's result (GridFilePart::finish) and its statistics (per-unit sums of squares) to rank 0, which receives
    // every other rank's in order, hands each part to its writer (GridFileWriter::addPart) and adds the statistics into
    // `sum`.
    void sendShare(const Stats& sum, const std::vector<double>& unitSumSq, const std::vector<std::byte>& part) const;
    void receiveShares(CellSink& sink, Stats& sum, std::vector<double>& unitSumSq) const;

    const Raster& t_;
    const RasterWindows* windows_;
    const MergeMask* mask_;
    std::optional<MergeMask> ownMask_;  // with water steps read by windows: the masks of this rank's nodes (run())
    const BuildOptions& opt_;
    int layers_;
    int rootLevel_, maxLevel_, tileLevel_;
    size_t tile_, ntx_, nty_;
    int shareLevel_ = 0;
    size_t nbx_ = 0, nby_ = 0;                                       // share nodes over the raster
    std::vector<Block> blocks_;                                      // the pixels this rank holds
    std::vector<int32_t> blockOf_;                                   // per share node (y * nbx + x): its block, or -1
    std::vector<std::vector<float>> windowValues_, windowRounding_;  // the windows' pixels (windows_ only)
};

}  // namespace hc::ingest::detail
