// ingest/src/build_on_ranks.cpp: the quadtree build (build.cpp) distributed over the ranks of mpirun (build.cpp's first
// comment: Shares): the share nodes and the pixels a rank holds, the water steps' masks and bathtubs over a rank's
// windows, the tile roots exchanged, the file's parts opened and hashed in turn, and every rank's part and statistics
// sent to rank 0. One process is rank 0 of 1.
#include <algorithm>
#include <array>
#include <cmath>
#include <exception>
#include <limits>
#include <memory>
#include <unordered_map>

#include <fmt/format.h>

#include "build_internal.h"
#include "heightcast/core/error.h"
#include "heightcast/core/heap.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/ranks.h"
#include "heightcast/core/timer.h"

namespace hc::ingest::detail {

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
        if (x < nbx_ && y < nby_)
            before += uint64_t(std::min(side, t_.width - x * side)) * std::min(side, t_.height - y * side);
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

std::vector<uint64_t> Builder::piecesOf(uint64_t c0, uint64_t c1, int rankCount) const {
    const uint64_t total = uint64_t(t_.width) * t_.height;
    if (!windows_ || rankCount > 1 || windows_->heldPixelsMax == 0 || total <= windows_->heldPixelsMax ||
        !windows_->stepTimesS.empty())
        return {};
    // Runs of about equal area, each within heldPixelsMax but for one share node (shareCuts' rounding).
    const uint64_t nodes = uint64_t(nbx_) * nby_;  // no piece smaller than a share node
    const int count = int(std::min(nodes, (total + windows_->heldPixelsMax - 1) / windows_->heldPixelsMax));
    std::vector<uint64_t> cuts = shareCuts(count);
    cuts.front() = c0, cuts.back() = c1;  // one process: [c0, c1) is every node
    return cuts;
}

uint64_t Builder::validHeld() const {
    uint64_t valid = 0;
    for (const Block& b : blocks_)
        valid += uint64_t(std::count_if(b.values, b.values + b.w * b.h, [](float v) { return !std::isnan(v); }));
    return valid;
}

uint64_t Builder::holdPixels(uint64_t c0, uint64_t c1, bool first, bool showProgress) {
    // blockOf_ over the share nodes of a block (whose corners lie on their lattice, or on the raster's edge).
    auto mark = [&](const Block& b, int32_t value) {
        const size_t side = size_t{1} << shareLevel_;
        for (size_t y = b.y0 / side; y < (b.y0 + b.h + side - 1) / side; ++y)
            for (size_t x = b.x0 / side; x < (b.x0 + b.w + side - 1) / side; ++x) blockOf_[y * nbx_ + x] = value;
    };
    if (blockOf_.size() != nbx_ * nby_) blockOf_.assign(nbx_ * nby_, -1);
    for (const Block& b : blocks_) mark(b, -1);  // those held before (not all nodes: a build in pieces holds many)
    blocks_.clear();
    windowValues_.clear(), windowRounding_.clear();  // those held before, freed
    if (!windows_) {
        blocks_.push_back(
            {0, 0, t_.width, t_.height, t_.values.data(), t_.roundingM.empty() ? nullptr : t_.roundingM.data()});
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
        while (shareLevel_ + k < rootLevel_ && m % (uint64_t{4} << (2 * k)) == 0 && m + (uint64_t{4} << (2 * k)) <= c1)
            ++k;
        squares.push_back({m, k});
        m += uint64_t{1} << (2 * k);
    }
    uint64_t read = 0;
    Progress progress("reading the raster's windows", squares.size(),
                      showProgress && opt_.progress && ranks::rank() == 0);
    for (const Square& q : squares) {
        const size_t x0 = size_t(mortonX(q.m)) << shareLevel_, y0 = size_t(mortonY(q.m)) << shareLevel_;
        const size_t side = size_t{1} << (shareLevel_ + q.k);
        progress.advance(1);
        if (x0 >= t_.width || y0 >= t_.height) continue;
        Block b{x0, y0, std::min(side, t_.width - x0), std::min(side, t_.height - y0), nullptr, nullptr};
        windowValues_.emplace_back();
        windowRounding_.emplace_back();
        windowValues_.back().reserve(b.w * b.h);  // huge pages before the read touches it (heap.h): fewer faults
        adviseHugePages(windowValues_.back().data(), b.w * b.h * sizeof(float));
        windows_->read(b.x0, t_.height - (b.y0 + b.h), b.w, b.h, windowValues_.back(), windowRounding_.back(), first);
        if (windowValues_.back().size() != b.w * b.h) throw Error("internal: a window read the wrong number of pixels");
        b.values = windowValues_.back().data();
        b.rounding = windowRounding_.back().empty() ? nullptr : windowRounding_.back().data();
        read += uint64_t(b.w) * b.h;
        mark(b, int32_t(blocks_.size()));
        blocks_.push_back(b);
    }
    progress.finish();
    return read;
}

// The shares: runs of share nodes in Morton order, about equal in area. A rank builds the tiles (pass A) and writes
// the cells (pass C) inside its own nodes, so it reads (windows_) or touches only their pixels. A build in pieces
// (piecesOf) reads them piece by piece in passes A and C, and checks them after pass A.
void Builder::takeShare(RunState& rs) {
    const int rank = rs.rank;
    rs.cuts = shareCuts(rs.rankCount);
    const std::vector<uint64_t>& cuts = rs.cuts;
    rs.myTiles = tilesOf(cuts[size_t(rank)], cuts[size_t(rank) + 1]);
    rs.pieces = piecesOf(cuts[size_t(rank)], cuts[size_t(rank) + 1], rs.rankCount);
    if (!rs.pieces.empty()) return;
    ranks::together([&] {
        rs.pixelsRead = holdPixels(cuts[size_t(rank)], cuts[size_t(rank) + 1], true, true);
        rs.windowsRead = blocks_.size();
    });
    if (windows_ && windows_->checkHeld) {
        const uint64_t valid = validHeld();
        uint64_t all = 0;
        for (const auto& v : ranks::allGatherVectors(std::vector<uint64_t>{valid})) all += v.empty() ? 0 : v[0];
        ranks::together([&] { windows_->checkHeld(all); });
    }
}

// Water steps read by windows: each step's merge mask over this rank's own nodes (every merge lies inside a share
// node, so in one of its blocks), from the same windows of each step raster.
void Builder::maskOwnNodes(bool root) {
    const size_t steps = windows_->stepTimesS.size();
    Progress progress("water steps: wet/dry edges", steps, opt_.progress && root && steps > 1);
    ranks::together([&] {
        std::vector<std::array<size_t, 4>> windows;  // the mask over this rank's windows only, up to the tiles
        for (const Block& b : blocks_) windows.push_back({b.x0, b.y0, b.w, b.h});
        ownMask_.emplace(t_.width, t_.height, maxLevel_, tileLevel_, windows, shareLevel_, blockOf_, nbx_);
        for (size_t k = 0; k < steps; ++k) {
            std::vector<std::vector<float>> storage;
            for (const Block& b : stepBlocks(k, storage, true))
                restrictByStep(b, opt_.toleranceM, maxLevel_, opt_.threads, *ownMask_);
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

// Every rank's tile roots and leaf counts (pass A built this rank's), for the coarse levels and the walk.
void Builder::gatherTileRoots(RunState& rs) const {
    const int rank = rs.rank, rankCount = rs.rankCount;
    const std::vector<uint64_t>& cuts = rs.cuts;
    std::vector<Node>& roots = rs.roots;
    std::vector<uint32_t>& leafCount = rs.leafCount;
    std::vector<Node> myRoots;
    std::vector<uint32_t> myCounts;
    for (size_t i : rs.myTiles) myRoots.push_back(roots[i]), myCounts.push_back(leafCount[i]);
    const auto allRoots = ranks::allGatherVectors(myRoots);
    const auto allCounts = ranks::allGatherVectors(myCounts);
    for (int r = 0; r < rankCount; ++r) {
        if (r == rank) continue;
        const std::vector<size_t> theirs = tilesOf(cuts[size_t(r)], cuts[size_t(r) + 1]);
        if (allRoots[size_t(r)].size() != theirs.size() || allCounts[size_t(r)].size() != theirs.size())
            throw Error("rank " + std::to_string(r + 1) + " sent " + std::to_string(allRoots[size_t(r)].size()) +
                        " tile roots, not " + std::to_string(theirs.size()));
        for (size_t k = 0; k < theirs.size(); ++k)
            roots[theirs[k]] = allRoots[size_t(r)][k], leafCount[theirs[k]] = allCounts[size_t(r)][k];
    }
}

// This rank's units: those inside its share nodes (a unit, no larger than a share node, lies in one; the
// units' nodes ascend in Morton order as the units do).
void Builder::findOwnUnits(RunState& rs) const {
    const int rank = rs.rank, rankCount = rs.rankCount;
    rs.myU0 = firstUnitAt(rs, rs.cuts[size_t(rank)]);
    rs.myU1 = rank + 1 == rankCount ? rs.units.size() : firstUnitAt(rs, rs.cuts[size_t(rank) + 1]);
}

size_t Builder::firstUnitAt(const RunState& rs, uint64_t code) const {
    const int shareLevel = shareLevel_;  // captured by value below
    return size_t(std::lower_bound(rs.units.begin(), rs.units.end(), code,
                                   [shareLevel](const Unit& u, uint64_t c) {
                                       return mortonEncode(uint32_t((u.x << u.level) >> shareLevel),
                                                           uint32_t((u.y << u.level) >> shareLevel)) < c;
                                   }) -
                  rs.units.begin());
}

// Under mpirun every rank writes its own cells into rank 0's file in place (GridFilePart): rank 0 says where, the
// others open their parts. (With water steps each rank keeps its own cells' codes: CellSink::keepOwn.)
std::unique_ptr<GridFilePart> Builder::openPart(const RunState& rs, CellSink& sink) const {
    std::unique_ptr<GridFilePart> part;
    if (rs.rankCount > 1) {
        std::vector<std::byte> where;
        if (rs.root) {
            GridFileWriter* w = sink.sharedWriter();
            if (!w) throw Error("internal: under mpirun rank 1's sink has no file for the ranks to write into");
            where = w->placement();
        }
        where = std::move(ranks::allGather(where)[0]);
        ranks::together([&] {
            if (!rs.root) part = std::make_unique<GridFilePart>(where, *sink.fileShape(), rs.offsetOf(rs.myU0));
        });
    }
    return part;
}

// What this rank read, built and wrote, into the ranks' log.
void Builder::logShare(const RunState& rs, const Stopwatch& rankStart) const {
    const uint64_t pixelsRead = rs.pixelsRead;
    const std::string pieces =
        rs.pieces.empty() ? std::string() : fmt::format(" in {} pieces, each read twice", rs.pieces.size() - 1);
    const std::string reads = windows_ ? fmt::format("{} window{} read{}, {} px ({:.1f} % of the raster), ",
                                                     rs.windowsRead, rs.windowsRead == 1 ? "" : "s", pieces, pixelsRead,
                                                     100.0 * double(pixelsRead) / double(t_.width * t_.height))
                                       : std::string("the whole raster held, ");
    ranks::log("hc-ingest",
               fmt::format("{}{} tiles of {}^2 px built, {} units, {} cells written, {:.3f} s, peak {:.1f} MB resident",
                           reads, rs.myTiles.size(), 1u << tileLevel_, rs.myU1 - rs.myU0, rs.myCells(),
                           rankStart.seconds(), double(peakRssBytes()) / 1e6));
}

// Under mpirun, the hashes (one stream over the whole file) and the order check's seam go on from rank to rank in
// Morton order (the checks, summaries and writing above went on in parallel): each rank in turn takes the state the
// ranks before it left, hashes its own cells from it (read back from the file: its page cache, as it just
// wrote them) and passes it on. Then each flushes its part: returns its result (GridFilePart::finish), empty on rank 0
// and in one process.
std::vector<std::byte> Builder::hashInTurn(const RunState& rs, CellSink& sink, GridFilePart* part) const {
    std::vector<std::byte> partResult;
    if (rs.rankCount <= 1) return partResult;
    const int rank = rs.rank, rankCount = rs.rankCount;
    const bool root = rs.root;
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
        ranks::log("hc-ingest", fmt::format("its {} cells ({:.1f} MB) written into the output in place; hashes in turn "
                                            "{:.3f} s (all ranks), flush {:.3f} s",
                                            rs.myCells(), double(rs.myCells()) * double(8 + 4 * layers_) / 1e6, inTurn,
                                            chain.seconds() - inTurn));
    return partResult;
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
        if (storage[i].size() != b.w * b.h)
            throw Error("internal: a water step's window read the wrong number of pixels");
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

namespace {

constexpr int64_t kHole = -1, kDry = -2;  // a block edge's pixel (bathtubBlocks): a hole, or not below the level

// A block's pixels below the bathtub's level, labelled (labelBelow).
struct BlockLabels {
    std::vector<int32_t> root;  // per pixel: its component's root pixel, -1 when not below the level
    std::vector<uint8_t> seed;  // per root pixel: the component touches the raster's edge or a hole in the block
};

// Block b's pixels below `level` labelled into L (4-connected, union-find over its pixels), a component seeded where it
// touches the edge of the raster (W x H pixels) or a hole inside the block; then b's place and its four edges' states
// appended to `edges` (Builder::bathtubBlocks).
void labelBelow(const Block& b, double level, size_t W, size_t H, BlockLabels& L, std::vector<int64_t>& edges) {
    const size_t n = b.w * b.h;
    if (n > size_t(std::numeric_limits<int32_t>::max()))
        throw Error("internal: a window of more than 2^31 pixels for the bathtub");
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
                              (r > 0 && std::isnan(b.values[p - b.w])) ||
                              (r + 1 < b.h && std::isnan(b.values[p + b.w]));
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

}  // namespace

// Each block labels the components of its pixels below the level (4-connected, union-find over its pixels) and seeds
// those that touch the raster's edge or a hole inside it. Its four edges (each pixel: its component's root and seed, a
// hole, or dry) go to every rank; every rank then joins the components that meet across two blocks' edges, and seeds
// those that meet a hole there, in the same order: the same answer everywhere. A pixel is wet when its component, so
// joined, holds a seed: exactly the pixels the whole raster's flood fill reaches.
void Builder::bathtubBlocks(double level, std::vector<std::vector<float>>& storage) const {
    const size_t W = t_.width, H = t_.height;
    std::vector<BlockLabels> local(blocks_.size());
    std::vector<int64_t> edges;  // per block: x0, y0, w, h, then its north, south, west and east edges' states
    for (size_t i = 0; i < blocks_.size(); ++i) labelBelow(blocks_[i], level, W, H, local[i], edges);
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
            for (size_t x = blocks[g].x0 >> shareLevel_; x <= (blocks[g].x0 + blocks[g].w - 1) >> shareLevel_; ++x)
                owner[y * nbx_ + x] = int32_t(g);
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
        if (ix >= W || iy >= H) return;                           // outside the raster: seeded in its block already
        const auto [h, t] = stateAt(ix, iy);
        if (t == kHole)
            seeds.push_back(id(g, s));
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
        BlockLabels& L = local[i];
        std::vector<float>& d = storage[i];
        d.assign(b.w * b.h, 0.0f);
        for (size_t p = 0; p < d.size(); ++p)  // each component's answer once, at its root (its least pixel: first)
            if (L.root[p] == int32_t(p) && !L.seed[p] && !seeds.empty())
                if (const auto it = ids.find(key(mine + i, int64_t(p) * 2)); it != ids.end())
                    L.seed[p] = wet[size_t(joins.find(it->second))];
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

void Builder::sendShare(const Stats& sum, const std::vector<double>& unitSumSq,
                        const std::vector<std::byte>& part) const {
    ranks::sendToRoot(part);
    std::vector<double> table{sum.maxDev, double(sum.pixels),
                              double(sum.wetCells)};  // then cells per level, then the unit sums
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

}  // namespace hc::ingest::detail
