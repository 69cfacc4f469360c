// The bottom-up quadtree build. See build.h for the merge rule and the guarantee.
//
// The domain is cut into tiles of 2^tileLevel pixels. Pass A builds each tile's pyramid (in parallel)
// and keeps only its root summary and leaf count. Pass B merges tile roots up the coarse levels.
// Pass C walks the coarse tree in Morton order to give every tile its output offset, then rebuilds
// each tile's pyramid (cheap, cache-resident) and writes its cells straight into the final arrays:
// no sort, no reallocation, and memory beyond the raster and the grid stays at a few hundred kB.
//
// Shares (core/ranks/ranks.h; DESIGN.md section 13): the raster is cut into share nodes (quadtree nodes no finer than a
// tile or the coarsest cell), and under mpirun each rank takes a run of them in Morton order, about equal in area: the
// tiles of pass A and the units of pass C inside its nodes. The roots are exchanged between the two passes. Rank 0 opens
// the file; the other ranks write their cells into it at their place (GridFilePart), check and hash them in turn, and
// send rank 0 their block checksums and statistics; with a trace to paint they send rank 0 their cells instead, which it
// writes. A raster read window by window (RasterWindows) is read by each rank only over its own nodes, in maximal
// aligned squares: no rank holds it whole. The file is the same bytes for any number of ranks and threads: the squared
// deviations are summed per unit, then over the units in Morton order.
//
// Water (DESIGN.md section 11): every step's depth raster is read once before the build, one at a time, into a merge
// mask (a byte per quadtree node: may these four cells merge, for every step?), so the terrain build keeps every
// step's wet/dry edges and depth tolerance. After the cells are written, each step is read again and its depth per
// cell computed exactly as a merge would (the float mean of the four children's means, bottom up): with one step the
// cells and depths are those of a build over both layers at once. Under mpirun every rank computes the depths of its own
// cells (their codes kept as it writes them) and sends rank 0 the wet ones, in rank order, which is the cells' order:
// no rank holds every cell's code. With a raster read window by window, each rank reads only its windows of each step
// (RasterWindows::readStep, or a level's bathtub flooded over its windows and joined across the ranks: bathtubBlocks)
// and keeps the merge masks of its own windows; the levels above the tiles, where every rank merges every node, are
// combined over the ranks.
#include "heightcast/ingest/build.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <exception>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <unordered_map>

#include <fmt/format.h>

#include "heightcast/grid/grid_file.h"

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/ranks.h"
#include "heightcast/core/timer.h"

namespace hc::ingest {
namespace {

constexpr int kTileLevelMax = 6;    // 64 x 64 pixel tiles: a pyramid fits in L2

struct Node {
    std::array<float, 1> mean{}, lo{}, hi{};  // elevation
    bool leaf = false;  // a single cell covers the whole node
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
    MergeMask(size_t width, size_t height, int maxLevel, int fineTop, const std::vector<std::array<size_t, 4>>& windows, int windowLevel,
              std::vector<int32_t> windowOf, size_t windowNx)
        : levels_(size_t(maxLevel) + 1), fineTop_(fineTop), windowLevel_(windowLevel), windowOf_(std::move(windowOf)), windowNx_(windowNx) {
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

// A depth raster, or a window of one, as a Block: the whole raster's pixels at (0, 0).
Block wholeOf(const Raster& d) { return {0, 0, d.width, d.height, d.values.data(), nullptr}; }

// A depth pixel at finest coordinates (ix east, iy north of the south-west corner): NaN outside the block or on a hole.
float depthAt(const Block& d, size_t ix, size_t iy) {
    if (ix < d.x0 || iy < d.y0 || ix - d.x0 >= d.w || iy - d.y0 >= d.h) return std::numeric_limits<float>::quiet_NaN();
    return d.values[d.index(ix, iy)];
}

// The depth a merged cell of `level` at (ix, iy) holds: the float mean of its four children's, bottom up, in the order
// the build merges them (Builder::merge).
float cellMean(const Block& d, size_t ix, size_t iy, int level) {
    if (level == 0) return depthAt(d, ix, iy);
    const size_t h = size_t{1} << (level - 1);
    const double sum = static_cast<double>(cellMean(d, ix, iy, level - 1)) + cellMean(d, ix + h, iy, level - 1) +
                       cellMean(d, ix, iy + h, level - 1) + cellMean(d, ix + h, iy + h, level - 1);
    return static_cast<float>(sum * 0.25);
}

// Forbids in `mask` every merge step `d` does not allow: four children that are not all wet or all dry, or whose
// depths the parent's mean does not hold within the tolerance (build.h's rule for water). `d` is the whole raster, or a
// window of it whose corner lies on the top level's lattice (a rank's block: share nodes are no finer than the coarsest
// cell), holding every pixel of the nodes it starts (or the raster's edge).
void restrictByStep(const Block& d, double tolerance, int maxLevel, unsigned threads, MergeMask& mask) {
    if (maxLevel < 1) return;
    struct Depth {
        float mean = 0, lo = 0, hi = 0;
        uint8_t state = 0;  // 0: no merge possible (hole, outside, or a forbidden merge below), 1 dry, 2 wet
    };
    const int top = maxLevel;  // nodes of the top level are independent: one task each
    const size_t side = size_t{1} << top;
    if (d.x0 % side != 0 || d.y0 % side != 0) throw Error("internal: a depth window off the coarsest level's lattice");
    const size_t ox = d.x0 / side, oy = d.y0 / side;  // the window's first top-level node
    const size_t nx = (d.w + side - 1) / side, ny = (d.h + side - 1) / side;
    std::vector<std::vector<std::vector<Depth>>> scratch(resolveThreads(threads));
    std::vector<std::vector<std::pair<int, std::pair<size_t, size_t>>>> forbidden(scratch.size());
    parallelFor(nx * ny, 4, threads, [&](size_t b, size_t e, unsigned worker) {
        auto& lv = scratch[worker];
        lv.resize(size_t(top) + 1);
        for (size_t t = b; t < e; ++t) {
            const size_t tx = ox + t % nx, ty = oy + t / nx;
            size_t n = side;
            lv[0].resize(n * n);
            for (size_t y = 0; y < n; ++y)
                for (size_t x = 0; x < n; ++x) {
                    const float v = depthAt(d, tx * side + x, ty * side + y);
                    lv[0][y * n + x] = std::isnan(v) ? Depth{} : Depth{v, v, v, uint8_t(v > 0 ? 2 : 1)};
                }
            for (int l = 1; l <= top; ++l) {
                const size_t cn = n;
                n /= 2;
                auto& cur = lv[size_t(l)];
                const auto& ch = lv[size_t(l) - 1];
                cur.resize(n * n);
                for (size_t y = 0; y < n; ++y)
                    for (size_t x = 0; x < n; ++x) {
                        const size_t c = 2 * y * cn + 2 * x;
                        const Depth& p = ch[c];
                        const Depth& q = ch[c + 1];
                        const Depth& r = ch[c + cn];
                        const Depth& s = ch[c + cn + 1];
                        Depth out;
                        const bool same = p.state != 0 && p.state == q.state && q.state == r.state && r.state == s.state;
                        const bool anyData = p.state || q.state || r.state || s.state;
                        if (same) {
                            const double sum = static_cast<double>(p.mean) + q.mean + r.mean + s.mean;
                            out.mean = static_cast<float>(sum * 0.25);
                            out.lo = std::min({p.lo, q.lo, r.lo, s.lo});
                            out.hi = std::max({p.hi, q.hi, r.hi, s.hi});
                            if (static_cast<double>(out.hi) - out.mean <= tolerance && out.mean - static_cast<double>(out.lo) <= tolerance)
                                out.state = p.state;
                        }
                        if (out.state == 0 && anyData)
                            forbidden[worker].push_back({l, {((tx * side) >> l) + x, ((ty * side) >> l) + y}});
                        cur[y * n + x] = out;
                    }
            }
        }
    });
    for (const auto& list : forbidden)
        for (const auto& [l, xy] : list) mask.forbid(l, xy.first, xy.second);
}

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

class Builder {
public:
    // `terrain` gives the geometry, and the pixels unless `windows` reads them (RasterWindows: each rank then reads
    // only the windows of its share).
    Builder(const Raster& terrain, const RasterWindows* windows, const MergeMask* mask, const BuildOptions& opt, int rootLevel,
            int maxLevel)
        : t_(terrain), windows_(windows), mask_(mask), opt_(opt), layers_(1), rootLevel_(rootLevel), maxLevel_(maxLevel),
          tileLevel_(std::min(rootLevel, kTileLevelMax)), tile_(size_t{1} << tileLevel_),
          ntx_((terrain.width + tile_ - 1) / tile_), nty_((terrain.height + tile_ - 1) / tile_) {
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
    // The block holding pixel (ix, iy) of the raster.
    const Block& blockAt(size_t ix, size_t iy) const {
        const int32_t b = blockOf_[(iy >> shareLevel_) * nbx_ + (ix >> shareLevel_)];
        if (b < 0) throw Error("internal: pixel " + std::to_string(ix) + ", " + std::to_string(iy) + " lies outside this rank's share");
        return blocks_[size_t(b)];
    }

    // Pixel at finest coordinates (ix east, iy north) from the SW corner, of block b (which holds it if it is inside
    // the raster); false if none.
    bool pixel(const Block& b, size_t ix, size_t iy, Node& n) const {
        if (ix >= t_.width || iy >= t_.height) return false;
        const size_t idx = b.index(ix, iy);
        float z = b.values[idx];
        if (std::isnan(z)) return false;
        n.mean[0] = n.lo[0] = n.hi[0] = z;
        if (b.rounding && b.rounding[idx] != 0) {
            // The source's own value lies between lo and hi (float32 neighbours of it), so merges
            // checked against lo and hi keep the tolerance against the source, not only its rounding.
            const double exact = static_cast<double>(z) + b.rounding[idx];
            (exact > z ? n.hi[0] : n.lo[0]) = std::nextafter(z, exact > z ? HUGE_VALF : -HUGE_VALF);
        }
        n.leaf = true;
        return true;
    }

    // The share nodes (quadtree nodes of shareLevel_, in Morton order over the root square) of ranks 0 .. N - 1:
    // rank r takes codes [cut[r], cut[r + 1]), runs of about equal area inside the raster.
    std::vector<uint64_t> shareCuts(int rankCount) const;
    // Pass A's tiles (index ty * ntx + tx) inside share nodes [c0, c1).
    std::vector<size_t> tilesOf(uint64_t c0, uint64_t c1) const;
    // This rank's pixels: the whole raster, or (windows_) the windows of share nodes [c0, c1), read in maximal
    // aligned squares. Returns the pixels read.
    uint64_t holdPixels(uint64_t c0, uint64_t c1);

    // The merge rule (build.h); (x, y) is the parent node at `level`, for the water steps' mask.
    Node merge(const Node& a, const Node& b, const Node& c, const Node& d, int level, size_t x, size_t y) const {
        Node p;
        if (!(a.leaf && b.leaf && c.leaf && d.leaf) || level > maxLevel_) return p;
        if (mask_ && !mask_->allowed(level, x, y)) return p;
        for (int l = 0; l < layers_; ++l) {
            double sum = static_cast<double>(a.mean[l]) + b.mean[l] + c.mean[l] + d.mean[l];
            float m = static_cast<float>(sum * 0.25);
            float lo = std::min({a.lo[l], b.lo[l], c.lo[l], d.lo[l]});
            float hi = std::max({a.hi[l], b.hi[l], c.hi[l], d.hi[l]});
            // Checked against the stored float value, so the guarantee holds after rounding too.
            if (static_cast<double>(hi) - m > opt_.toleranceM || m - static_cast<double>(lo) > opt_.toleranceM) return p;
            p.mean[l] = m;
            p.lo[l] = lo;
            p.hi[l] = hi;
        }
        p.leaf = true;
        return p;
    }

    // Builds tile (tx, ty)'s pyramid into scratch[level]; returns the root.
    const Node& buildTile(size_t tx, size_t ty, std::vector<std::vector<Node>>& scratch) const {
        scratch.resize(static_cast<size_t>(tileLevel_) + 1);
        size_t side = tile_;
        scratch[0].assign(side * side, Node{});
        const Block& b = blockAt(tx * tile_, ty * tile_);  // a tile lies in one share node, so in one block
        for (size_t y = 0; y < side; ++y)
            for (size_t x = 0; x < side; ++x) pixel(b, tx * tile_ + x, ty * tile_ + y, scratch[0][y * side + x]);
        for (int l = 1; l <= tileLevel_; ++l) {
            size_t childSide = side;
            side /= 2;
            auto& cur = scratch[static_cast<size_t>(l)];
            const auto& ch = scratch[static_cast<size_t>(l) - 1];
            if (l > maxLevel_) {  // nothing merges above the coarsest level: skip the arithmetic
                cur.assign(side * side, Node{});
                continue;
            }
            cur.resize(side * side);
            for (size_t y = 0; y < side; ++y)
                for (size_t x = 0; x < side; ++x) {
                    size_t c = 2 * y * childSide + 2 * x;
                    cur[y * side + x] = merge(ch[c], ch[c + 1], ch[c + childSide], ch[c + childSide + 1], l, ((tx * tile_) >> l) + x,
                                              ((ty * tile_) >> l) + y);
                }
        }
        return scratch[static_cast<size_t>(tileLevel_)][0];
    }

    // Emits the leaves of a built tile pyramid in Morton order; returns how many.
    size_t emitTile(size_t tx, size_t ty, const std::vector<std::vector<Node>>& scratch, Batch* grid, size_t at) const {
        size_t count = 0;
        auto visit = [&](auto&& self, int l, size_t x, size_t y) -> void {
            size_t side = tile_ >> l;
            const Node& n = scratch[static_cast<size_t>(l)][y * side + x];
            if (n.leaf) {
                if (grid) writeCell(*grid, at + count, tx * tile_ + (x << l), ty * tile_ + (y << l), l, n);
                ++count;
                return;
            }
            if (l == 0) return;  // a hole
            for (int q = 0; q < 4; ++q) self(self, l - 1, 2 * x + (q & 1), 2 * y + (q >> 1));
        };
        visit(visit, tileLevel_, 0, 0);
        return count;
    }

    void writeCell(Batch& b, size_t at, size_t ix, size_t iy, int level, const Node& n) const {
        b.codes[at] = makeCellCode(mortonEncode(static_cast<uint32_t>(ix), static_cast<uint32_t>(iy)), level);
        for (int l = 0; l < layers_; ++l) b.values[static_cast<size_t>(l)][at] = n.mean[static_cast<size_t>(l)];
    }

    // The guarantee, measured: every valid pixel under cells [begin, end) of the batch against the stored value of its
    // cell (largest deviation, pixels and cells per level into acc); returns the sum of the squared deviations.
    double measure(const Batch& b, size_t begin, size_t end, Stats& acc, bool paintElevations) const;
    // Under mpirun every rank writes its own cells into rank 0's file (GridFilePart); then a rank other than 0 sends its
    // part's result (GridFilePart::finish) and its statistics (per-unit sums of squares) to rank 0, which receives every
    // other rank's in order, hands each part to its writer (GridFileWriter::addPart) and adds the statistics into `sum`.
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
    size_t nbx_ = 0, nby_ = 0;        // share nodes over the raster
    std::vector<Block> blocks_;       // the pixels this rank holds
    std::vector<int32_t> blockOf_;    // per share node (y * nbx + x): its block, or -1
    std::vector<std::vector<float>> windowValues_, windowRounding_;  // the windows' pixels (windows_ only)
};

std::vector<uint64_t> Builder::shareCuts(int rankCount) const {
    const uint64_t codes = uint64_t{1} << (2 * (rootLevel_ - shareLevel_));
    const size_t side = size_t{1} << shareLevel_;
    const uint64_t total = uint64_t(t_.width) * t_.height;
    std::vector<uint64_t> cut(size_t(rankCount) + 1, codes);
    cut[0] = 0;
    uint64_t before = 0;  // pixels of the raster in the nodes before code m
    int r = 1;
    for (uint64_t m = 0; m < codes && r < rankCount; ++m) {
        while (r < rankCount && before >= ranks::shareBegin(total, r, rankCount)) cut[size_t(r++)] = m;
        const size_t x = mortonX(m), y = mortonY(m);
        if (x < nbx_ && y < nby_) before += uint64_t(std::min(side, t_.width - x * side)) * std::min(side, t_.height - y * side);
    }
    return cut;
}

std::vector<size_t> Builder::tilesOf(uint64_t c0, uint64_t c1) const {
    std::vector<size_t> out;
    const size_t per = size_t{1} << (shareLevel_ - tileLevel_);  // tiles per share node side
    for (uint64_t m = c0; m < c1; ++m) {
        const size_t x = mortonX(m), y = mortonY(m);
        if (x >= nbx_ || y >= nby_) continue;
        for (size_t ty = y * per; ty < std::min(nty_, (y + 1) * per); ++ty)
            for (size_t tx = x * per; tx < std::min(ntx_, (x + 1) * per); ++tx) out.push_back(ty * ntx_ + tx);
    }
    return out;
}

uint64_t Builder::holdPixels(uint64_t c0, uint64_t c1) {
    blockOf_.assign(nbx_ * nby_, -1);
    blocks_.clear();
    if (!windows_) {
        blocks_.push_back({0, 0, t_.width, t_.height, t_.values.data(), t_.roundingM.empty() ? nullptr : t_.roundingM.data()});
        std::fill(blockOf_.begin(), blockOf_.end(), 0);
        return 0;
    }
    // Maximal aligned squares: from code m, the largest 4^k nodes that start at m and end by c1.
    struct Square {
        uint64_t m;
        int k;
    };
    std::vector<Square> squares;
    for (uint64_t m = c0; m < c1;) {
        int k = 0;
        while (shareLevel_ + k < rootLevel_ && m % (uint64_t{4} << (2 * k)) == 0 && m + (uint64_t{4} << (2 * k)) <= c1) ++k;
        squares.push_back({m, k});
        m += uint64_t{1} << (2 * k);
    }
    uint64_t read = 0;
    Progress progress("reading the raster's windows", squares.size(), opt_.progress && ranks::rank() == 0);
    for (const Square& q : squares) {
        const size_t x0 = size_t(mortonX(q.m)) << shareLevel_, y0 = size_t(mortonY(q.m)) << shareLevel_;
        const size_t side = size_t{1} << (shareLevel_ + q.k);
        progress.advance(1);
        if (x0 >= t_.width || y0 >= t_.height) continue;
        Block b{x0, y0, std::min(side, t_.width - x0), std::min(side, t_.height - y0), nullptr, nullptr};
        windowValues_.emplace_back();
        windowRounding_.emplace_back();
        windows_->read(b.x0, t_.height - (b.y0 + b.h), b.w, b.h, windowValues_.back(), windowRounding_.back());
        if (windowValues_.back().size() != b.w * b.h) throw Error("internal: a window read the wrong number of pixels");
        b.values = windowValues_.back().data();
        b.rounding = windowRounding_.back().empty() ? nullptr : windowRounding_.back().data();
        read += uint64_t(b.w) * b.h;
        for (size_t y = y0 >> shareLevel_; y < std::min(nby_, (y0 + side) >> shareLevel_); ++y)
            for (size_t x = x0 >> shareLevel_; x < std::min(nbx_, (x0 + side) >> shareLevel_); ++x) blockOf_[y * nbx_ + x] = int32_t(blocks_.size());
        blocks_.push_back(b);
    }
    progress.finish();
    return read;
}

std::vector<Block> Builder::stepBlocks(size_t k, std::vector<std::vector<float>>& storage, bool first) const {
    const bool levels = windows_ && !windows_->stepLevelsM.empty();
    if (!windows_ || (!windows_->readStep && !levels)) throw Error("internal: water steps by windows without a reader");
    std::vector<Block> out;
    storage.assign(blocks_.size(), {});
    if (levels) bathtubBlocks(windows_->stepLevelsM.at(k), storage);
    for (size_t i = 0; i < blocks_.size(); ++i) {
        const Block& b = blocks_[i];
        if (!levels) windows_->readStep(k, b.x0, t_.height - (b.y0 + b.h), b.w, b.h, b.values, storage[i], first);
        if (storage[i].size() != b.w * b.h) throw Error("internal: a water step's window read the wrong number of pixels");
        out.push_back({b.x0, b.y0, b.w, b.h, storage[i].data(), nullptr});
    }
    return out;
}

namespace {
// Union-find over the indices of `parent` (path halving); the smaller index becomes a set's root, so the same joins in
// the same order give the same roots. An index whose parent is -1 is in no set: callers keep it out of find and join.
template <class Index>
struct DisjointSets {
    std::vector<Index> parent;  // parent[i] == i: a root
    Index find(Index i) {
        while (parent[size_t(i)] != i) i = parent[size_t(i)] = parent[size_t(parent[size_t(i)])];
        return i;
    }
    void join(Index a, Index b) {
        a = find(a), b = find(b);
        if (a != b) parent[size_t(std::max(a, b))] = std::min(a, b);
    }
};
}  // namespace

// Each block labels the components of its pixels below the level (4-connected, union-find over its pixels) and seeds
// those that touch the raster's edge or a hole inside it. Its four edges (each pixel: its component's root and seed, a
// hole, or dry) go to every rank; every rank then joins the components that meet across two blocks' edges, and seeds
// those that meet a hole there, in the same order: the same answer everywhere. A pixel is wet when its component, so
// joined, holds a seed: exactly the pixels the whole raster's flood fill reaches.
void Builder::bathtubBlocks(double level, std::vector<std::vector<float>>& storage) const {
    constexpr int64_t kHole = -1, kDry = -2;
    const size_t W = t_.width, H = t_.height;
    struct Local {
        std::vector<int32_t> root;  // per pixel: its component's root pixel, -1 when not below the level
        std::vector<uint8_t> seed;  // per root pixel: the component touches the raster's edge or a hole in the block
    };
    std::vector<Local> local(blocks_.size());
    std::vector<int64_t> edges;  // per block: x0, y0, w, h, then its north, south, west and east edges' states
    for (size_t i = 0; i < blocks_.size(); ++i) {
        const Block& b = blocks_[i];
        Local& L = local[i];
        const size_t n = b.w * b.h;
        if (n > size_t(std::numeric_limits<int32_t>::max())) throw Error("internal: a window of more than 2^31 pixels for the bathtub");
        auto below = [&](size_t p) { return !std::isnan(b.values[p]) && b.values[p] < level; };
        DisjointSets<int32_t> sets;  // the pixels below the level; the others -1
        std::vector<int32_t>& parent = sets.parent;
        parent.assign(n, -1);
        for (size_t r = 0; r < b.h; ++r)  // row r of the block (north-up), column c
            for (size_t c = 0; c < b.w; ++c) {
                const size_t p = r * b.w + c;
                if (!below(p)) continue;
                parent[p] = int32_t(p);
                if (c > 0 && parent[p - 1] >= 0) sets.join(int32_t(p), int32_t(p - 1));
                if (r > 0 && parent[p - b.w] >= 0) sets.join(int32_t(p), int32_t(p - b.w));
            }
        L.seed.assign(n, 0);
        for (size_t r = 0; r < b.h; ++r)
            for (size_t c = 0; c < b.w; ++c) {
                const size_t p = r * b.w + c;
                if (parent[p] < 0) continue;
                parent[p] = sets.find(int32_t(p));
                const size_t ix = b.x0 + c, iy = b.y0 + b.h - 1 - r;
                // A neighbour outside the raster, or a hole inside this block: a seed (neighbours in other blocks: below).
                const bool edge = ix == 0 || iy == 0 || ix + 1 >= W || iy + 1 >= H;
                const bool hole = (c > 0 && std::isnan(b.values[p - 1])) || (c + 1 < b.w && std::isnan(b.values[p + 1])) ||
                                  (r > 0 && std::isnan(b.values[p - b.w])) || (r + 1 < b.h && std::isnan(b.values[p + b.w]));
                if (edge || hole) L.seed[size_t(parent[p])] = 1;
            }
        L.root = std::move(parent);  // every pixel below the level points at its root now
        edges.insert(edges.end(), {int64_t(b.x0), int64_t(b.y0), int64_t(b.w), int64_t(b.h)});
        auto state = [&](size_t r, size_t c) {
            const size_t p = r * b.w + c;
            if (std::isnan(b.values[p])) return kHole;
            if (L.root[p] < 0) return kDry;
            return int64_t(L.root[p]) * 2 + L.seed[size_t(L.root[p])];
        };
        for (size_t c = 0; c < b.w; ++c) edges.push_back(state(0, c));        // north
        for (size_t c = 0; c < b.w; ++c) edges.push_back(state(b.h - 1, c));  // south
        for (size_t r = 0; r < b.h; ++r) edges.push_back(state(r, 0));        // west
        for (size_t r = 0; r < b.h; ++r) edges.push_back(state(r, b.w - 1));  // east
    }
    // Every rank's blocks and edges, in rank order: block g's component with root pixel p is key g * 2^40 + p.
    const std::vector<std::vector<int64_t>> all = ranks::allGatherVectors(edges);
    struct Edges {
        size_t x0, y0, w, h;
        const int64_t* at;  // north (w), south (w), west (h), east (h)
    };
    std::vector<Edges> blocks;
    size_t mine = 0;  // this rank's first block
    for (size_t r = 0; r < all.size(); ++r) {
        if (int(r) == ranks::rank()) mine = blocks.size();
        for (size_t at = 0; at + 4 <= all[r].size();) {
            const int64_t* q = all[r].data() + at;
            const Edges e{size_t(q[0]), size_t(q[1]), size_t(q[2]), size_t(q[3]), q + 4};
            at += 4 + 2 * (e.w + e.h);
            if (at > all[r].size()) throw Error("internal: a rank sent a block's edges cut short");
            blocks.push_back(e);
        }
    }
    std::vector<int32_t> owner(nbx_ * nby_, -1);  // share node -> the block holding it
    for (size_t g = 0; g < blocks.size(); ++g)
        for (size_t y = blocks[g].y0 >> shareLevel_; y <= (blocks[g].y0 + blocks[g].h - 1) >> shareLevel_; ++y)
            for (size_t x = blocks[g].x0 >> shareLevel_; x <= (blocks[g].x0 + blocks[g].w - 1) >> shareLevel_; ++x) owner[y * nbx_ + x] = int32_t(g);
    // The state of pixel (ix, iy), which lies on an edge of its block.
    auto stateAt = [&](size_t ix, size_t iy) {
        const int32_t g = owner[(iy >> shareLevel_) * nbx_ + (ix >> shareLevel_)];
        if (g < 0) throw Error("internal: a pixel of the raster in no rank's block");
        const Edges& e = blocks[size_t(g)];
        const size_t c = ix - e.x0, r = e.y0 + e.h - 1 - iy;
        if (r == 0) return std::pair{size_t(g), e.at[c]};
        if (r == e.h - 1) return std::pair{size_t(g), e.at[e.w + c]};
        if (c == 0) return std::pair{size_t(g), e.at[2 * e.w + r]};
        return std::pair{size_t(g), e.at[2 * e.w + e.h + r]};
    };
    // The components on the blocks' edges, numbered as met (the same order on every rank), and their joins.
    auto key = [](size_t g, int64_t s) { return int64_t(g) * (int64_t{1} << 40) + s / 2; };
    std::unordered_map<int64_t, int64_t> ids;
    DisjointSets<int64_t> joins;
    auto id = [&](size_t g, int64_t s) {
        const auto [it, fresh] = ids.try_emplace(key(g, s), int64_t(joins.parent.size()));
        if (fresh) joins.parent.push_back(it->second);
        return it->second;
    };
    std::vector<int64_t> seeds;
    auto meet = [&](size_t g, int64_t s, size_t ix, size_t iy) {  // s: a below pixel of block g; (ix, iy) its neighbour
        if (ix >= W || iy >= H) return;  // outside the raster: seeded in its block already
        const auto [h, t] = stateAt(ix, iy);
        if (t == kHole) seeds.push_back(id(g, s));
        else if (t >= 0) {
            const int64_t a = id(g, s), c = id(h, t);  // numbered in this order
            joins.join(a, c);
        }
    };
    for (size_t g = 0; g < blocks.size(); ++g) {
        const Edges& e = blocks[g];
        for (size_t j = 0; j < 2 * (e.w + e.h); ++j)  // the components seeded in their own block
            if (e.at[j] >= 0 && (e.at[j] & 1)) seeds.push_back(id(g, e.at[j]));
        for (size_t c = 0; c < e.w; ++c) {
            const size_t ix = e.x0 + c;
            if (const int64_t s = e.at[c]; s >= 0) meet(g, s, ix, e.y0 + e.h);  // north of the north edge
            if (const int64_t s = e.at[e.w + c]; s >= 0 && e.y0 > 0) meet(g, s, ix, e.y0 - 1);
        }
        for (size_t r = 0; r < e.h; ++r) {
            const size_t iy = e.y0 + e.h - 1 - r;
            if (const int64_t s = e.at[2 * e.w + r]; s >= 0 && e.x0 > 0) meet(g, s, e.x0 - 1, iy);
            if (const int64_t s = e.at[2 * e.w + e.h + r]; s >= 0) meet(g, s, e.x0 + e.w, iy);
        }
    }
    std::vector<uint8_t> wet(joins.parent.size(), 0);  // per root: its joined component holds a seed
    for (int64_t s : seeds) wet[size_t(joins.find(s))] = 1;
    for (size_t i = 0; i < blocks_.size(); ++i) {
        const Block& b = blocks_[i];
        Local& L = local[i];
        std::vector<float>& d = storage[i];
        d.assign(b.w * b.h, 0.0f);
        for (size_t p = 0; p < d.size(); ++p)  // each component's answer once, at its root (its least pixel: first)
            if (L.root[p] == int32_t(p) && !L.seed[p] && !seeds.empty())
                if (const auto it = ids.find(key(mine + i, int64_t(p) * 2)); it != ids.end()) L.seed[p] = wet[size_t(joins.find(it->second))];
        for (size_t p = 0; p < d.size(); ++p) {
            if (std::isnan(b.values[p])) {
                d[p] = std::numeric_limits<float>::quiet_NaN();
                continue;
            }
            const int32_t root = L.root[p];
            if (root >= 0 && L.seed[size_t(root)]) d[p] = static_cast<float>(level - b.values[p]);
        }
    }
}

Stats Builder::run(CellSink& sink) {
    const unsigned threads = resolveThreads(opt_.threads);
    const size_t tiles = ntx_ * nty_;
    // Under mpirun (ranks.h) each rank builds a contiguous share of the tiles, then of the cells, and writes those into
    // rank 0's file at their place. One process is rank 0 of 1: all of it.
    const int rank = ranks::rank(), rankCount = ranks::count();
    const bool root = rank == 0;
    // Ranks write into a file, never into a grid in memory, and paint no trace (the tools read rasters by windows under
    // mpirun, and a trace is painted without windows only): the same answer on every rank, so all of them throw.
    if (rankCount > 1 && (!sink.fileShape() || opt_.cellElevations))
        throw Error("internal: under mpirun the grid is built into a file (each rank writes its own cells there) and without a trace of "
                    "the source; an in-memory grid or a trace is built by one process");
    const auto rankStart = Stopwatch();

    // The shares: runs of share nodes in Morton order, about equal in area. A rank builds the tiles (pass A) and writes
    // the cells (pass C) inside its own nodes, so it reads (windows_) or touches only their pixels.
    const std::vector<uint64_t> cuts = shareCuts(rankCount);
    const std::vector<size_t> myTiles = tilesOf(cuts[size_t(rank)], cuts[size_t(rank) + 1]);
    uint64_t pixelsRead = 0;
    ranks::together([&] { pixelsRead = holdPixels(cuts[size_t(rank)], cuts[size_t(rank) + 1]); });
    if (windows_ && windows_->checkHeld) {
        uint64_t valid = 0;
        for (const Block& b : blocks_) valid += uint64_t(std::count_if(b.values, b.values + b.w * b.h, [](float v) { return !std::isnan(v); }));
        uint64_t all = 0;
        for (const auto& v : ranks::allGatherVectors(std::vector<uint64_t>{valid})) all += v.empty() ? 0 : v[0];
        ranks::together([&] { windows_->checkHeld(all); });
    }
    // Water steps read by windows: each step's merge mask over this rank's own nodes (every merge lies inside a share
    // node, so in one of its blocks), from the same windows of each step raster.
    if (windows_ && !windows_->stepTimesS.empty()) {
        const size_t steps = windows_->stepTimesS.size();
        Progress progress("water steps: wet/dry edges", steps, opt_.progress && root && steps > 1);
        ranks::together([&] {
            std::vector<std::array<size_t, 4>> windows;  // the mask over this rank's windows only, up to the tiles
            for (const Block& b : blocks_) windows.push_back({b.x0, b.y0, b.w, b.h});
            ownMask_.emplace(t_.width, t_.height, maxLevel_, tileLevel_, windows, shareLevel_, blockOf_, nbx_);
            for (size_t k = 0; k < steps; ++k) {
                std::vector<std::vector<float>> storage;
                for (const Block& b : stepBlocks(k, storage, true)) restrictByStep(b, opt_.toleranceM, maxLevel_, opt_.threads, *ownMask_);
                progress.advance(1);
            }
        });
        // Above the tiles every rank merges every node (pass B): the levels there, a byte per 4^7 pixels or fewer, are
        // combined over the ranks, each of which forbade merges in its own nodes only.
        for (int l = tileLevel_ + 1; l <= maxLevel_; ++l)
            for (const auto& other : ranks::allGatherVectors(ownMask_->level(l))) ownMask_->forbidAlso(l, other);
        progress.finish();
        mask_ = &*ownMask_;
    }

    // Pass A: tile roots and leaf counts.
    std::vector<Node> roots(tiles);
    std::vector<uint32_t> leafCount(tiles);
    {
        Progress progress("building quadtree", 2 * tiles, opt_.progress && root);
        std::vector<std::vector<std::vector<Node>>> scratch(threads);
        ranks::together([&] {
            parallelFor(myTiles.size(), 16, threads, [&](size_t b, size_t e, unsigned worker) {
                for (size_t k = b; k < e; ++k) {
                    const size_t i = myTiles[k], tx = i % ntx_, ty = i / ntx_;
                    roots[i] = buildTile(tx, ty, scratch[worker]);
                    leafCount[i] = static_cast<uint32_t>(emitTile(tx, ty, scratch[worker], nullptr, 0));
                }
                progress.advance((e - b) * size_t(rankCount));
            });
        });
        if (rankCount > 1) {  // every rank needs every root for the coarse levels and the walk
            std::vector<Node> myRoots;
            std::vector<uint32_t> myCounts;
            for (size_t i : myTiles) myRoots.push_back(roots[i]), myCounts.push_back(leafCount[i]);
            const auto allRoots = ranks::allGatherVectors(myRoots);
            const auto allCounts = ranks::allGatherVectors(myCounts);
            for (int r = 0; r < rankCount; ++r) {
                if (r == rank) continue;
                const std::vector<size_t> theirs = tilesOf(cuts[size_t(r)], cuts[size_t(r) + 1]);
                if (allRoots[size_t(r)].size() != theirs.size() || allCounts[size_t(r)].size() != theirs.size())
                    throw Error("rank " + std::to_string(r + 1) + " sent " + std::to_string(allRoots[size_t(r)].size()) + " tile roots, not " +
                                std::to_string(theirs.size()));
                for (size_t k = 0; k < theirs.size(); ++k) roots[theirs[k]] = allRoots[size_t(r)][k], leafCount[theirs[k]] = allCounts[size_t(r)][k];
            }
        }

        // Pass B: coarse levels over tile roots, level tileLevel+1 .. rootLevel.
        std::vector<std::vector<Node>> coarse{roots};
        std::vector<std::pair<size_t, size_t>> dims{{ntx_, nty_}};
        for (int l = tileLevel_ + 1; l <= rootLevel_; ++l) {
            const size_t cw = dims.back().first, chh = dims.back().second;  // not a structured binding: the lambda below
                                                                             // captures them (clang 14 cannot)
            size_t nw = (cw + 1) / 2, nh = (chh + 1) / 2;
            const auto& ch = coarse.back();
            std::vector<Node> cur(nw * nh);
            auto child = [&](size_t x, size_t y) -> Node { return (x < cw && y < chh) ? ch[y * cw + x] : Node{}; };
            for (size_t y = 0; y < nh; ++y)
                for (size_t x = 0; x < nw; ++x)
                    cur[y * nw + x] = merge(child(2 * x, 2 * y), child(2 * x + 1, 2 * y), child(2 * x, 2 * y + 1),
                                            child(2 * x + 1, 2 * y + 1), l, x, y);
            coarse.push_back(std::move(cur));
            dims.emplace_back(nw, nh);
        }

        // Pass C, walk: units in Morton order. A unit is a merged coarse cell or one tile.
        struct Unit {
            size_t x, y;  // node coordinates at its level
            int level;    // absolute level; tileLevel_ means "a tile"
            size_t offset;
        };
        std::vector<Unit> units;
        size_t total = 0;
        auto walk = [&](auto&& self, int l, size_t x, size_t y) -> void {
            auto k = static_cast<size_t>(l - tileLevel_);
            auto [cw, chh] = dims[k];
            if (x >= cw || y >= chh) return;
            const Node& n = coarse[k][y * cw + x];
            if (l == tileLevel_) {
                size_t count = leafCount[y * ntx_ + x];
                if (count > 0) units.push_back({x, y, l, total});
                total += count;
                return;
            }
            if (n.leaf) {
                units.push_back({x, y, l, total});
                total += 1;
                return;
            }
            for (int q = 0; q < 4; ++q) self(self, l - 1, 2 * x + (q & 1), 2 * y + (q >> 1));
        };
        walk(walk, rootLevel_, 0, 0);

        // This rank's units: those inside its share nodes (a unit, no larger than a share node, lies in one; the
        // units' nodes ascend in Morton order as the units do).
        const int shareLevel = shareLevel_;  // captured by value below
        auto firstUnit = [&](int r) {
            return size_t(std::lower_bound(units.begin(), units.end(), cuts[size_t(r)], [shareLevel](const Unit& u, uint64_t c) {
                              return mortonEncode(uint32_t((u.x << u.level) >> shareLevel), uint32_t((u.y << u.level) >> shareLevel)) < c;
                          }) - units.begin());
        };
        const size_t myU0 = firstUnit(rank), myU1 = rank + 1 == rankCount ? units.size() : firstUnit(rank + 1);
        auto offsetOf = [&](size_t u) { return u < units.size() ? units[u].offset : total; };
        const size_t myCells = offsetOf(myU1) - offsetOf(myU0);

        ranks::together([&] {
            if (total == 0)
                throw Error((windows_ && !windows_->source.empty() ? windows_->source + ": " : std::string()) +
                            "the raster holds no valid pixel (all nodata): nothing to build");
            if (root) sink.begin(total);
        });
        // Under mpirun every rank writes its own cells into rank 0's file in place (GridFilePart): rank 0 says where, the
        // others open their parts. (With water steps each rank keeps its own cells' codes: CellSink::keepOwn.)
        std::unique_ptr<GridFilePart> part;
        if (rankCount > 1) {
            std::vector<std::byte> where;
            if (root) {
                GridFileWriter* w = sink.sharedWriter();
                if (!w) throw Error("internal: under mpirun rank 1's sink has no file for the ranks to write into");
                where = w->placement();
            }
            where = std::move(ranks::allGather(where)[0]);
            ranks::together([&] {
                if (!root) part = std::make_unique<GridFilePart>(where, *sink.fileShape(), offsetOf(myU0));
            });
        }

        // Pass C, write: batches of consecutive units (about 64 k cells, a few MB), filled in parallel, measured, and
        // handed to the sink in order (another rank writes them into the file at their place, to read them back in its
        // turn of the hashes). The squared
        // deviations are summed per unit, then over the units in order: the same figure (bits) on any number of
        // threads and ranks.
        std::vector<Stats> acc(threads);
        for (auto& a : acc) a.perLevel.assign(static_cast<size_t>(maxLevel_) + 1, 0);
        std::vector<double> unitSumSq(myU1 - myU0, 0.0);
        Batch batch;
        batch.values.resize(static_cast<size_t>(layers_));
        ranks::together([&] {
            size_t u0 = myU0;
            while (u0 < myU1) {
                size_t u1 = u0;
                const size_t first = units[u0].offset;
                while (u1 < myU1 && (u1 == u0 || units[u1].offset - first < (size_t{1} << 16))) ++u1;
                const size_t last = offsetOf(u1);
                batch.codes.resize(last - first);
                for (auto& v : batch.values) v.resize(last - first);
                parallelFor(u1 - u0, 1, threads, [&](size_t b, size_t e, unsigned worker) {
                    size_t tilesDone = 0;
                    for (size_t k = u0 + b; k < u0 + e; ++k) {
                        const Unit& unit = units[k];
                        const size_t at = unit.offset - first;
                        size_t written = 1;
                        if (unit.level > tileLevel_) {
                            auto lk = static_cast<size_t>(unit.level - tileLevel_);
                            const Node& n = coarse[lk][unit.y * dims[lk].first + unit.x];
                            size_t span = size_t{1} << unit.level;
                            writeCell(batch, at, unit.x * span, unit.y * span, unit.level, n);
                        } else {
                            buildTile(unit.x, unit.y, scratch[worker]);
                            written = emitTile(unit.x, unit.y, scratch[worker], &batch, at);
                            assert(written == leafCount[unit.y * ntx_ + unit.x]);
                            ++tilesDone;
                        }
                        unitSumSq[k - myU0] = measure(batch, at, at + written, acc[worker], root);
                    }
                    progress.advance(tilesDone * size_t(rankCount));
                });
                if (root) {
                    std::vector<std::span<const float>> values(batch.values.begin(), batch.values.end());
                    sink.append(batch.codes, values);
                } else {  // into the file at its place; read back for the hashes (nothing held)
                    part->append(batch.codes, std::vector<std::span<const float>>(batch.values.begin(), batch.values.end()));
                    sink.keepOwn(batch.codes);
                }
                u0 = u1;
            }
        });
        Stats sum;
        sum.perLevel.assign(static_cast<size_t>(maxLevel_) + 1, 0);
        sum.firstCell = offsetOf(myU0), sum.ownCells = myCells;
        for (const Stats& a : acc) {
            sum.maxDev = std::max(sum.maxDev, a.maxDev);
            sum.pixels += a.pixels;
            sum.wetCells += a.wetCells;
            for (size_t l = 0; l < a.perLevel.size(); ++l) sum.perLevel[l] += a.perLevel[l];
        }
        const std::string reads = windows_ ? fmt::format("{} window{} read, {} px ({:.1f} % of the raster), ", blocks_.size(), blocks_.size() == 1 ? "" : "s", pixelsRead,
                                                         100.0 * double(pixelsRead) / double(t_.width * t_.height))
                                           : std::string("the whole raster held, ");
        ranks::log("hc-ingest", fmt::format("{}{} tiles of {}^2 px built, {} units, {} cells written, {:.3f} s, peak {:.1f} MB resident", reads,
                                            myTiles.size(), 1u << tileLevel_, myU1 - myU0, myCells, rankStart.seconds(), double(peakRssBytes()) / 1e6));
        std::vector<std::byte> partResult;
        if (rankCount > 1) {
            // The hashes (one stream over the whole file) and the order check's seam go on from rank to rank in Morton
            // order (the checks, summaries and writing above went on in parallel): each rank in turn takes the state the
            // ranks before it left, hashes its own cells from it (read back from the file: its page cache, as it just
            // wrote them) and passes it on. Then each flushes its part.
            const Stopwatch chain;
            std::vector<std::byte> state;
            if (root) state = sink.sharedWriter()->streamState();
            state = std::move(ranks::allGather(state)[0]);
            for (int r = 1; r < rankCount; ++r) {
                std::vector<std::byte> next;
                ranks::together([&] {
                    if (rank != r) return;
                    part->resume(state);
                    part->follow();
                    next = part->state();
                });
                state = std::move(ranks::allGather(next)[size_t(r)]);
            }
            const double inTurn = chain.seconds();
            ranks::together([&] {
                if (part) partResult = part->finish();
            });
            if (!root)
                ranks::log("hc-ingest", fmt::format("its {} cells ({:.1f} MB) written into the output in place; hashes in turn {:.3f} s (all ranks), flush {:.3f} s",
                                                    myCells, double(myCells) * double(8 + 4 * layers_) / 1e6, inTurn, chain.seconds() - inTurn));
        }
        if (!root) {
            sendShare(sum, unitSumSq, partResult);
            return sum;
        }
        receiveShares(sink, sum, unitSumSq);
        if (unitSumSq.size() != units.size())
            throw Error("ranks sent statistics of " + std::to_string(unitSumSq.size()) + " units, not " + std::to_string(units.size()));
        for (double u : unitSumSq) sum.sumSq += u;
        progress.advance(2 * tiles);  // units cover fewer than all tiles; fill the bar
        progress.finish();
        return sum;
    }
}

void Builder::sendShare(const Stats& sum, const std::vector<double>& unitSumSq, const std::vector<std::byte>& part) const {
    ranks::sendToRoot(part);
    std::vector<double> table{sum.maxDev, double(sum.pixels), double(sum.wetCells)};  // then cells per level, then the unit sums
    for (uint64_t c : sum.perLevel) table.push_back(double(c));
    table.insert(table.end(), unitSumSq.begin(), unitSumSq.end());
    ranks::sendToRoot(table);
}

void Builder::receiveShares(CellSink& sink, Stats& sum, std::vector<double>& unitSumSq) const {
    // A sink that fails (a full disk) must not leave a sender blocked: every rank's part and statistics are still
    // received, and the first failure thrown at the end.
    std::exception_ptr failed;
    for (int r = 1; r < ranks::count(); ++r) {
        const std::vector<std::byte> part = ranks::receiveFrom(r);
        try {
            if (!failed) sink.sharedWriter()->addPart(part);
        } catch (...) {
            failed = std::current_exception();
        }
        const std::vector<double> table = ranks::receiveVectorFrom<double>(r);
        const size_t levels = sum.perLevel.size();
        if (table.size() < 3 + levels) throw Error("rank " + std::to_string(r + 1) + ": a short statistics table");
        sum.maxDev = std::max(sum.maxDev, table[0]);
        sum.pixels += uint64_t(table[1]);
        sum.wetCells += uint64_t(table[2]);
        for (size_t l = 0; l < levels; ++l) sum.perLevel[l] += uint64_t(table[3 + l]);
        unitSumSq.insert(unitSumSq.end(), table.begin() + ptrdiff_t(3 + levels), table.end());
    }
    if (failed) std::rethrow_exception(failed);
}

double Builder::measure(const Batch& b, size_t begin, size_t end, Stats& a, bool paintElevations) const {
    double sumSq = 0;
    for (size_t i = begin; i < end; ++i) {
        const uint64_t key = codeKey(b.codes[i]);
        const int level = codeLevel(b.codes[i]);
        ++a.perLevel[static_cast<size_t>(level)];
        const size_t span = size_t{1} << level;
        const size_t ix0 = mortonX(key), iy0 = mortonY(key);
        const double z = b.values[0][i];
        const Block& px = blockAt(ix0, iy0);  // a cell lies in one share node
        for (size_t iy = iy0; iy < iy0 + span; ++iy) {
            for (size_t ix = ix0; ix < ix0 + span; ++ix) {
                const size_t idx = px.index(ix, iy);
                const double exact = static_cast<double>(px.values[idx]) + (px.rounding ? px.rounding[idx] : 0.0);
                const double dz = exact - z;
                if (paintElevations && opt_.cellElevations) (*opt_.cellElevations)[(t_.height - 1 - iy) * t_.width + ix] = b.values[0][i];
                sumSq += dz * dz;
                a.maxDev = std::max(a.maxDev, std::abs(dz));
                ++a.pixels;
            }
        }
    }
    return sumSq;
}

}  // namespace

namespace {

// The grid's geometry for a raster: origin at its south-west corner, finest cell = its pixel.
// `windowed`: the raster's values are read window by window (RasterWindows), not held in terrain.values.
Grid shapeFor(const Raster& terrain, bool water, const BuildOptions& options, int& rootLevel, int& maxLevel, bool windowed = false) {
    if (terrain.width == 0 || terrain.height == 0 || (!windowed && terrain.values.size() != terrain.width * terrain.height))
        throw Error("raster is empty or inconsistent");
    if (!(options.toleranceM >= 0) || !std::isfinite(options.toleranceM)) throw Error("tolerance must be a finite number >= 0");
    if (!(terrain.pixelSizeM > 0)) throw Error("pixel size must be positive");
    if (!terrain.roundingM.empty() && terrain.roundingM.size() != terrain.values.size())
        throw Error("terrain rounding does not match the terrain raster");
    rootLevel = 0;
    while ((size_t{1} << rootLevel) < std::max(terrain.width, terrain.height)) ++rootLevel;
    if (rootLevel > kMaxRootLevel) throw Error("raster of " + std::to_string(terrain.width) + " x " +
                                               std::to_string(terrain.height) + " pixels is too large for one grid");
    maxLevel = std::clamp(options.maxLevel, 0, rootLevel);
    Grid g;
    g.originWorldX = terrain.westWorld;
    g.originWorldY = terrain.southWorld();
    g.finestCellM = terrain.pixelSizeM;
    g.rootLevel = rootLevel;
    g.minLevel = 0;
    g.maxLevel = maxLevel;
    g.crsWkt = terrain.crsWkt;
    g.crsName = terrain.crsName;
    if (water) {
        g.layers.push_back({"water_depth", "m"});
        g.values.emplace_back();
    }
    g.stats.sourceWidth = terrain.width;
    g.stats.sourceHeight = terrain.height;
    g.stats.toleranceM = options.toleranceM;
    return g;
}

void checkStepRaster(const Raster& terrain, const Raster& d, size_t k) {
    if (d.width != terrain.width || d.height != terrain.height || d.values.size() != terrain.values.size())
        throw Error("water step " + std::to_string(k) + ": depth raster does not match the terrain raster's geometry");
}

// The merge mask of every step, each step's raster read once (WaterSteps::load), or nullopt without water.
std::optional<MergeMask> maskOf(const Raster& terrain, const WaterSteps* steps, const BuildOptions& opt, int maxLevel) {
    if (!steps || steps->count == 0) return std::nullopt;
    MergeMask mask(terrain.width, terrain.height, maxLevel);
    Progress progress("water steps: wet/dry edges", steps->count, opt.progress && steps->count > 1);
    for (size_t k = 0; k < steps->count; ++k) {
        const Raster d = steps->load(k);
        checkStepRaster(terrain, d, k);
        restrictByStep(wholeOf(d), opt.toleranceM, maxLevel, opt.threads, mask);
        progress.advance(1);
    }
    progress.finish();
    return mask;
}

// One step's depth per cell (cellMean) for the cells `codes`: the wet ones (> 0) in stored form, and the largest
// |pixel - cell depth| over the pixels the cells cover. viewOf(ix, iy): the depths (the whole raster, or the rank's
// block) holding the cell whose south-west pixel is (ix, iy), and so all its pixels.
WaterStepData stepValues(const std::function<const Block&(size_t ix, size_t iy)>& viewOf, std::span<const uint64_t> codes, double timeS,
                         unsigned threads, double& maxDev) {
    struct Part {
        std::vector<uint32_t> wet;
        std::vector<float> depth;
        double maxDev = 0;
    };
    const size_t chunk = size_t{1} << 16;
    std::vector<Part> parts((codes.size() + chunk - 1) / chunk);
    parallelFor(parts.size(), 1, threads, [&](size_t b, size_t e, unsigned) {
        for (size_t c = b; c < e; ++c) {
            Part& part = parts[c];
            for (size_t i = c * chunk; i < std::min(codes.size(), (c + 1) * chunk); ++i) {
                const uint64_t key = codeKey(codes[i]);
                const int level = codeLevel(codes[i]);
                const size_t ix = mortonX(key), iy = mortonY(key), span = size_t{1} << level;
                const Block& d = viewOf(ix, iy);
                const float m = cellMean(d, ix, iy, level);
                for (size_t y = iy; y < iy + span; ++y)
                    for (size_t x = ix; x < ix + span; ++x)
                        part.maxDev = std::max(part.maxDev, std::abs(static_cast<double>(depthAt(d, x, y)) - m));
                if (m > 0) {
                    part.wet.push_back(static_cast<uint32_t>(i));
                    part.depth.push_back(m);
                }
            }
        }
    });
    WaterStepData out;
    out.timeS = timeS;
    out.values.resize(1);
    for (const Part& p : parts) {
        out.wet.insert(out.wet.end(), p.wet.begin(), p.wet.end());
        out.values[0].insert(out.values[0].end(), p.depth.begin(), p.depth.end());
        maxDev = std::max(maxDev, p.maxDev);
    }
    return out;
}

void fillStats(const Stats& st, IngestStats& out) {
    out.maxDevM = st.maxDev;
    out.rmsDevM = st.pixels ? std::sqrt(st.sumSq / static_cast<double>(st.pixels)) : 0.0;
    out.validPixels = st.pixels;
}

class GridSink : public CellSink {
public:
    explicit GridSink(Grid& g) : g_(g) {}
    void begin(uint64_t cellCount) override {
        g_.codes.reserve(cellCount);
        g_.values[0].reserve(cellCount);
    }
    void append(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& values) override {
        g_.codes.insert(g_.codes.end(), codes.begin(), codes.end());
        g_.values[0].insert(g_.values[0].end(), values[0].begin(), values[0].end());
    }

private:
    Grid& g_;
};

// Streams the cells into a GridFileWriter; keeps their codes (8 bytes a cell) when water steps follow.
class FileSink : public CellSink {
public:
    FileSink(const std::string& path, const Grid& shape, size_t steps) : path_(path), shape_(shape), steps_(steps) {}
    void begin(uint64_t cellCount) override {
        if (cellCount == 0) throw Error("the raster holds no valid pixel (all nodata): nothing to build");
        if (steps_ > 0 && cellCount > UINT32_MAX)
            throw Error(std::to_string(cellCount) + " cells: a grid with water steps holds at most 2^32 - 1 cells");
        writer_ = std::make_unique<GridFileWriter>(path_, shape_, cellCount, steps_);
        if (steps_ > 0 && !ranks::distributed()) codes.reserve(cellCount);  // under mpirun rank 0 keeps its own share
    }
    void append(std::span<const uint64_t> c, const std::vector<std::span<const float>>& values) override {
        writer_->append(c, values);
        keepOwn(c);
    }
    // Water steps: each rank computes the depths of its own cells (buildFile), so it keeps their codes.
    void keepOwn(std::span<const uint64_t> c) override {
        if (steps_ > 0) codes.insert(codes.end(), c.begin(), c.end());
    }
    GridFileWriter& writer() { return *writer_; }
    GridFileWriter* sharedWriter() override { return writer_.get(); }
    const Grid* fileShape() const override { return &shape_; }
    std::vector<uint64_t> codes;  // with water steps: the cells appended or kept, in order

private:
    std::string path_;
    const Grid& shape_;
    size_t steps_;
    std::unique_ptr<GridFileWriter> writer_;
};

}  // namespace

Grid buildGrid(const Raster& terrain, const Raster* waterDepth, const BuildOptions& options) {
    int rootLevel = 0, maxLevel = 0;
    Grid g = shapeFor(terrain, waterDepth != nullptr, options, rootLevel, maxLevel);
    WaterSteps one;
    if (waterDepth) {
        checkStepRaster(terrain, *waterDepth, 0);
        one.count = 1;
        one.timesS = {0.0};
        one.load = [&](size_t) { return *waterDepth; };
    }
    const std::optional<MergeMask> mask = maskOf(terrain, waterDepth ? &one : nullptr, options, maxLevel);
    GridSink sink(g);
    if (options.cellElevations) options.cellElevations->assign(terrain.values.size(), std::numeric_limits<float>::quiet_NaN());
    Stats st = Builder(terrain, nullptr, mask ? &*mask : nullptr, options, rootLevel, maxLevel).run(sink);
    if (g.cellCount() == 0) throw Error("the raster holds no valid pixel (all nodata): nothing to build");
    if (waterDepth) {
        g.values[1].clear();
        const Block whole = wholeOf(*waterDepth);
        const WaterStepData data = stepValues([&](size_t, size_t) -> const Block& { return whole; }, g.codes, 0.0, options.threads, st.maxDev);
        selectStep(g, data, 0);
    }
    fillStats(st, g.stats);
    assert(g.validate().empty());
    return g;
}

namespace {

// buildGridFile, its pixels from terrain.values or read window by window (`windows`; without water steps).
BuildSummary buildFile(const Raster& terrain, const RasterWindows* windows, const WaterSteps* steps, const BuildOptions& options,
                       const std::string& path, const IngestStats& extraStats) {
    const Stopwatch clock;
    int rootLevel = 0, maxLevel = 0;
    const size_t stepCount = steps ? steps->count : 0;
    if (steps && steps->timesS.size() != stepCount) throw Error("water steps: " + std::to_string(steps->timesS.size()) + " times for " + std::to_string(stepCount) + " steps");
    for (size_t k = 1; k < stepCount; ++k)
        if (!(steps->timesS[k] > steps->timesS[k - 1]))
            throw Error("water step times must increase strictly: step " + std::to_string(k) + " at " + std::to_string(steps->timesS[k]) +
                        " s follows " + std::to_string(steps->timesS[k - 1]) + " s");
    BuildSummary out;
    if (windows && options.cellElevations) throw Error("internal: a raster read by windows is built without a trace");
    out.shape = shapeFor(terrain, stepCount > 0, options, rootLevel, maxLevel, windows != nullptr);
    // Steps read by windows: each rank makes the masks of its own nodes (Builder::run).
    const std::optional<MergeMask> mask = windows ? std::nullopt : maskOf(terrain, steps, options, maxLevel);
    FileSink sink(path, out.shape, stepCount);
    const bool root = ranks::rank() == 0;  // under mpirun, rank 0 commits the file (Builder::run)
    if (options.cellElevations && root) options.cellElevations->assign(terrain.values.size(), std::numeric_limits<float>::quiet_NaN());
    Builder builder(terrain, windows, mask ? &*mask : nullptr, options, rootLevel, maxLevel);
    Stats st = builder.run(sink);
    for (uint64_t c : st.perLevel) out.cellCount += c;  // on rank 0 every rank's cells, on another its share
    if (stepCount > 0) {
        // Each step's depth per cell: every rank over its own cells (the codes its sink kept), the wet ones sent to rank 0
        // in rank order, which is the cells' order.
        if (sink.codes.size() < st.ownCells) throw Error("internal: a rank kept fewer codes than it has cells");
        const std::span<const uint64_t> own = std::span<const uint64_t>(sink.codes).first(st.ownCells);
        const Stopwatch stepClock;
        Progress progress("water steps: depth per cell", stepCount, options.progress && root);
        for (size_t k = 0; k < stepCount; ++k) {
            WaterStepData data;
            double maxDev = 0;
            ranks::together([&] {
                if (windows) {  // the same windows of the step as of the terrain: every own cell lies in one
                    std::vector<std::vector<float>> storage;
                    const std::vector<Block> views = builder.stepBlocks(k, storage, false);
                    auto viewOf = [&](size_t ix, size_t iy) -> const Block& { return views[builder.blockIndexAt(ix, iy)]; };
                    data = stepValues(viewOf, own, steps->timesS[k], options.threads, maxDev);
                } else {
                    const Raster d = steps->load(k);
                    checkStepRaster(terrain, d, k);
                    const Block whole = wholeOf(d);
                    data = stepValues([&](size_t, size_t) -> const Block& { return whole; }, own, steps->timesS[k], options.threads, maxDev);
                }
                for (uint32_t& i : data.wet) i = uint32_t(i + st.firstCell);  // < 2^32: FileSink::begin
            });
            if (!root) {  // after the agreement: rank 0 receives every piece
                ranks::sendToRoot(data.wet);
                ranks::sendToRoot(data.values[0]);
                ranks::sendToRoot(std::vector<double>{maxDev});
                continue;
            }
            st.maxDev = std::max(st.maxDev, maxDev);
            std::string bad;  // said once every rank's pieces are in: a sender is never left blocked
            for (int r = 1; r < ranks::count(); ++r) {
                const std::vector<uint32_t> wet = ranks::receiveVectorFrom<uint32_t>(r);
                const std::vector<float> depth = ranks::receiveVectorFrom<float>(r);
                const std::vector<double> dev = ranks::receiveVectorFrom<double>(r);
                if (depth.size() != wet.size() || dev.size() != 1) {
                    if (bad.empty()) bad = fmt::format("rank {} sent {} depths for {} wet cells of water step {}", r + 1, depth.size(), wet.size(), k);
                    continue;
                }
                data.wet.insert(data.wet.end(), wet.begin(), wet.end());
                data.values[0].insert(data.values[0].end(), depth.begin(), depth.end());
                st.maxDev = std::max(st.maxDev, dev[0]);
            }
            if (!bad.empty()) throw Error(bad);
            StepInfo info;
            info.timeS = data.timeS;
            info.wetCells = data.wet.size();
            out.steps.push_back(info);
            out.stepBytes += 8 * data.wet.size();
            sink.writer().appendStep(data);
            progress.advance(1);
        }
        progress.finish();
        if (ranks::distributed())
            ranks::log("hc-ingest", fmt::format("water steps: the depths of its {} cells in {} step{}, {:.3f} s", own.size(), stepCount,
                                                stepCount == 1 ? "" : "s", stepClock.seconds()));
    }
    if (!root) return out;
    IngestStats stats = extraStats;
    stats.sourceWidth = out.shape.stats.sourceWidth;
    stats.sourceHeight = out.shape.stats.sourceHeight;
    stats.toleranceM = options.toleranceM;
    fillStats(st, stats);
    stats.seconds = extraStats.seconds + clock.seconds();
    sink.writer().commit(stats);
    out.shape.stats = stats;
    out.shape.steps = out.steps;
    out.cellsPerLevel = st.perLevel;
    out.wetCells = out.steps.empty() ? 0 : out.steps.back().wetCells;
    return out;
}

}  // namespace

BuildSummary buildGridFile(const Raster& terrain, const WaterSteps* steps, const BuildOptions& options, const std::string& path,
                           const IngestStats& extraStats) {
    return buildFile(terrain, nullptr, steps, options, path, extraStats);
}

BuildSummary buildGridFile(const RasterWindows& terrain, const BuildOptions& options, const std::string& path, const IngestStats& extraStats) {
    if (!terrain.read) throw Error("internal: raster windows without a reader");
    WaterSteps steps;  // read by the builder through terrain.readStep
    steps.count = terrain.stepTimesS.size();
    steps.timesS = terrain.stepTimesS;
    return buildFile(terrain.shape, &terrain, steps.count ? &steps : nullptr, options, path, extraStats);
}

}  // namespace hc::ingest
