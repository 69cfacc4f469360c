// The lists and the pyramid on the ranks of mpirun (on_ranks.h): each rank its nodes, each node from a region of the
// grid file around it; rank 0 assembles all of it.
#include "heightcast/influence/on_ranks.h"

#include <algorithm>
#include <bit>
#include <numeric>

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/ranks.h"
#include "heightcast/core/timer.h"
#include "heightcast/influence/region.h"
#include "list_index.h"
#include "pyramid_build.h"
#include "pyramid_storage.h"

namespace hc::influence {

namespace {

constexpr int kNodesPerRank = 16;   // enough nodes to balance cell counts between ranks
constexpr int kMaxPartitionDepth = 6;  // at most 4^6 nodes looked at

Grid::Square nodeSquare(const Grid& shape, uint64_t key, int level) {
    const double x0 = double(mortonX(key)) * shape.finestCellM, y0 = double(mortonY(key)) * shape.finestCellM;
    const double side = shape.levelSizeM(level);
    return {x0, y0, x0 + side, y0 + side};
}

// A region of the file with each of its cells' index in the file.
struct IndexedRegion {
    Grid grid;
    std::vector<uint32_t> fileIndex;  // per region cell
    size_t lo = 0, hi = 0;            // the region cells inside the node it was read for
};

IndexedRegion readIndexed(const GridRegionReader& file, const Grid::Square& box, const std::vector<double>& margins, uint64_t key, int level,
                          bool wantIndex) {
    IndexedRegion r;
    std::vector<std::pair<uint64_t, uint64_t>> runs;
    r.grid = file.region(box, margins, &runs);
    if (wantIndex) {
        r.fileIndex.reserve(r.grid.cellCount());
        for (auto [lo, hi] : runs)
            for (uint64_t i = lo; i < hi; ++i) r.fileIndex.push_back(uint32_t(i));
    }
    const auto& c = r.grid.codes;
    r.lo = size_t(std::lower_bound(c.begin(), c.end(), makeCellCode(key, 0)) - c.begin());
    r.hi = size_t(std::lower_bound(c.begin(), c.end(), makeCellCode(key + mortonSpan(level), 0)) - c.begin());
    return r;
}

std::vector<size_t> myNodes(const RankPartition& part) {
    std::vector<size_t> out;
    for (size_t j = 0; j < part.keys.size(); ++j)
        if (part.rank[j] == ranks::rank()) out.push_back(j);
    return out;
}

}  // namespace

RankPartition partitionOf(const GridRegionReader& file, int ranks) {
    const Grid& shape = file.shape();
    const int root = shape.rootLevel;
    // No node finer than the coarsest cell (each cell lies in one node) or than the node of a finest pyramid tile.
    const int lowest = std::min(root, std::max(shape.maxLevel, kPyramidTileLog2));
    RankPartition p;
    for (int level = root;; --level) {
        p = {};
        p.level = level;
        const uint64_t nodes = uint64_t{1} << (2 * (root - level));
        for (uint64_t k = 0; k < nodes; ++k)
            if (const uint64_t n = file.cellsInNode(k * mortonSpan(level), level); n > 0) {
                p.keys.push_back(k * mortonSpan(level));
                p.cells.push_back(n);
            }
        if (p.keys.size() >= size_t(kNodesPerRank) * size_t(ranks) || level <= lowest || root - level >= kMaxPartitionDepth) break;
    }
    const uint64_t total = std::accumulate(p.cells.begin(), p.cells.end(), uint64_t{0});
    uint64_t before = 0;
    for (uint64_t n : p.cells) {
        // The rank whose equal share holds the node's middle cell.
        const long double mid = (long double)before + (long double)n / 2;
        p.rank.push_back(std::min(ranks - 1, int(mid * ranks / (long double)std::max<uint64_t>(total, 1))));
        before += n;
    }
    return p;
}

InfluenceLists buildInfluenceListsOnRanks(const GridRegionReader& file, const KernelParams& params, unsigned threads, bool progress,
                                          RankShare* share) {
    if (std::string why = params.validate(); !why.empty()) throw Error("influence parameters: " + why);
    if (file.cellCount() >= std::numeric_limits<uint32_t>::max()) throw Error("grid has too many cells for 32-bit influence indices");
    const Stopwatch clock;
    const int rank = ranks::rank(), count = ranks::count();
    const RankPartition part = partitionOf(file, count);
    const std::vector<double> margins = kernelReachM(file.shape(), params);
    const std::vector<size_t> mine = myNodes(part);
    RankShare s;
    uint64_t myCells = 0;
    for (size_t j : mine) myCells += part.cells[j];
    std::vector<uint32_t> lengths, entries;
    {
        Progress bar("influence lists", myCells, progress && rank == 0);
        for (size_t j : mine) {
            const IndexedRegion r = readIndexed(file, nodeSquare(file.shape(), part.keys[j], part.level), margins, part.keys[j], part.level, true);
            const detail::ListIndex index(r.grid, params);
            const auto blocks = detail::splitNodes(r.grid, {part.keys[j], part.level, r.lo, r.hi}, detail::kSuperBlockCells);
            const detail::ListPart lists = detail::buildListPart(index, blocks, 0, blocks.size(), threads, bar);
            for (size_t k = 0; k + 1 < lists.offsets.size(); ++k) lengths.push_back(uint32_t(lists.offsets[k + 1] - lists.offsets[k]));
            const size_t at = entries.size();
            entries.resize(at + lists.entries);
            for (size_t e = 0; e < lists.entries; ++e) entries[at + e] = r.fileIndex[lists.indices[e]];  // region -> file index
            s.nodes += 1, s.cells += r.hi - r.lo, s.cellsRead += r.grid.cellCount();
        }
        bar.finish();
    }
    s.seconds = clock.seconds();
    if (share) *share = s;
    // Every rank's cell and entry counts first (a small table), so rank 0 places each rank's lists straight into the one
    // buffer of the whole cache: its peak is the cache plus its own share, not a cache grown by copies.
    const auto counts = ranks::allGatherVectors(std::vector<uint64_t>{lengths.size(), entries.size()});
    if (rank != 0) {
        ranks::sendToRoot(lengths);
        ranks::sendToRoot(entries);
        return {};
    }
    const size_t n = file.cellCount();
    uint64_t totalCells = 0, totalEntries = 0;
    for (const auto& c : counts) totalCells += c[0], totalEntries += c[1];
    if (totalCells != n) throw Error("the ranks built lists of " + std::to_string(totalCells) + " cells, not " + std::to_string(n));
    std::vector<uint64_t> offsets(n + 1, 0);
    auto indices = std::unique_ptr<uint32_t[]>(new uint32_t[std::max<uint64_t>(totalEntries, 1)]);
    size_t cell = 0, used = 0;
    std::vector<uint32_t> len;
    for (int r = 0; r < count; ++r) {
        const uint64_t cells = counts[size_t(r)][0], ent = counts[size_t(r)][1];
        if (r == 0) {
            len = std::move(lengths);
            std::copy(entries.begin(), entries.end(), indices.get());
            std::vector<uint32_t>().swap(entries);
        } else {
            len.resize(cells);
            ranks::receiveInto(r, std::as_writable_bytes(std::span<uint32_t>(len)));
            ranks::receiveInto(r, std::as_writable_bytes(std::span<uint32_t>(indices.get() + used, ent)));
        }
        uint64_t sum = 0;
        for (size_t k = 0; k < cells; ++k) offsets[cell + k + 1] = offsets[cell + k] + len[k], sum += len[k];
        if (sum != ent) throw Error("rank " + std::to_string(r + 1) + " sent list lengths that do not add up to its entries");
        cell += cells, used += ent;
    }
    return InfluenceLists(params, file.info().structureHash, file.info().contentHash, std::move(offsets), std::move(indices), used);
}

SurfacePyramid buildPyramidOnRanks(const GridRegionReader& file, const KernelParams& params, unsigned threads, bool progress,
                                   bool waterOnly, RankShare* share) {
    if (std::string why = params.validate(); !why.empty()) throw Error("influence parameters: " + why);
    const Grid& shape = file.shape();
    const int depthLayer = shape.findLayer("water_depth");
    if (waterOnly && depthLayer < 0) throw Error("a water pyramid is built for a grid with water");
    const Stopwatch clock;
    const int rank = ranks::rank(), count = ranks::count();
    threads = resolveThreads(threads);
    const RankPartition part = partitionOf(file, count);
    const int channels = depthLayer >= 0 ? 3 : 1;
    const std::vector<int> sides = detail::pyramidTileSides(shape);
    const int top = int(sides.size()) - 1;
    auto nodeLevelOf = [&](int t) { return t + std::countr_zero(unsigned(sides[size_t(t)])); };
    auto planeOf = [&](int t) { return size_t(sides[size_t(t)]) * size_t(sides[size_t(t)]); };
    // Margins: every cell whose kernel reaches the node; for a water pyramid also those one tile further (the tiles a wet
    // cell marks are grown by one: wetMarkedTiles), a tile of a level inside the node being at most the node's side.
    std::vector<double> margins = kernelReachM(shape, params);
    if (waterOnly)
        for (double& m : margins) m += shape.levelSizeM(part.level);
    const std::vector<double> reach = kernelReachM(shape, params);

    RankShare s;
    // What this rank sends: per level, its tiles' keys and samples.
    std::vector<std::vector<uint64_t>> keys(size_t(top) + 1);
    std::vector<std::vector<float>> samples(size_t(top) + 1);
    // Coarse levels (tiles larger than a node): the tiles this rank's nodes keep, and (water) mark.
    std::vector<std::vector<uint64_t>> coarseKept(size_t(top) + 1), coarseMarked(size_t(top) + 1);
    const std::vector<size_t> mine = myNodes(part);
    {
        Progress bar("surface pyramid", mine.size(), progress && rank == 0);
        std::vector<detail::PyramidWorkspace> scratch(threads);
        for (size_t j : mine) {
            const uint64_t nodeKey = part.keys[j];
            const IndexedRegion r = readIndexed(file, nodeSquare(shape, nodeKey, part.level), margins, nodeKey, part.level, false);
            const detail::ListIndex index(r.grid, params);
            for (int t = 0; t <= top; ++t) {
                const int side = sides[size_t(t)];
                std::vector<uint64_t> k;
                if (nodeLevelOf(t) > part.level) {  // a coarse tile: decided once every node has spoken for its own cells
                    detail::tileKeysOfCells(r.grid, params, r.lo, r.hi, t, top, side, k);
                    coarseKept[size_t(t)].insert(coarseKept[size_t(t)].end(), k.begin(), k.end());
                    if (waterOnly) detail::wetMarkedTiles(r.grid, params, depthLayer, r.lo, r.hi, t, side, coarseMarked[size_t(t)]);
                    continue;
                }
                // A tile inside the node: kept by a cell of the node or of its margin, whose kernel may reach into it.
                detail::tileKeysOfCells(r.grid, params, 0, r.grid.cellCount(), t, top, side, k);
                const uint64_t nodeMask = ~(mortonSpan(part.level) - 1);
                std::erase_if(k, [&](uint64_t key) { return (key & nodeMask) != nodeKey; });
                std::sort(k.begin(), k.end());
                k.erase(std::unique(k.begin(), k.end()), k.end());
                std::erase_if(k, [&](uint64_t key) { return file.cellsInNode(key, nodeLevelOf(t)) == 0; });  // all NaN there
                if (waterOnly) {
                    std::vector<uint64_t> marked, kept;
                    detail::wetMarkedTiles(r.grid, params, depthLayer, 0, r.grid.cellCount(), t, side, marked);
                    std::sort(marked.begin(), marked.end());
                    std::set_intersection(k.begin(), k.end(), marked.begin(), marked.end(), std::back_inserter(kept));
                    k = std::move(kept);
                }
                const size_t floats = size_t(channels) * planeOf(t), at = samples[size_t(t)].size();
                samples[size_t(t)].resize(at + k.size() * floats);
                parallelFor(k.size(), 4, threads, [&](size_t b, size_t e, unsigned worker) {
                    for (size_t i = b; i < e; ++i)
                        detail::buildTile(r.grid, index, params, t, side, k[i], channels, depthLayer, &samples[size_t(t)][at + i * floats],
                                          scratch[worker], -1);
                });
                keys[size_t(t)].insert(keys[size_t(t)].end(), k.begin(), k.end());
                s.tiles += k.size();
            }
            s.nodes += 1, s.cells += r.hi - r.lo, s.cellsRead += r.grid.cellCount();
            bar.advance(1);
        }
        bar.finish();
    }

    // The coarse tiles: kept where some node keeps them (and, for water, some wet cell marks them), then shared out one by
    // one; each of their blocks is sampled from a region read around the block.
    struct CoarseTile {
        int t;
        uint64_t key;
    };
    std::vector<CoarseTile> coarse;
    for (int t = 0; t <= top; ++t) {
        if (nodeLevelOf(t) <= part.level) continue;
        auto unite = [](const std::vector<uint64_t>& v) {
            std::vector<uint64_t> all;
            for (const auto& from : ranks::allGatherVectors(v)) all.insert(all.end(), from.begin(), from.end());
            std::sort(all.begin(), all.end());
            all.erase(std::unique(all.begin(), all.end()), all.end());
            return all;
        };
        std::vector<uint64_t> kept = unite(coarseKept[size_t(t)]);
        std::erase_if(kept, [&](uint64_t key) { return file.cellsInNode(key, nodeLevelOf(t)) == 0; });  // all NaN there
        if (waterOnly) {
            const std::vector<uint64_t> marked = unite(coarseMarked[size_t(t)]);
            std::vector<uint64_t> both;
            std::set_intersection(kept.begin(), kept.end(), marked.begin(), marked.end(), std::back_inserter(both));
            kept = std::move(both);
        }
        for (uint64_t key : kept) coarse.push_back({t, key});
    }
    {
        std::vector<CoarseTile> ours;
        for (size_t i = 0; i < coarse.size(); ++i)
            if (int(i % size_t(count)) == rank) ours.push_back(coarse[i]);
        struct Job {
            size_t tile;
            int block;
        };
        std::vector<Job> jobs;
        std::vector<size_t> at(ours.size());
        for (size_t i = 0; i < ours.size(); ++i) {
            const int t = ours[i].t, block = detail::pyramidBlockSide(shape, params, t), blocks = (sides[size_t(t)] + block - 1) / block;
            at[i] = samples[size_t(t)].size();
            samples[size_t(t)].resize(at[i] + size_t(channels) * planeOf(t));
            keys[size_t(t)].push_back(ours[i].key);
            for (int b = 0; b < blocks * blocks; ++b) jobs.push_back({i, b});
        }
        s.tiles += ours.size();
        std::vector<uint64_t> readPerWorker(threads, 0);
        std::vector<detail::PyramidWorkspace> scratch(threads);
        parallelFor(jobs.size(), 1, threads, [&](size_t b, size_t e, unsigned worker) {
            for (size_t q = b; q < e; ++q) {
                const CoarseTile& c = ours[jobs[q].tile];
                const int side = sides[size_t(c.t)], block = detail::pyramidBlockSide(shape, params, c.t), blocks = (side + block - 1) / block;
                const int bi = (jobs[q].block % blocks) * block, bj = (jobs[q].block / blocks) * block;
                const int bi1 = std::min(side, bi + block), bj1 = std::min(side, bj + block);
                const double h = shape.levelSizeM(c.t);
                const double x0 = double(mortonX(c.key)) * shape.finestCellM, y0 = double(mortonY(c.key)) * shape.finestCellM;
                const Grid::Square box{x0 + bi * h, y0 + bj * h, x0 + (bi1 - 1) * h, y0 + (bj1 - 1) * h};
                const Grid region = file.region(box, reach);
                readPerWorker[worker] += region.cellCount();
                const detail::ListIndex index(region, params);
                detail::buildTile(region, index, params, c.t, side, c.key, channels, depthLayer, &samples[size_t(c.t)][at[jobs[q].tile]],
                                  scratch[worker], jobs[q].block);
            }
        });
        for (uint64_t n : readPerWorker) s.cellsRead += n;
    }
    s.seconds = clock.seconds();
    if (share) *share = s;

    if (rank != 0) {
        for (int t = 0; t <= top; ++t) {
            ranks::sendToRoot(keys[size_t(t)]);
            ranks::sendToRoot(samples[size_t(t)]);
        }
        return {};
    }
    // Rank 0: every rank's tiles of each level, in key order.
    SurfacePyramid p;
    p.finestCellM = shape.finestCellM;
    p.rootLevel = shape.rootLevel;
    p.params = params;
    p.structureHash = file.info().structureHash;
    p.contentHash = file.info().contentHash;
    p.channels = channels;
    auto owned = std::make_shared<SurfacePyramid::Storage>();
    owned->keys.resize(size_t(top) + 1);
    owned->samples.resize(size_t(top) + 1);
    for (int t = 0; t <= top; ++t) {
        const size_t floats = size_t(channels) * planeOf(t);
        std::vector<std::vector<uint64_t>> k{std::move(keys[size_t(t)])};
        std::vector<std::vector<float>> v{std::move(samples[size_t(t)])};
        for (int r = 1; r < count; ++r) {
            k.push_back(ranks::receiveVectorFrom<uint64_t>(r));
            v.push_back(ranks::receiveVectorFrom<float>(r));
            if (v.back().size() != k.back().size() * floats)
                throw Error("rank " + std::to_string(r + 1) + " sent " + std::to_string(v.back().size()) + " samples for " +
                            std::to_string(k.back().size()) + " tiles of level " + std::to_string(t));
        }
        std::vector<std::pair<uint64_t, std::pair<size_t, size_t>>> order;  // key, (rank, tile)
        for (size_t r = 0; r < k.size(); ++r)
            for (size_t i = 0; i < k[r].size(); ++i) order.push_back({k[r][i], {r, i}});
        std::sort(order.begin(), order.end());
        for (size_t i = 1; i < order.size(); ++i)
            if (order[i].first == order[i - 1].first) throw Error("two ranks sampled the same pyramid tile of level " + std::to_string(t));
        auto& outKeys = owned->keys[size_t(t)];
        auto& outSamples = owned->samples[size_t(t)];
        outSamples.resize(order.size() * floats);
        for (size_t i = 0; i < order.size(); ++i) {
            outKeys.push_back(order[i].first);
            const auto [r, tile] = order[i].second;
            std::copy_n(v[r].begin() + ptrdiff_t(tile * floats), floats, outSamples.begin() + ptrdiff_t(i * floats));
        }
    }
    const SurfacePyramid done = detail::finishPyramid(std::move(p), std::move(owned), sides, threads);
    return waterOnly ? waterPyramidOf(done) : done;
}

}  // namespace hc::influence
