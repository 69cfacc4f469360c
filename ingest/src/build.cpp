// The bottom-up quadtree build. See build.h for the merge rule and the guarantee.
//
// The domain is cut into tiles of 2^tileLevel pixels. Pass A builds each tile's pyramid (in parallel)
// and keeps only its root summary and leaf count. Pass B merges tile roots up the coarse levels.
// Pass C walks the coarse tree in Morton order to give every tile its output offset, then rebuilds
// each tile's pyramid (cheap, cache-resident) and writes its cells straight into the final arrays:
// no sort, no reallocation, and memory beyond the raster and the grid stays at a few hundred kB.
//
// Under mpirun (core/ranks/ranks.h; DESIGN.md section 13) every rank holds the raster and takes an equal run of pass
// A's tiles and of pass C's cells; the roots are exchanged between the two, and the ranks other than 0 send their
// cells and statistics to rank 0, which alone writes. The file is the same bytes for any number of ranks and threads:
// the squared deviations are summed per unit, then over the units in Morton order.
//
// Water (DESIGN.md section 11): every step's depth raster is read once before the build, one at a time, into a merge
// mask (a byte per quadtree node: may these four cells merge, for every step?), so the terrain build keeps every
// step's wet/dry edges and depth tolerance. After the cells are written, each step is read again and its depth per
// cell computed exactly as a merge would (the float mean of the four children's means, bottom up): with one step the
// cells and depths are those of a build over both layers at once.
#include "heightcast/ingest/build.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>

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
class MergeMask {
public:
    MergeMask(size_t width, size_t height, int maxLevel) : levels_(size_t(maxLevel) + 1) {
        for (int l = 1; l <= maxLevel; ++l) {
            const size_t nx = (width + (size_t{1} << l) - 1) >> l, ny = (height + (size_t{1} << l) - 1) >> l;
            levels_[size_t(l)] = {nx, ny, std::vector<uint8_t>(nx * ny, 1)};
        }
    }
    bool allowed(int level, size_t x, size_t y) const {
        const Level& L = levels_[size_t(level)];
        return x < L.nx && y < L.ny && L.ok[y * L.nx + x];
    }
    void forbid(int level, size_t x, size_t y) {
        Level& L = levels_[size_t(level)];
        if (x < L.nx && y < L.ny) L.ok[y * L.nx + x] = 0;
    }

private:
    struct Level {
        size_t nx = 0, ny = 0;
        std::vector<uint8_t> ok;
    };
    std::vector<Level> levels_;
};

// A depth pixel at finest coordinates (ix east, iy north of the south-west corner): NaN outside or on a hole.
float depthAt(const Raster& d, size_t ix, size_t iy) {
    if (ix >= d.width || iy >= d.height) return std::numeric_limits<float>::quiet_NaN();
    return d.values[(d.height - 1 - iy) * d.width + ix];
}

// The depth a merged cell of `level` at (ix, iy) holds: the float mean of its four children's, bottom up, in the order
// the build merges them (Builder::merge).
float cellMean(const Raster& d, size_t ix, size_t iy, int level) {
    if (level == 0) return depthAt(d, ix, iy);
    const size_t h = size_t{1} << (level - 1);
    const double sum = static_cast<double>(cellMean(d, ix, iy, level - 1)) + cellMean(d, ix + h, iy, level - 1) +
                       cellMean(d, ix, iy + h, level - 1) + cellMean(d, ix + h, iy + h, level - 1);
    return static_cast<float>(sum * 0.25);
}

// Forbids in `mask` every merge step `d` does not allow: four children that are not all wet or all dry, or whose
// depths the parent's mean does not hold within the tolerance (build.h's rule for water).
void restrictByStep(const Raster& d, double tolerance, int maxLevel, unsigned threads, MergeMask& mask) {
    if (maxLevel < 1) return;
    struct Depth {
        float mean = 0, lo = 0, hi = 0;
        uint8_t state = 0;  // 0: no merge possible (hole, outside, or a forbidden merge below), 1 dry, 2 wet
    };
    const int top = maxLevel;  // nodes of the top level are independent: one task each
    const size_t side = size_t{1} << top;
    const size_t nx = (d.width + side - 1) / side, ny = (d.height + side - 1) / side;
    std::vector<std::vector<std::vector<Depth>>> scratch(resolveThreads(threads));
    std::vector<std::vector<std::pair<int, std::pair<size_t, size_t>>>> forbidden(scratch.size());
    parallelFor(nx * ny, 4, threads, [&](size_t b, size_t e, unsigned worker) {
        auto& lv = scratch[worker];
        lv.resize(size_t(top) + 1);
        for (size_t t = b; t < e; ++t) {
            const size_t tx = t % nx, ty = t / nx;
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
};

class Builder {
public:
    Builder(const Raster& terrain, const MergeMask* mask, const BuildOptions& opt, int rootLevel, int maxLevel)
        : t_(terrain), mask_(mask), opt_(opt), layers_(1), rootLevel_(rootLevel), maxLevel_(maxLevel),
          tileLevel_(std::min(rootLevel, kTileLevelMax)), tile_(size_t{1} << tileLevel_),
          ntx_((terrain.width + tile_ - 1) / tile_), nty_((terrain.height + tile_ - 1) / tile_) {}

    // Builds the tree and hands its cells, in Morton order, to the sink. Returns the measurements.
    Stats run(CellSink& sink);

private:
    // Pixel at finest coordinates (ix east, iy north) from the SW corner; false if none.
    bool pixel(size_t ix, size_t iy, Node& n) const {
        if (ix >= t_.width || iy >= t_.height) return false;
        size_t idx = (t_.height - 1 - iy) * t_.width + ix;
        float z = t_.values[idx];
        if (std::isnan(z)) return false;
        n.mean[0] = n.lo[0] = n.hi[0] = z;
        if (!t_.roundingM.empty() && t_.roundingM[idx] != 0) {
            // The source's own value lies between lo and hi (float32 neighbours of it), so merges
            // checked against lo and hi keep the tolerance against the source, not only its rounding.
            const double exact = static_cast<double>(z) + t_.roundingM[idx];
            (exact > z ? n.hi[0] : n.lo[0]) = std::nextafter(z, exact > z ? HUGE_VALF : -HUGE_VALF);
        }
        n.leaf = true;
        return true;
    }

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
        for (size_t y = 0; y < side; ++y)
            for (size_t x = 0; x < side; ++x) pixel(tx * tile_ + x, ty * tile_ + y, scratch[0][y * side + x]);
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
    // Under mpirun: a rank other than 0 sends its share (cells, statistics, per-unit sums of squares) to rank 0; rank 0
    // receives every other rank's in order, feeds their cells to the sink and adds their statistics into `sum`.
    void sendShare(const Batch& share, const Stats& sum, const std::vector<double>& unitSumSq) const;
    void receiveShares(CellSink& sink, Stats& sum, std::vector<double>& unitSumSq) const;
    // Fills BuildOptions::cellElevations under cells [begin, end) of the batch (rank 0 does it for every rank's cells).
    void paint(const Batch& b, size_t begin, size_t end) const;

    const Raster& t_;
    const MergeMask* mask_;
    const BuildOptions& opt_;
    int layers_;
    int rootLevel_, maxLevel_, tileLevel_;
    size_t tile_, ntx_, nty_;
};

Stats Builder::run(CellSink& sink) {
    const unsigned threads = resolveThreads(opt_.threads);
    const size_t tiles = ntx_ * nty_;
    // Under mpirun (ranks.h) each rank builds a contiguous share of the tiles, then of the cells; rank 0 receives the
    // others' cells in order and alone feeds the sink. One process is rank 0 of 1: all of it.
    const int rank = ranks::rank(), rankCount = ranks::count();
    const bool root = rank == 0;
    const auto rankStart = Stopwatch();

    // Pass A: tile roots and leaf counts.
    std::vector<Node> roots(tiles);
    std::vector<uint32_t> leafCount(tiles);
    {
        Progress progress("building quadtree", 2 * tiles, opt_.progress && root);
        std::vector<std::vector<std::vector<Node>>> scratch(threads);
        const size_t a0 = ranks::shareBegin(tiles, rank, rankCount), a1 = ranks::shareBegin(tiles, rank + 1, rankCount);
        ranks::together([&] {
            parallelFor(a1 - a0, 16, threads, [&](size_t b, size_t e, unsigned worker) {
                for (size_t i = a0 + b; i < a0 + e; ++i) {
                    size_t tx = i % ntx_, ty = i / ntx_;
                    roots[i] = buildTile(tx, ty, scratch[worker]);
                    leafCount[i] = static_cast<uint32_t>(emitTile(tx, ty, scratch[worker], nullptr, 0));
                }
                progress.advance((e - b) * size_t(rankCount));
            });
        });
        if (rankCount > 1) {  // every rank needs every root for the coarse levels and the walk
            const auto allRoots = ranks::allGatherVectors(std::vector<Node>(roots.begin() + ptrdiff_t(a0), roots.begin() + ptrdiff_t(a1)));
            const auto allCounts = ranks::allGatherVectors(std::vector<uint32_t>(leafCount.begin() + ptrdiff_t(a0), leafCount.begin() + ptrdiff_t(a1)));
            for (int r = 0; r < rankCount; ++r) {
                const size_t at = ranks::shareBegin(tiles, r, rankCount);
                std::copy(allRoots[size_t(r)].begin(), allRoots[size_t(r)].end(), roots.begin() + ptrdiff_t(at));
                std::copy(allCounts[size_t(r)].begin(), allCounts[size_t(r)].end(), leafCount.begin() + ptrdiff_t(at));
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

        // This rank's units: those whose first cell lies in its share of the cells.
        auto firstUnit = [&](int r) {
            const uint64_t cell = ranks::shareBegin(total, r, rankCount);
            return size_t(std::lower_bound(units.begin(), units.end(), cell, [](const Unit& u, uint64_t c) { return u.offset < c; }) - units.begin());
        };
        const size_t myU0 = firstUnit(rank), myU1 = rank + 1 == rankCount ? units.size() : firstUnit(rank + 1);

        if (root) sink.begin(total);

        // Pass C, write: batches of consecutive units (about 64 k cells, a few MB), filled in parallel, measured, and
        // handed to the sink in order (another rank keeps its share's cells, then sends them to rank 0). The squared
        // deviations are summed per unit, then over the units in order: the same figure (bits) on any number of
        // threads and ranks.
        std::vector<Stats> acc(threads);
        for (auto& a : acc) a.perLevel.assign(static_cast<size_t>(maxLevel_) + 1, 0);
        std::vector<double> unitSumSq(myU1 - myU0, 0.0);
        Batch batch, share;
        batch.values.resize(static_cast<size_t>(layers_));
        share.values.resize(static_cast<size_t>(layers_));
        ranks::together([&] {
            size_t u0 = myU0;
            while (u0 < myU1) {
                size_t u1 = u0;
                const size_t first = units[u0].offset;
                while (u1 < myU1 && (u1 == u0 || units[u1].offset - first < (size_t{1} << 16))) ++u1;
                const size_t last = u1 < units.size() ? units[u1].offset : total;
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
                } else {
                    share.codes.insert(share.codes.end(), batch.codes.begin(), batch.codes.end());
                    for (size_t l = 0; l < batch.values.size(); ++l)
                        share.values[l].insert(share.values[l].end(), batch.values[l].begin(), batch.values[l].end());
                }
                u0 = u1;
            }
        });
        Stats sum;
        sum.perLevel.assign(static_cast<size_t>(maxLevel_) + 1, 0);
        for (const Stats& a : acc) {
            sum.maxDev = std::max(sum.maxDev, a.maxDev);
            sum.pixels += a.pixels;
            sum.wetCells += a.wetCells;
            for (size_t l = 0; l < a.perLevel.size(); ++l) sum.perLevel[l] += a.perLevel[l];
        }
        const uint64_t myTiles = a1 - a0, myCells = (myU1 < units.size() ? units[myU1].offset : total) - (myU0 < units.size() ? units[myU0].offset : total);
        ranks::log("hc-ingest", fmt::format("{} tiles of {}^2 px built, {} units, {} cells written, {:.3f} s, peak {:.1f} MB resident", myTiles,
                                            1u << tileLevel_, myU1 - myU0, myCells, rankStart.seconds(), double(peakRssBytes()) / 1e6));
        if (!root) {
            sendShare(share, sum, unitSumSq);
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

void Builder::sendShare(const Batch& share, const Stats& sum, const std::vector<double>& unitSumSq) const {
    ranks::sendToRoot(share.codes);
    for (const auto& v : share.values) ranks::sendToRoot(v);
    std::vector<double> table{sum.maxDev, double(sum.pixels), double(sum.wetCells)};  // then cells per level, then the unit sums
    for (uint64_t c : sum.perLevel) table.push_back(double(c));
    table.insert(table.end(), unitSumSq.begin(), unitSumSq.end());
    ranks::sendToRoot(table);
}

void Builder::receiveShares(CellSink& sink, Stats& sum, std::vector<double>& unitSumSq) const {
    for (int r = 1; r < ranks::count(); ++r) {
        Batch in;
        in.codes = ranks::receiveVectorFrom<uint64_t>(r);
        for (int l = 0; l < layers_; ++l) in.values.push_back(ranks::receiveVectorFrom<float>(r));
        const std::vector<double> table = ranks::receiveVectorFrom<double>(r);
        const size_t levels = sum.perLevel.size();
        if (table.size() < 3 + levels) throw Error("rank " + std::to_string(r + 1) + ": a short statistics table");
        sum.maxDev = std::max(sum.maxDev, table[0]);
        sum.pixels += uint64_t(table[1]);
        sum.wetCells += uint64_t(table[2]);
        for (size_t l = 0; l < levels; ++l) sum.perLevel[l] += uint64_t(table[3 + l]);
        unitSumSq.insert(unitSumSq.end(), table.begin() + ptrdiff_t(3 + levels), table.end());
        if (opt_.cellElevations) paint(in, 0, in.codes.size());
        for (size_t at = 0; at < in.codes.size(); at += size_t{1} << 16) {
            const size_t n = std::min(in.codes.size() - at, size_t{1} << 16);
            std::vector<std::span<const float>> values;
            for (const auto& v : in.values) values.emplace_back(v.data() + at, n);
            sink.append(std::span<const uint64_t>(in.codes.data() + at, n), values);
        }
    }
}

void Builder::paint(const Batch& b, size_t begin, size_t end) const {
    for (size_t i = begin; i < end; ++i) {
        const uint64_t key = codeKey(b.codes[i]);
        const size_t span = size_t{1} << codeLevel(b.codes[i]);
        const size_t ix0 = mortonX(key), iy0 = mortonY(key);
        for (size_t iy = iy0; iy < iy0 + span; ++iy)
            for (size_t ix = ix0; ix < ix0 + span; ++ix) (*opt_.cellElevations)[(t_.height - 1 - iy) * t_.width + ix] = b.values[0][i];
    }
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
        for (size_t iy = iy0; iy < iy0 + span; ++iy) {
            const size_t row = t_.height - 1 - iy;
            for (size_t ix = ix0; ix < ix0 + span; ++ix) {
                const size_t idx = row * t_.width + ix;
                const double exact = static_cast<double>(t_.values[idx]) + (t_.roundingM.empty() ? 0.0 : t_.roundingM[idx]);
                const double dz = exact - z;
                if (paintElevations && opt_.cellElevations) (*opt_.cellElevations)[idx] = b.values[0][i];
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
Grid shapeFor(const Raster& terrain, bool water, const BuildOptions& options, int& rootLevel, int& maxLevel) {
    if (terrain.width == 0 || terrain.height == 0 || terrain.values.size() != terrain.width * terrain.height)
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
        restrictByStep(d, opt.toleranceM, maxLevel, opt.threads, mask);
        progress.advance(1);
    }
    progress.finish();
    return mask;
}

// One step's depth per cell (cellMean) for the cells `codes`: the wet ones (> 0) in stored form, and the largest
// |pixel - cell depth| over the pixels the cells cover.
WaterStepData stepValues(const Raster& d, std::span<const uint64_t> codes, double timeS, unsigned threads, double& maxDev) {
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
        if (steps_ > 0) codes.reserve(cellCount);
    }
    void append(std::span<const uint64_t> c, const std::vector<std::span<const float>>& values) override {
        writer_->append(c, values);
        if (steps_ > 0) codes.insert(codes.end(), c.begin(), c.end());
    }
    GridFileWriter& writer() { return *writer_; }
    std::vector<uint64_t> codes;

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
    Stats st = Builder(terrain, mask ? &*mask : nullptr, options, rootLevel, maxLevel).run(sink);
    if (g.cellCount() == 0) throw Error("the raster holds no valid pixel (all nodata): nothing to build");
    if (waterDepth) {
        g.values[1].clear();
        const WaterStepData data = stepValues(*waterDepth, g.codes, 0.0, options.threads, st.maxDev);
        selectStep(g, data, 0);
    }
    fillStats(st, g.stats);
    assert(g.validate().empty());
    return g;
}

BuildSummary buildGridFile(const Raster& terrain, const WaterSteps* steps, const BuildOptions& options, const std::string& path,
                           const IngestStats& extraStats) {
    const Stopwatch clock;
    int rootLevel = 0, maxLevel = 0;
    const size_t stepCount = steps ? steps->count : 0;
    if (steps && steps->timesS.size() != stepCount) throw Error("water steps: " + std::to_string(steps->timesS.size()) + " times for " + std::to_string(stepCount) + " steps");
    for (size_t k = 1; k < stepCount; ++k)
        if (!(steps->timesS[k] > steps->timesS[k - 1]))
            throw Error("water step times must increase strictly: step " + std::to_string(k) + " at " + std::to_string(steps->timesS[k]) +
                        " s follows " + std::to_string(steps->timesS[k - 1]) + " s");
    BuildSummary out;
    out.shape = shapeFor(terrain, stepCount > 0, options, rootLevel, maxLevel);
    const std::optional<MergeMask> mask = maskOf(terrain, steps, options, maxLevel);
    FileSink sink(path, out.shape, stepCount);
    const bool root = ranks::rank() == 0;  // under mpirun, rank 0 alone writes (Builder::run)
    if (options.cellElevations && root) options.cellElevations->assign(terrain.values.size(), std::numeric_limits<float>::quiet_NaN());
    Stats st = Builder(terrain, mask ? &*mask : nullptr, options, rootLevel, maxLevel).run(sink);
    if (!root) {
        for (uint64_t c : st.perLevel) out.cellCount += c;  // this rank's share
        return out;
    }
    {
        Progress progress("water steps: depth per cell", stepCount, options.progress && stepCount > 0);
        for (size_t k = 0; k < stepCount; ++k) {
            const Raster d = steps->load(k);
            checkStepRaster(terrain, d, k);
            const WaterStepData data = stepValues(d, sink.codes, steps->timesS[k], options.threads, st.maxDev);
            StepInfo info;
            info.timeS = data.timeS;
            info.wetCells = data.wet.size();
            out.steps.push_back(info);
            out.stepBytes += 8 * data.wet.size();
            sink.writer().appendStep(data);
            progress.advance(1);
        }
        progress.finish();
    }
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
    for (uint64_t c : st.perLevel) out.cellCount += c;
    return out;
}

}  // namespace hc::ingest
