// The bottom-up quadtree build. See build.h for the merge rule and the guarantee.
//
// The domain is cut into tiles of 2^tileLevel pixels. Pass A builds each tile's pyramid (in parallel)
// and keeps only its root summary and leaf count. Pass B merges tile roots up the coarse levels.
// Pass C walks the coarse tree in Morton order to give every tile its output offset, then rebuilds
// each tile's pyramid (cheap, cache-resident) and writes its cells straight into the final arrays:
// no sort, no reallocation, and memory beyond the raster and the grid stays at a few hundred kB.
//
// Shares (core/ranks/ranks.h; docs/design.md section 7): the raster is cut into share nodes (quadtree nodes no finer
// than a tile or the coarsest cell), and under mpirun each rank takes a run of them in Morton order, about equal in
// area: the tiles of pass A and the units of pass C inside its nodes. The roots are exchanged between the two passes.
// Rank 0 opens the file; the other ranks write their cells into it at their place (GridFilePart), check and hash them
// in turn, and send rank 0 their block checksums and statistics; with a trace to paint they send rank 0 their cells
// instead, which it writes. A raster read window by window (RasterWindows) is read by each rank only over its own
// nodes, in maximal aligned squares: no rank holds it whole. The file is the same bytes for any number of ranks and
// threads: the squared deviations are summed per unit, then over the units in Morton order.
//
// Water (docs/design.md section 6): every step's depth raster is read once before the build, one at a time, into a
// merge mask (a byte per quadtree node: may these four cells merge, for every step?), so the terrain build keeps every
// step's wet/dry edges and depth tolerance. After the cells are written, each step is read again and its depth per
// cell computed exactly as a merge would (the float mean of the four children's means, bottom up): with one step the
// cells and depths are those of a build over both layers at once. Under mpirun every rank computes the depths of its
// own cells (their codes kept as it writes them) and sends rank 0 the wet ones, in rank order, which is the cells'
// order: no rank holds every cell's code. With a raster read window by window, each rank reads only its windows of each
// step (RasterWindows::readStep, or a level's bathtub flooded over its windows and joined across the ranks:
// bathtubBlocks) and keeps the merge masks of its own windows; the levels above the tiles, where every rank merges
// every node, are combined over the ranks.
//
// The files: the algorithm here (the merge rule, the tiles' pyramids, the passes of Builder::run); its distribution
// over the ranks in build_on_ranks.cpp; the entry points and the water steps' masks and depths in build_grid.cpp; what
// they share in build_internal.h.
#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <functional>
#include <future>
#include <memory>
#include <span>

#include "build_internal.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/ranks.h"
#include "heightcast/core/timer.h"

namespace hc::ingest::detail {

bool Builder::pixel(const Block& b, size_t ix, size_t iy, Node& n) const {
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

Node Builder::merge(const Node& a, const Node& b, const Node& c, const Node& d, int level, size_t x, size_t y) const {
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

const Node& Builder::buildTile(size_t tx, size_t ty, std::vector<std::vector<Node>>& scratch) const {
    scratch.resize(static_cast<size_t>(tileLevel_) + 1);
    size_t side = tile_;
    scratch[0].resize(side * side);  // every node written below: no fill first (it cost as much as the rest)
    const Block& b = blockAt(tx * tile_, ty * tile_);  // a tile lies in one share node, so in one block
    const size_t x0 = tx * tile_, y0 = ty * tile_;
    const size_t nx = std::min(side, t_.width - x0), ny = std::min(side, t_.height - y0);  // inside the raster
    for (size_t y = 0; y < side; ++y) {
        Node* row = &scratch[0][y * side];
        const size_t inside = y < ny ? nx : 0;
        if (b.rounding) {  // the rare case (a Float64 source): pixel() widens lo and hi
            for (size_t x = 0; x < inside; ++x) row[x] = Node{}, pixel(b, x0 + x, y0 + y, row[x]);
        } else if (inside) {
            const float* z = &b.values[b.index(x0, y0 + y)];
            for (size_t x = 0; x < inside; ++x) {
                const float v = z[x];
                row[x] = std::isnan(v) ? Node{} : Node{{v}, {v}, {v}, true};
            }
        }
        std::fill(row + inside, row + side, Node{});
    }
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
                cur[y * side + x] = merge(ch[c], ch[c + 1], ch[c + childSide], ch[c + childSide + 1], l,
                                          ((tx * tile_) >> l) + x, ((ty * tile_) >> l) + y);
            }
    }
    return scratch[static_cast<size_t>(tileLevel_)][0];
}

size_t Builder::countLeaves(const std::vector<std::vector<Node>>& scratch) const {
    // A leaf is a cell unless its parent is one too: a scan of the levels, no walk.
    size_t count = scratch[static_cast<size_t>(tileLevel_)][0].leaf ? 1 : 0;
    for (int l = tileLevel_ - 1; l >= 0; --l) {
        const size_t side = tile_ >> l;
        const std::vector<Node>& cur = scratch[static_cast<size_t>(l)];
        const std::vector<Node>& up = scratch[static_cast<size_t>(l) + 1];
        for (size_t y = 0; y < side; ++y)
            for (size_t x = 0; x < side; ++x) count += cur[y * side + x].leaf && !up[(y / 2) * (side / 2) + x / 2].leaf;
    }
    return count;
}

bool Builder::anyMerged(const std::vector<std::vector<Node>>& scratch) const {
    if (tileLevel_ == 0) return false;
    const std::vector<Node>& up = scratch[1];
    return std::any_of(up.begin(), up.end(), [](const Node& n) { return n.leaf; });
}

namespace {

// A tile's local Morton index -> its pixel (x in the low byte, y in the high one), for tiles up to 64 x 64 pixels.
static_assert(kTileLevelMax <= 6);
const std::array<uint16_t, 4096> kTileXY = [] {
    std::array<uint16_t, 4096> t{};
    for (uint32_t m = 0; m < t.size(); ++m) t[m] = static_cast<uint16_t>(mortonX(m) | (mortonY(m) << 8));
    return t;
}();

}  // namespace

size_t Builder::emitTile(size_t tx, size_t ty, const std::vector<std::vector<Node>>* scratch, Emit& out) const {
    // The tile's pixels in Morton order: at each, the cell that starts there is its highest leaf (a leaf's pixels are
    // all leaves), and the walk skips that cell's pixels. A cell's key is the tile's key with the local index set.
    const Block& px = blockAt(tx * tile_, ty * tile_);
    const size_t x0 = tx * tile_, y0 = ty * tile_;
    const uint64_t base = mortonEncode(static_cast<uint32_t>(x0), static_cast<uint32_t>(y0));
    uint64_t* codes = out.batch.codes.data() + out.at;
    float* values = out.batch.values[0].data() + out.at;
    const bool plain = !px.rounding && !(out.paint && opt_.cellElevations);  // a pixel's own cell: nothing to measure
    auto leaf = [&](int l, size_t x, size_t y) -> const Node* {
        const Node& n = (*scratch)[static_cast<size_t>(l)][(y >> l) * (tile_ >> l) + (x >> l)];
        return n.leaf ? &n : nullptr;
    };
    size_t count = 0;
    for (uint64_t m = 0, end = mortonSpan(tileLevel_); m < end;) {
        const size_t x = kTileXY[m] & 0xFFu, y = kTileXY[m] >> 8;
        int level = 0;
        float z = 0;
        if (!scratch) {  // nothing merged: each valid pixel is a cell
            if (x0 + x >= t_.width || y0 + y >= t_.height || std::isnan(z = px.values[px.index(x0 + x, y0 + y)])) {
                ++m;
                continue;
            }
        } else {
            const Node* n = leaf(0, x, y);
            if (!n) {  // a hole
                ++m;
                continue;
            }
            for (const Node* up; level < tileLevel_ && (up = leaf(level + 1, x, y)); ++level) n = up;
            z = n->mean[0];
        }
        codes[count] = makeCellCode(base | m, level);
        values[count] = z;
        if (level == 0 && plain) {
            ++out.tally.perLevel[0];
            ++out.tally.pixels;
        } else {
            measureCell(px, x0 + x, y0 + y, level, z, out.tally, out.paint);
        }
        ++count;
        m += mortonSpan(level);
    }
    return count;
}

void Builder::writeCell(Batch& b, size_t at, size_t ix, size_t iy, int level, const Node& n) const {
    b.codes[at] = makeCellCode(mortonEncode(static_cast<uint32_t>(ix), static_cast<uint32_t>(iy)), level);
    for (int l = 0; l < layers_; ++l) b.values[static_cast<size_t>(l)][at] = n.mean[static_cast<size_t>(l)];
}

Stats Builder::run(CellSink& sink) {
    RunState rs;
    rs.threads = resolveThreads(opt_.threads);
    const size_t tiles = ntx_ * nty_;
    // Under mpirun (ranks.h) each rank builds a contiguous share of the tiles, then of the cells, and writes those into
    // rank 0's file at their place. One process is rank 0 of 1: all of it.
    rs.rank = ranks::rank(), rs.rankCount = ranks::count();
    rs.root = rs.rank == 0;
    // Ranks write into a file, never into a grid in memory, and paint no trace (the tools read rasters by windows under
    // mpirun, and a trace is painted without windows only): the same answer on every rank, so all of them throw.
    if (rs.rankCount > 1 && (!sink.fileShape() || opt_.cellElevations))
        throw Error(
            "internal: under mpirun the grid is built into a file (each rank writes its own cells there) and without a "
            "trace of "
            "the source; an in-memory grid or a trace is built by one process");
    const auto rankStart = Stopwatch();
    takeShare(rs);
    if (windows_ && !windows_->stepTimesS.empty()) maskOwnNodes(rs.root);

    Progress progress("building quadtree", 2 * tiles, opt_.progress && rs.root);
    buildTileRoots(rs, progress);
    if (rs.rankCount > 1) gatherTileRoots(rs);  // every rank needs every root for the coarse levels and the walk
    buildCoarseLevels(rs);
    walkUnits(rs);
    findOwnUnits(rs);
    ranks::together([&] {
        if (rs.total == 0)
            throw Error((windows_ && !windows_->source.empty() ? windows_->source + ": " : std::string()) +
                        "the raster holds no valid pixel (all nodata): nothing to build");
        if (rs.root) sink.begin(rs.total);
    });
    const std::unique_ptr<GridFilePart> part = openPart(rs, sink);
    std::vector<double> unitSumSq(rs.myU1 - rs.myU0, 0.0);
    Stats sum = writeUnits(rs, sink, part.get(), unitSumSq, progress);
    logShare(rs, rankStart);
    const std::vector<std::byte> partResult = hashInTurn(rs, sink, part.get());
    if (!rs.root) {
        sendShare(sum, unitSumSq, partResult);
        return sum;
    }
    receiveShares(sink, sum, unitSumSq);
    if (unitSumSq.size() != rs.units.size())
        throw Error("ranks sent statistics of " + std::to_string(unitSumSq.size()) + " units, not " +
                    std::to_string(rs.units.size()));
    for (double u : unitSumSq) sum.sumSq += u;
    progress.advance(2 * tiles);  // units cover fewer than all tiles; fill the bar
    progress.finish();
    return sum;
}

// Pass A: tile roots and leaf counts, of this rank's tiles (gatherTileRoots brings the others'). A build in pieces
// reads each piece's pixels before its tiles, and checks the pixels read once all are (takeShare).
void Builder::buildTileRoots(RunState& rs, Progress& progress) {
    const size_t tiles = ntx_ * nty_;
    rs.roots = std::vector<Node>(tiles);
    rs.leafCount = std::vector<uint32_t>(tiles);
    rs.merged = std::vector<uint8_t>(tiles);
    rs.scratch = std::vector<std::vector<std::vector<Node>>>(rs.threads);
    std::vector<Node>& roots = rs.roots;
    std::vector<uint32_t>& leafCount = rs.leafCount;
    std::vector<uint8_t>& merged = rs.merged;
    std::vector<std::vector<std::vector<Node>>>& scratch = rs.scratch;
    const int rankCount = rs.rankCount;
    auto build = [&](const std::vector<size_t>& myTiles) {
        ranks::together([&] {
            parallelFor(myTiles.size(), 16, rs.threads, [&](size_t b, size_t e, unsigned worker) {
                for (size_t k = b; k < e; ++k) {
                    const size_t i = myTiles[k], tx = i % ntx_, ty = i / ntx_;
                    roots[i] = buildTile(tx, ty, scratch[worker]);
                    leafCount[i] = static_cast<uint32_t>(countLeaves(scratch[worker]));
                    merged[i] = anyMerged(scratch[worker]);
                }
                progress.advance((e - b) * size_t(rankCount));
            });
        });
    };
    if (rs.pieces.empty()) return build(rs.myTiles);
    uint64_t valid = 0;
    for (size_t p = 0; p + 1 < rs.pieces.size(); ++p) {
        rs.pixelsRead += holdPixels(rs.pieces[p], rs.pieces[p + 1], true, false);
        rs.windowsRead += blocks_.size();
        valid += validHeld();
        build(tilesOf(rs.pieces[p], rs.pieces[p + 1]));
    }
    holdPixels(0, 0, false, false);  // none held
    if (windows_->checkHeld) windows_->checkHeld(valid);
}

// Pass B: coarse levels over tile roots, level tileLevel+1 .. rootLevel.
void Builder::buildCoarseLevels(RunState& rs) const {
    std::vector<std::vector<Node>> coarse{rs.roots};
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
    rs.coarse = std::move(coarse);
    rs.dims = std::move(dims);
}

// Pass C, walk: units in Morton order. A unit is a merged coarse cell or one tile.
void Builder::walkUnits(RunState& rs) const {
    const std::vector<std::vector<Node>>& coarse = rs.coarse;
    const std::vector<std::pair<size_t, size_t>>& dims = rs.dims;
    const std::vector<uint32_t>& leafCount = rs.leafCount;
    std::vector<Unit>& units = rs.units;
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
    rs.total = total;
}

// Pass C, write: batches of consecutive units (about 64 k cells, a few MB), filled in parallel, measured, and
// handed to the sink in order (another rank writes them into the file at their place, to read them back in its
// turn of the hashes). The squared
// deviations are summed per unit, then over the units in order: the same figure (bits) on any number of
// threads and ranks. Returns this rank's statistics; its units' sums of squares go to unitSumSq.
Stats Builder::writeUnits(RunState& rs, CellSink& sink, GridFilePart* part, std::vector<double>& unitSumSq,
                          Progress& progress) {
    std::vector<Stats> acc(rs.threads);
    for (auto& a : acc) a.perLevel.assign(static_cast<size_t>(maxLevel_) + 1, 0);
    // Two batches: the workers fill one while a thread of its own hands the other to the sink (checks, hashes,
    // checksums, writes: one thread's work), so that work no longer leaves the other cores idle.
    std::array<Batch, 2> batches;
    for (Batch& b : batches) b.values.resize(static_cast<size_t>(layers_));
    auto hand = [&](const Batch& batch) {
        const std::vector<std::span<const float>> values(batch.values.begin(), batch.values.end());
        if (rs.root) {
            sink.append(batch.codes, values);
        } else {  // into the file at its place; read back for the hashes (nothing held)
            part->append(batch.codes, values);
            sink.keepOwn(batch.codes);
        }
    };
    ranks::together([&] {
        std::future<void> handing;  // declared after the batches: waited for before they go
        // A build in pieces reads a piece's pixels again before its first unit (no batch spans two pieces; the batch
        // being handed holds no pixel).
        size_t u0 = rs.myU0, next = 0, piece = 0, end = rs.pieces.empty() ? rs.myU1 : rs.myU0;
        while (u0 < rs.myU1) {
            while (u0 == end) {
                end = firstUnitAt(rs, rs.pieces[piece + 1]);
                holdPixels(rs.pieces[piece], rs.pieces[piece + 1], false, false);
                ++piece;
            }
            size_t u1 = u0;
            const size_t first = rs.units[u0].offset;
            while (u1 < end && (u1 == u0 || rs.units[u1].offset - first < (size_t{1} << 16))) ++u1;
            const size_t last = rs.offsetOf(u1);
            Batch& batch = batches[next];
            batch.codes.resize(last - first);
            for (auto& v : batch.values) v.resize(last - first);
            fillBatch(rs, u0, u1, batch, acc, unitSumSq, progress);
            if (handing.valid()) handing.get();  // the batch before, handed in order
            handing = std::async(std::launch::async, hand, std::cref(batch));
            next ^= 1;
            u0 = u1;
        }
        if (handing.valid()) handing.get();
    });
    if (!rs.pieces.empty()) holdPixels(0, 0, false, false);  // none held
    Stats sum;
    sum.perLevel.assign(static_cast<size_t>(maxLevel_) + 1, 0);
    sum.firstCell = rs.offsetOf(rs.myU0), sum.ownCells = rs.myCells();
    for (const Stats& a : acc) {
        sum.maxDev = std::max(sum.maxDev, a.maxDev);
        sum.pixels += a.pixels;
        sum.wetCells += a.wetCells;
        for (size_t l = 0; l < a.perLevel.size(); ++l) sum.perLevel[l] += a.perLevel[l];
    }
    return sum;
}

// Units [u0, u1) into `batch` (from the first unit's offset on), on all workers, each unit measured: its sum of
// squares into unitSumSq, the rest into its worker's acc.
void Builder::fillBatch(RunState& rs, size_t u0, size_t u1, Batch& batch, std::vector<Stats>& acc,
                        std::vector<double>& unitSumSq, Progress& progress) const {
    const std::vector<Unit>& units = rs.units;
    const size_t first = units[u0].offset;
    parallelFor(u1 - u0, 1, rs.threads, [&](size_t b, size_t e, unsigned worker) {
        size_t tilesDone = 0;
        for (size_t k = u0 + b; k < u0 + e; ++k) {
            const Unit& unit = units[k];
            Emit out{batch, unit.offset - first, rs.root};
            if (unit.level > tileLevel_) {
                auto lk = static_cast<size_t>(unit.level - tileLevel_);
                const Node& n = rs.coarse[lk][unit.y * rs.dims[lk].first + unit.x];
                size_t span = size_t{1} << unit.level;
                writeCell(batch, out.at, unit.x * span, unit.y * span, unit.level, n);
                measureCell(blockAt(unit.x * span, unit.y * span), unit.x * span, unit.y * span, unit.level, n.mean[0],
                            out.tally, out.paint);
            } else {
                const size_t tile = unit.y * ntx_ + unit.x;
                if (rs.merged[tile]) buildTile(unit.x, unit.y, rs.scratch[worker]);  // else its pixels are its cells
                [[maybe_unused]] const size_t written =
                    emitTile(unit.x, unit.y, rs.merged[tile] ? &rs.scratch[worker] : nullptr, out);
                assert(written == rs.leafCount[tile]);
                ++tilesDone;
            }
            unitSumSq[k - rs.myU0] = out.tally.sumSq;
            Stats& a = acc[worker];
            a.maxDev = std::max(a.maxDev, out.tally.maxDev);
            a.pixels += out.tally.pixels;
            for (size_t l = 0; l < a.perLevel.size(); ++l) a.perLevel[l] += out.tally.perLevel[l];
        }
        progress.advance(tilesDone * size_t(rs.rankCount));
    });
}

void Builder::measureCell(const Block& px, size_t ix0, size_t iy0, int level, float stored, Tally& a,
                          bool paintElevations) const {
    ++a.perLevel[static_cast<size_t>(level)];
    double& sumSq = a.sumSq;
    const size_t span = size_t{1} << level;
    const double z = stored;
    for (size_t iy = iy0; iy < iy0 + span; ++iy) {
        for (size_t ix = ix0; ix < ix0 + span; ++ix) {
            const size_t idx = px.index(ix, iy);
            const double exact = static_cast<double>(px.values[idx]) + (px.rounding ? px.rounding[idx] : 0.0);
            const double dz = exact - z;
            if (paintElevations && opt_.cellElevations)
                (*opt_.cellElevations)[(t_.height - 1 - iy) * t_.width + ix] = stored;
            sumSq += dz * dz;
            a.maxDev = std::max(a.maxDev, std::abs(dz));
            ++a.pixels;
        }
    }
}

}  // namespace hc::ingest::detail
