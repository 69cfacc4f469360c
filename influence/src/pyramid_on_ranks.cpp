// influence/src/pyramid_on_ranks.cpp: the surface pyramid built on the ranks (on_ranks.h) and written a node at a time.
//
// A rank samples the tiles of the levels inside a partition node, node by node: a node's tiles, once sampled, get their
// parent errors from the node's own tiles and go to the rank's sample spill (a temporary file beside the pyramid), in
// key order; the node's samples are then dropped. Only keys and errors (12-20 bytes a tile) stay for every tile, and
// whole tiles only where an error must wait: a tile whose parent samples lie partly in the next node (on the node's
// high x or y edge), and a tile of the last level inside a node (its parents are coarse tiles, sampled after the
// nodes). Kept beside them are the tiles on the nodes' low edges above level 0: the parent samples those read in the
// nodes beside. Once the coarse tiles are sampled (shared out among the ranks as before), the waiting errors are
// measured over the kept tiles, the coarse ones and the other ranks' halo (detail::finishPyramid), and the file is
// written from the spill, a chunk at a time. Every sample and error is the same bits as a pyramid held whole: the
// errors read the same parent samples (measureParentErrorsInto), the samples are region.h's argument.
#include <algorithm>
#include <bit>
#include <limits>
#include <memory>

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/ranks.h"
#include "heightcast/core/timer.h"
#include "heightcast/influence/region.h"
#include "file_layouts.h"
#include "on_ranks_parts.h"
#include "pyramid_build.h"
#include "pyramid_storage.h"

namespace hc::influence {

namespace {

using detail::IndexedRegion;
using detail::Run;
using detail::SampleSpill;

// The tiles of fine levels (tiles inside a partition node) that other ranks hold beside this rank's nodes, as the
// parent level's tiles its own tiles' parent errors read (detail::finishPyramid's halo): each rank shares the first row
// and column of its tiles on the low x or low y edge of their node (the samples a tile in the node to their -x, -y or
// -x-y reads as parent samples), and keeps of the others' those beside its own nodes; their other samples are NaN,
// never read.
SurfacePyramid haloOf(const RankPartition& part, const Grid& shape, const SurfacePyramid::Storage& owned,
                      const std::vector<int>& sides, int channels) {
    const int rank = ranks::rank(), top = int(sides.size()) - 1;
    const uint64_t nodeSide = uint64_t{1} << part.level;  // in finest cells
    auto rankOf = [&](uint64_t key) {
        const uint64_t node = key & ~(mortonSpan(part.level) - 1);
        const auto it = std::lower_bound(part.keys.begin(), part.keys.end(), node);
        return it != part.keys.end() && *it == node ? part.rank[size_t(it - part.keys.begin())] : -1;
    };
    auto halo = std::make_shared<SurfacePyramid::Storage>();
    halo->keys.resize(sides.size());
    halo->samples.resize(sides.size());
    for (int t = 1; t <= top; ++t) {
        const size_t side = size_t(sides[size_t(t)]), plane = side * side, ch = size_t(channels);
        if (t + std::countr_zero(unsigned(side)) > part.level) continue;  // a coarse level: every rank holds it whole
        std::vector<uint64_t> edgeKeys;
        std::vector<float> edges;  // per tile, per channel: row 0, then column 0
        const auto& keys = owned.keys[size_t(t)];
        for (size_t i = 0; i < keys.size(); ++i) {
            if (mortonX(keys[i]) % nodeSide != 0 && mortonY(keys[i]) % nodeSide != 0) continue;
            edgeKeys.push_back(keys[i]);
            for (size_t c = 0; c < ch; ++c) {
                const float* s = &owned.samples[size_t(t)][(i * ch + c) * plane];
                edges.insert(edges.end(), s, s + side);
                for (size_t j = 0; j < side; ++j) edges.push_back(s[j * side]);
            }
        }
        const auto allKeys = ranks::allGatherVectors(edgeKeys);
        const auto allEdges = ranks::allGatherVectors(edges);
        const uint64_t span = uint64_t(side) << t;  // a tile's side in finest cells
        for (size_t r = 0; r < allKeys.size(); ++r) {
            if (int(r) == rank) continue;
            if (allEdges[r].size() != allKeys[r].size() * ch * 2 * side)
                throw Error("rank " + std::to_string(r + 1) + " sent a halo of another size");
            for (size_t i = 0; i < allKeys[r].size(); ++i) {
                const uint64_t key = allKeys[r][i], x = mortonX(key), y = mortonY(key);
                const bool beside =
                    (x >= span && rankOf(mortonEncode(uint32_t(x - span), uint32_t(y))) == rank) ||
                    (y >= span && rankOf(mortonEncode(uint32_t(x), uint32_t(y - span))) == rank) ||
                    (x >= span && y >= span && rankOf(mortonEncode(uint32_t(x - span), uint32_t(y - span))) == rank);
                if (!beside) continue;
                halo->keys[size_t(t)].push_back(key);
                auto& out = halo->samples[size_t(t)];
                const size_t at = out.size();
                out.resize(at + ch * plane, std::numeric_limits<float>::quiet_NaN());
                const float* e = &allEdges[r][i * ch * 2 * side];
                for (size_t c = 0; c < ch; ++c, e += 2 * side) {
                    float* tile = &out[at + c * plane];
                    std::copy_n(e, side, tile);
                    for (size_t j = 0; j < side; ++j) tile[j * side] = e[side + j];
                }
            }
        }
    }
    SurfacePyramid p;
    p.finestCellM = shape.finestCellM;
    p.rootLevel = shape.rootLevel;
    p.channels = channels;
    p.levels.resize(sides.size());
    for (size_t t = 0; t < sides.size(); ++t) {
        p.levels[t].level = int(t);
        p.levels[t].tileSide = sides[t];
        p.levels[t].keys = halo->keys[t];
        p.levels[t].samples = halo->samples[t];
    }
    p.storage = std::move(halo);
    return p;
}

// The build's state on one rank (the file's first comment): the partition, and per level this rank's tiles as the file
// will hold them and the tiles kept whole for the errors that wait.
class PyramidBuild {
public:
    PyramidBuild(const GridRegionReader& file, const KernelParams& params, unsigned threads, bool waterOnly,
                 const std::string& path);
    void sampleNodes(bool progress);
    void sampleCoarse();
    void measureWaiting();
    PyramidFileSummary write(const std::string& path);
    RankShare share;

private:
    // This rank's tiles of a level, as the file's sections hold them: samples in the spill (runs of it, a node's at a
    // time) or, on the coarse levels, in memory.
    struct Level {
        std::vector<uint64_t> keys;
        std::vector<float> errors;                             // per tile, per channel written
        std::vector<std::pair<uint64_t, uint64_t>> spillRuns;  // (offset, bytes) until the spill is mapped
        std::vector<float> samples;                            // the coarse levels
    };
    int nodeLevelOf(int t) const { return t + std::countr_zero(unsigned(sides_[size_t(t)])); }
    size_t planeOf(int t) const { return size_t(sides_[size_t(t)]) * size_t(sides_[size_t(t)]); }
    bool coarse(int t) const { return nodeLevelOf(t) > part_.level; }
    SurfacePyramid shell(int channels) const;
    void sampleNode(uint64_t nodeKey, std::vector<std::vector<uint64_t>>& keys,
                    std::vector<std::vector<float>>& samples, std::vector<detail::PyramidWorkspace>& scratch);
    void putNode(std::vector<std::vector<uint64_t>>&& keys, std::vector<std::vector<float>>&& samples);
    struct CoarseTile {
        int t;
        uint64_t key;
    };
    void sampleCoarseShare(const std::vector<CoarseTile>& tiles, std::vector<std::vector<uint64_t>>& keys,
                           std::vector<std::vector<float>>& samples);
    bool written(const float* tile, int t) const;
    void appendErrors(std::vector<float>& to, const float* from) const;

    const GridRegionReader& file_;
    const Grid& shape_;
    const KernelParams params_;
    const unsigned threads_;
    const bool waterOnly_;
    const int depthLayer_, channels_, firstOut_, channelsOut_;  // sampled; written from firstOut_ on
    const RankPartition part_;
    const std::vector<int> sides_;
    const int top_;
    int lastInside_ = -1;  // the levels whose tiles lie inside a partition node: 0..lastInside_
    std::vector<double> margins_;
    std::vector<Level> out_;
    SampleSpill spill_;
    // Kept whole: per level the tiles, every channel, and per tile the index of its error among out_'s (-1: none
    // waits); on the coarse levels every tile (all ranks').
    std::shared_ptr<SurfacePyramid::Storage> kept_ = std::make_shared<SurfacePyramid::Storage>();
    std::vector<std::vector<int64_t>> waiting_;
    std::vector<std::vector<uint64_t>> coarseKept_, coarseMarked_;
};

PyramidBuild::PyramidBuild(const GridRegionReader& file, const KernelParams& params, unsigned threads, bool waterOnly,
                           const std::string& path)
    : file_(file),
      shape_(file.shape()),
      params_(params),
      threads_(resolveThreads(threads)),
      waterOnly_(waterOnly),
      depthLayer_(shape_.findLayer("water_depth")),
      channels_(depthLayer_ >= 0 ? 3 : 1),
      firstOut_(waterOnly ? 1 : 0),
      channelsOut_(waterOnly ? 2 : channels_),
      part_(partitionOf(file, ranks::count())),
      sides_(detail::pyramidTileSides(shape_)),
      top_(int(sides_.size()) - 1),
      out_(sides_.size()),
      spill_(path),
      waiting_(sides_.size()),
      coarseKept_(sides_.size()),
      coarseMarked_(sides_.size()) {
    if (waterOnly && depthLayer_ < 0) throw Error("a water pyramid is built for a grid with water");
    // Margins: every cell whose kernel reaches the node; for a water pyramid also those one tile further (the tiles a
    // wet cell marks are grown by one: wetMarkedTiles), a tile of a level inside the node being at most the node's
    // side.
    margins_ = kernelReachM(shape_, params_);
    if (waterOnly)
        for (double& m : margins_) m += shape_.levelSizeM(part_.level);
    while (lastInside_ < top_ && nodeLevelOf(lastInside_ + 1) <= part_.level) ++lastInside_;
    kept_->keys.resize(sides_.size());
    kept_->samples.resize(sides_.size());
}

// The pyramid's fields (its levels empty), with `channels`.
SurfacePyramid PyramidBuild::shell(int channels) const {
    SurfacePyramid p;
    p.finestCellM = shape_.finestCellM;
    p.rootLevel = shape_.rootLevel;
    p.params = params_;
    p.structureHash = file_.info().structureHash;
    p.contentHash = file_.info().contentHash;
    p.channels = channels;
    p.levels.resize(sides_.size());
    for (size_t t = 0; t < sides_.size(); ++t) p.levels[t].level = int(t), p.levels[t].tileSide = sides_[t];
    return p;
}

// Whether a tile of level t (its channels at `tile`) is written: a water pyramid's where water is drawn.
bool PyramidBuild::written(const float* tile, int t) const {
    return !waterOnly_ || detail::waterDrawnIn(tile, planeOf(t));
}

void PyramidBuild::appendErrors(std::vector<float>& to, const float* from) const {
    to.insert(to.end(), from + firstOut_, from + firstOut_ + channelsOut_);
}

// The tiles of node `nodeKey` on the levels inside it, sampled into keys[t] and samples[t] (ascending keys), from a
// region of the file around the node; the coarse levels' tiles its own cells keep (and, for water, mark) noted.
void PyramidBuild::sampleNode(uint64_t nodeKey, std::vector<std::vector<uint64_t>>& keys,
                              std::vector<std::vector<float>>& samples,
                              std::vector<detail::PyramidWorkspace>& scratch) {
    const IndexedRegion r = detail::readIndexed(file_, detail::nodeSquare(shape_, nodeKey, part_.level), margins_,
                                                nodeKey, part_.level, false);
    const detail::ListIndex index(r.grid, params_);
    // Every level's tile keys at once: inside the node from every cell read (the node's and its margin's), above it
    // from the node's own cells.
    std::vector<std::vector<uint64_t>> levelKeys(size_t(top_) + 1);
    detail::tileKeysOnThreads(r.grid, params_, 0, r.grid.cellCount(), 0, lastInside_, top_, sides_, threads_,
                              levelKeys);
    detail::tileKeysOnThreads(r.grid, params_, r.lo, r.hi, lastInside_ + 1, top_, top_, sides_, threads_, levelKeys);
    for (int t = 0; t <= top_; ++t) {
        const int side = sides_[size_t(t)];
        std::vector<uint64_t> k = std::move(levelKeys[size_t(t)]);
        if (coarse(t)) {  // a coarse tile: decided once every node has spoken for its own cells
            coarseKept_[size_t(t)].insert(coarseKept_[size_t(t)].end(), k.begin(), k.end());
            if (waterOnly_)
                detail::wetMarkedTiles(r.grid, params_, depthLayer_, r.lo, r.hi, t, side, coarseMarked_[size_t(t)]);
            continue;
        }
        // A tile inside the node: kept by a cell of the node or of its margin, whose kernel may reach into it.
        const uint64_t nodeMask = ~(mortonSpan(part_.level) - 1);
        std::erase_if(k, [&](uint64_t key) { return (key & nodeMask) != nodeKey; });
        std::sort(k.begin(), k.end());
        k.erase(std::unique(k.begin(), k.end()), k.end());
        std::erase_if(k, [&](uint64_t key) { return file_.cellsInNode(key, nodeLevelOf(t)) == 0; });  // all NaN there
        if (waterOnly_) {
            std::vector<uint64_t> marked, both;
            detail::wetMarkedTiles(r.grid, params_, depthLayer_, 0, r.grid.cellCount(), t, side, marked);
            std::sort(marked.begin(), marked.end());
            std::set_intersection(k.begin(), k.end(), marked.begin(), marked.end(), std::back_inserter(both));
            k = std::move(both);
        }
        const size_t floats = size_t(channels_) * planeOf(t);
        samples[size_t(t)].resize(k.size() * floats);
        parallelFor(k.size(), 4, threads_, [&](size_t b, size_t e, unsigned worker) {
            for (size_t i = b; i < e; ++i)
                detail::buildTile(r.grid, index, params_, t, side, k[i], channels_, depthLayer_,
                                  &samples[size_t(t)][i * floats], scratch[worker], -1);
        });
        share.tiles += k.size();
        keys[size_t(t)] = std::move(k);
    }
    share.nodes += 1, share.cells += r.hi - r.lo, share.cellsRead += r.grid.cellCount();
}

// A node's tiles (sampleNode) to the file's order: their parent errors from the node's own tiles, the tiles written
// to the spill (and their keys and errors kept), those whose errors wait and those the waiting ones read kept whole.
void PyramidBuild::putNode(std::vector<std::vector<uint64_t>>&& keys, std::vector<std::vector<float>>&& samples) {
    auto node = std::make_shared<SurfacePyramid::Storage>();
    node->keys = std::move(keys);
    node->samples = std::move(samples);
    const SurfacePyramid p = detail::finishPyramid(shell(channels_), node, sides_, threads_);
    const uint64_t nodeSide = uint64_t{1} << part_.level;  // in finest cells
    for (int t = 0; t <= lastInside_; ++t) {
        const SurfacePyramid::Level& L = p.levels[size_t(t)];
        const size_t plane = planeOf(t), floats = size_t(channels_) * plane;
        const uint64_t span = uint64_t(sides_[size_t(t)]) << t;  // a tile's side in finest cells
        Level& o = out_[size_t(t)];
        const uint64_t spillAt = spill_.size();
        for (size_t i = 0; i < L.tileCount(); ++i) {
            const uint64_t x = mortonX(L.keys[i]), y = mortonY(L.keys[i]);
            const bool low = x % nodeSide == 0 || y % nodeSide == 0,
                       high = (x + span) % nodeSide == 0 || (y + span) % nodeSide == 0;
            const bool waits = t == lastInside_ || high;  // its parent samples are not all in this node
            const float* tile = &L.samples[i * floats];
            const bool out = written(tile, t);
            if (waits || (low && t > 0)) {
                kept_->keys[size_t(t)].push_back(L.keys[i]);
                kept_->samples[size_t(t)].insert(kept_->samples[size_t(t)].end(), tile, tile + floats);
                waiting_[size_t(t)].push_back(waits && out ? int64_t(o.keys.size()) : -1);
            }
            if (!out) continue;
            o.keys.push_back(L.keys[i]);
            appendErrors(o.errors, &L.parentErrorM[i * size_t(channels_)]);
            spill_.append(std::as_bytes(std::span(tile + size_t(firstOut_) * plane, size_t(channelsOut_) * plane)));
        }
        if (spill_.size() > spillAt) o.spillRuns.push_back({spillAt, spill_.size() - spillAt});
    }
}

void PyramidBuild::sampleNodes(bool progress) {
    const std::vector<size_t> mine = detail::myNodes(part_);
    ranks::together([&] {
        Progress bar("surface pyramid", mine.size(), progress && ranks::rank() == 0);
        std::vector<detail::PyramidWorkspace> scratch(threads_);
        for (size_t j : mine) {
            std::vector<std::vector<uint64_t>> keys(size_t(top_) + 1);
            std::vector<std::vector<float>> samples(size_t(top_) + 1);
            sampleNode(part_.keys[j], keys, samples, scratch);
            file_.releasePages();  // the node's cells were copied out: the file's pages need not stay resident
            putNode(std::move(keys), std::move(samples));
            bar.advance(1);
        }
        bar.finish();
    });
}

// The coarse tiles: kept where some node keeps them (and, for water, some wet cell marks them), then shared out one by
// one (sampleCoarseShare) and gathered on every rank (a few thousand at most: one per node of a level coarser than the
// partition's), for the errors that wait and, on rank 0, to write.
void PyramidBuild::sampleCoarse() {
    std::vector<CoarseTile> tiles;
    for (int t = 0; t <= top_; ++t) {
        if (!coarse(t)) continue;
        auto unite = [](const std::vector<uint64_t>& v) {
            std::vector<uint64_t> all;
            for (const auto& from : ranks::allGatherVectors(v)) all.insert(all.end(), from.begin(), from.end());
            std::sort(all.begin(), all.end());
            all.erase(std::unique(all.begin(), all.end()), all.end());
            return all;
        };
        std::vector<uint64_t> kept = unite(coarseKept_[size_t(t)]);
        std::erase_if(kept, [&](uint64_t key) { return file_.cellsInNode(key, nodeLevelOf(t)) == 0; });  // all NaN
        if (waterOnly_) {
            const std::vector<uint64_t> marked = unite(coarseMarked_[size_t(t)]);
            std::vector<uint64_t> both;
            std::set_intersection(kept.begin(), kept.end(), marked.begin(), marked.end(), std::back_inserter(both));
            kept = std::move(both);
        }
        for (uint64_t key : kept) tiles.push_back({t, key});
    }
    std::vector<std::vector<uint64_t>> keys(sides_.size());
    std::vector<std::vector<float>> samples(sides_.size());
    ranks::together([&] { sampleCoarseShare(tiles, keys, samples); });
    for (int t = 0; t <= top_; ++t) {
        if (!coarse(t)) continue;
        const size_t floats = size_t(channels_) * planeOf(t);
        const auto k = ranks::allGatherVectors(keys[size_t(t)]);
        const auto v = ranks::allGatherVectors(samples[size_t(t)]);
        std::vector<std::pair<uint64_t, std::pair<size_t, size_t>>> order;  // key, (rank, tile)
        for (size_t r = 0; r < k.size(); ++r)
            for (size_t i = 0; i < k[r].size(); ++i) order.push_back({k[r][i], {r, i}});
        std::sort(order.begin(), order.end());
        for (size_t i = 1; i < order.size(); ++i)
            if (order[i].first == order[i - 1].first)
                throw Error("two ranks sampled the same pyramid tile of level " + std::to_string(t));
        auto& outKeys = kept_->keys[size_t(t)];
        auto& outSamples = kept_->samples[size_t(t)];
        outSamples.resize(order.size() * floats);
        for (size_t i = 0; i < order.size(); ++i) {
            outKeys.push_back(order[i].first);
            const auto [r, tile] = order[i].second;
            std::copy_n(v[r].begin() + ptrdiff_t(tile * floats), floats, outSamples.begin() + ptrdiff_t(i * floats));
        }
    }
}

// This rank's share of the coarse tiles (every count-th), each block sampled from a region read around the block.
void PyramidBuild::sampleCoarseShare(const std::vector<CoarseTile>& tiles, std::vector<std::vector<uint64_t>>& keys,
                                     std::vector<std::vector<float>>& samples) {
    std::vector<CoarseTile> ours;
    for (size_t i = 0; i < tiles.size(); ++i)
        if (int(i % size_t(ranks::count())) == ranks::rank()) ours.push_back(tiles[i]);
    struct Job {
        size_t tile;
        int block;
    };
    std::vector<Job> jobs;
    std::vector<size_t> at(ours.size());
    for (size_t i = 0; i < ours.size(); ++i) {
        const int t = ours[i].t, block = detail::pyramidBlockSide(shape_, params_, t),
                  blocks = (sides_[size_t(t)] + block - 1) / block;
        at[i] = samples[size_t(t)].size();
        samples[size_t(t)].resize(at[i] + size_t(channels_) * planeOf(t));
        keys[size_t(t)].push_back(ours[i].key);
        for (int b = 0; b < blocks * blocks; ++b) jobs.push_back({i, b});
    }
    share.tiles += ours.size();
    const std::vector<double> reach = kernelReachM(shape_, params_);
    std::vector<uint64_t> readPerWorker(threads_, 0);
    std::vector<detail::PyramidWorkspace> scratch(threads_);
    detail::PageReleaser release(file_);
    parallelFor(jobs.size(), 1, threads_, [&](size_t b, size_t e, unsigned worker) {
        for (size_t q = b; q < e; ++q) {
            const CoarseTile& c = ours[jobs[q].tile];
            const int side = sides_[size_t(c.t)], block = detail::pyramidBlockSide(shape_, params_, c.t),
                      blocks = (side + block - 1) / block;
            const int bi = (jobs[q].block % blocks) * block, bj = (jobs[q].block / blocks) * block;
            const int bi1 = std::min(side, bi + block), bj1 = std::min(side, bj + block);
            const double h = shape_.levelSizeM(c.t);
            const double x0 = double(mortonX(c.key)) * shape_.finestCellM,
                         y0 = double(mortonY(c.key)) * shape_.finestCellM;
            const Grid::Square box{x0 + bi * h, y0 + bj * h, x0 + (bi1 - 1) * h, y0 + (bj1 - 1) * h};
            const Grid region = file_.region(box, reach);
            readPerWorker[worker] += region.cellCount();
            release.after(region);
            const detail::ListIndex index(region, params_);
            detail::buildTile(region, index, params_, c.t, side, c.key, channels_, depthLayer_,
                              &samples[size_t(c.t)][at[jobs[q].tile]], scratch[worker], jobs[q].block);
        }
    });
    for (uint64_t n : readPerWorker) share.cellsRead += n;
}

// The errors that waited: measured over the kept tiles, the coarse ones and the other ranks' halo, each into its place
// among the tiles written; and on rank 0 the coarse levels to write.
void PyramidBuild::measureWaiting() {
    const SurfacePyramid halo = haloOf(part_, shape_, *kept_, sides_, channels_);
    const SurfacePyramid p = detail::finishPyramid(shell(channels_), kept_, sides_, threads_, &halo);
    const size_t ch = size_t(channels_), chOut = size_t(channelsOut_);
    for (int t = 0; t <= lastInside_; ++t) {
        const SurfacePyramid::Level& L = p.levels[size_t(t)];
        for (size_t i = 0; i < waiting_[size_t(t)].size(); ++i)
            if (const int64_t at = waiting_[size_t(t)][i]; at >= 0)
                std::copy_n(&L.parentErrorM[i * ch + size_t(firstOut_)], chOut,
                            &out_[size_t(t)].errors[size_t(at) * chOut]);
    }
    if (ranks::rank() != 0) return;  // rank 0 writes the coarse levels
    for (int t = lastInside_ + 1; t <= top_; ++t) {
        const SurfacePyramid::Level& L = p.levels[size_t(t)];
        const size_t plane = planeOf(t), floats = ch * plane;
        Level& o = out_[size_t(t)];
        for (size_t i = 0; i < L.tileCount(); ++i) {
            const float* tile = &L.samples[i * floats];
            if (!written(tile, t)) continue;
            o.keys.push_back(L.keys[i]);
            appendErrors(o.errors, &L.parentErrorM[i * ch]);
            o.samples.insert(o.samples.end(), tile + size_t(firstOut_) * plane,
                             tile + (size_t(firstOut_) + chOut) * plane);
        }
    }
}

// Collective: the file, every rank's tiles at their place (rank 0's first, ranks in Morton order), the samples from the
// spill a chunk at a time; the whole pyramid's figures.
PyramidFileSummary PyramidBuild::write(const std::string& path) {
    std::span<const std::byte> spilled;
    ranks::together([&] { spilled = spill_.map(); });
    const size_t levels = sides_.size(), chOut = size_t(channelsOut_);
    std::vector<uint64_t> tiles(levels);
    for (size_t t = 0; t < levels; ++t) tiles[t] = out_[t].keys.size();
    const auto perRank = ranks::allGatherVectors(tiles);
    std::vector<uint64_t> total(levels, 0), before(levels, 0);
    for (int r = 0; r < ranks::count(); ++r)
        for (size_t t = 0; t < levels; ++t) {
            if (perRank[size_t(r)].size() != levels)
                throw Error("rank " + std::to_string(r + 1) + " holds a pyramid of another height");
            total[t] += perRank[size_t(r)][t];
            if (r < ranks::rank()) before[t] += perRank[size_t(r)][t];
        }
    std::vector<Run> runs;
    for (size_t t = 0; t < levels; ++t) {
        const Level& o = out_[t];
        if (o.keys.empty()) continue;
        const uint64_t plane = planeOf(int(t));
        runs.push_back({3 * t, before[t] * 8, std::as_bytes(std::span(o.keys))});
        runs.push_back({3 * t + 1, before[t] * chOut * 4, std::as_bytes(std::span(o.errors))});
        uint64_t at = before[t] * chOut * plane * 4;
        for (const auto& [offset, bytes] : o.spillRuns)
            runs.push_back({3 * t + 2, at, spilled.subspan(offset, bytes), &spill_}), at += bytes;
        if (!o.samples.empty()) runs.push_back({3 * t + 2, at, std::as_bytes(std::span(o.samples))});
    }
    const SurfacePyramid head = shell(channelsOut_);
    detail::writeByParts(path, detail::pyramidFileFormat(), detail::pyramidFileLayout(total, sides_, channelsOut_),
                         runs, detail::pyramidFileHeader(head));
    // The figures: this rank's, then every rank's added (doubles hold the counts exactly below 2^53).
    std::vector<double> mine(2 * levels, 0.0);
    for (size_t t = 0; t < levels; ++t) {
        mine[2 * t] = double(tiles[t]);
        for (size_t i = 0; i < out_[t].errors.size(); i += chOut)
            mine[2 * t + 1] = std::max(mine[2 * t + 1], double(out_[t].errors[i]));
    }
    PyramidFileSummary sum;
    sum.channels = channelsOut_;
    sum.tiles.assign(levels, 0);
    sum.worstM.assign(levels, 0.0f);
    for (const auto& v : ranks::allGatherVectors(mine)) {
        if (v.size() != mine.size()) throw Error("a rank holds a pyramid of another height");
        for (size_t t = 0; t < levels; ++t)
            sum.tiles[t] += uint64_t(v[2 * t]), sum.worstM[t] = std::max(sum.worstM[t], float(v[2 * t + 1]));
    }
    for (size_t t = 0; t < levels; ++t) {
        const uint64_t samples = sum.tiles[t] * chOut * planeOf(int(t));
        sum.samples += samples;
        sum.bytes += sum.tiles[t] * (8 + 4 * chOut) + samples * 4;
    }
    return sum;
}

}  // namespace

PyramidFileSummary writePyramidOnRanks(const GridRegionReader& file, const KernelParams& params, unsigned threads,
                                       bool progress, bool waterOnly, const std::string& path, RankShare* share) {
    if (std::string why = params.validate(); !why.empty()) throw Error("influence parameters: " + why);
    const Stopwatch clock;
    std::unique_ptr<PyramidBuild> b;
    ranks::together([&] { b = std::make_unique<PyramidBuild>(file, params, threads, waterOnly, path); });
    b->sampleNodes(progress);
    b->sampleCoarse();
    ranks::together([&] { b->measureWaiting(); });
    b->share.seconds = clock.seconds();
    if (share) *share = b->share;
    const Stopwatch writing;
    PyramidFileSummary sum = b->write(path);
    sum.buildSeconds = b->share.seconds, sum.writeSeconds = writing.seconds();
    return sum;
}

}  // namespace hc::influence
