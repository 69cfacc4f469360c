// The lists and the pyramid on the ranks of mpirun (on_ranks.h): each rank its share, rank 0 all of it.
#include "heightcast/influence/on_ranks.h"

#include <algorithm>

#include "heightcast/core/error.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/ranks.h"
#include "heightcast/core/timer.h"
#include "list_index.h"
#include "pyramid_build.h"
#include "pyramid_storage.h"

namespace hc::influence {

std::vector<size_t> rankCellCuts(const Grid& g, int ranks) {
    const size_t n = g.cellCount();
    const uint64_t nodeMask = ~(mortonSpan(std::clamp(g.maxLevel, 0, g.rootLevel)) - 1);
    std::vector<size_t> cuts(size_t(ranks) + 1, n);
    cuts[0] = 0;
    for (int r = 1; r < ranks; ++r) {
        size_t i = std::max<size_t>(cuts[size_t(r) - 1], size_t(ranks::shareBegin(n, r, ranks)));
        // Forward to the first cell of a coarsest-level node.
        while (i > 0 && i < n && (codeKey(g.codes[i]) & nodeMask) == (codeKey(g.codes[i - 1]) & nodeMask)) ++i;
        cuts[size_t(r)] = i;
    }
    return cuts;
}

namespace {

// The rank whose share holds cell i.
int rankOfCell(const std::vector<size_t>& cuts, size_t i) { return int(std::upper_bound(cuts.begin(), cuts.end(), i) - cuts.begin()) - 1; }

// The rank that samples the pyramid tile with corner key `key`: the owner of its first cell (a kept tile's node holds a cell).
int rankOfTile(const Grid& g, const std::vector<size_t>& cuts, uint64_t key) {
    const size_t i = size_t(std::lower_bound(g.codes.begin(), g.codes.end(), makeCellCode(key, 0)) - g.codes.begin());
    return rankOfCell(cuts, std::min(i, g.cellCount() ? g.cellCount() - 1 : 0));
}

}  // namespace

InfluenceLists buildInfluenceListsOnRanks(const Grid& g, const KernelParams& params, unsigned threads, bool progress, RankShare* share) {
    const int rank = ranks::rank(), count = ranks::count();
    if (count == 1) {
        const Stopwatch clock;
        InfluenceLists lists = buildInfluenceLists(g, params, threads, progress);
        if (share) *share = {g.cellCount(), 0, clock.seconds()};
        return lists;
    }
    detail::checkListInputs(g, params);
    const Stopwatch clock;
    const std::vector<size_t> cuts = rankCellCuts(g, count);
    const auto superBlocks = detail::splitNodes(g, {0, g.rootLevel, 0, g.cellCount()}, detail::kSuperBlockCells);
    // A super-block is built whole by the rank of its first cell.
    auto firstBlock = [&](int r) {
        return size_t(std::lower_bound(superBlocks.begin(), superBlocks.end(), cuts[size_t(r)],
                                       [](const detail::NodeRange& b, size_t c) { return b.lo < c; }) - superBlocks.begin());
    };
    const size_t s0 = firstBlock(rank), s1 = rank + 1 == count ? superBlocks.size() : firstBlock(rank + 1);
    detail::ListPart part;
    {
        const detail::ListIndex index(g, params);
        Progress bar("influence lists", s0 < s1 ? superBlocks[s1 - 1].hi - superBlocks[s0].lo : 0, progress && rank == 0);
        part = detail::buildListPart(index, superBlocks, s0, s1, threads, bar);
        bar.finish();
    }
    const size_t myCells = part.offsets.size() - 1;
    if (share) *share = {myCells, 0, clock.seconds()};
    if (rank != 0) {
        // Lengths (4 bytes a cell, not the 8 of an offset), then the entries.
        std::vector<uint32_t> lengths(myCells);
        for (size_t k = 0; k < myCells; ++k) lengths[k] = uint32_t(part.offsets[k + 1] - part.offsets[k]);
        ranks::sendToRoot(lengths);
        ranks::sendToRoot(std::as_bytes(std::span<const uint32_t>(part.indices.get(), part.entries)));
        return {};
    }
    // Rank 0: its own part first (the lowest cells), then every other rank's, in order.
    const size_t n = g.cellCount();
    std::vector<uint64_t> offsets = std::move(part.offsets);
    offsets.resize(n + 1);
    size_t used = part.entries, capacity = used;
    std::unique_ptr<uint32_t[]> indices = std::move(part.indices);
    size_t cell = myCells;
    for (int r = 1; r < count; ++r) {
        const std::vector<uint32_t> lengths = ranks::receiveVectorFrom<uint32_t>(r);
        const std::vector<uint32_t> entries = ranks::receiveVectorFrom<uint32_t>(r);
        if (cell + lengths.size() > n) throw Error("rank " + std::to_string(r + 1) + " sent lists of more cells than the grid has");
        uint64_t sum = 0;
        for (size_t k = 0; k < lengths.size(); ++k) {
            offsets[cell + k + 1] = offsets[cell + k] + lengths[k];
            sum += lengths[k];
        }
        if (sum != entries.size()) throw Error("rank " + std::to_string(r + 1) + " sent list lengths that do not add up to its entries");
        if (used + entries.size() > capacity) {
            capacity = std::max(used + entries.size(), capacity + capacity / 2);
            auto bigger = std::unique_ptr<uint32_t[]>(new uint32_t[capacity]);
            std::copy(indices.get(), indices.get() + used, bigger.get());
            indices = std::move(bigger);
        }
        std::copy(entries.begin(), entries.end(), indices.get() + used);
        used += entries.size();
        cell += lengths.size();
    }
    if (cell != n) throw Error("the ranks sent lists of " + std::to_string(cell) + " cells, not " + std::to_string(n));
    return InfluenceLists(params, g.structureHash(), g.contentHash(), std::move(offsets), std::move(indices), used);
}

SurfacePyramid buildPyramidOnRanks(const Grid& g, const KernelParams& params, unsigned threads, bool progress, bool waterOnly,
                                   RankShare* share) {
    const int rank = ranks::rank(), count = ranks::count();
    const Stopwatch clock;
    if (count == 1) {
        SurfacePyramid p = waterOnly ? buildWaterPyramid(g, params, threads, progress) : buildSurfacePyramid(g, params, threads, progress);
        if (share) {
            share->tiles = 0;
            for (const auto& L : p.levels) share->tiles += L.tileCount();
            share->cells = g.cellCount(), share->seconds = clock.seconds();
        }
        return p;
    }
    if (waterOnly && g.findLayer("water_depth") < 0) throw Error("a water pyramid is built for a grid with water");
    const std::vector<size_t> cuts = rankCellCuts(g, count);
    const detail::TileFilter mine = [&](int, uint64_t key) { return rankOfTile(g, cuts, key) == rank; };
    SurfacePyramid p = detail::samplePyramid(g, params, threads, progress && rank == 0, waterOnly, &mine);
    auto& storage = const_cast<SurfacePyramid::Storage&>(*p.storage);  // samplePyramid's own vectors
    const size_t channels = size_t(p.channels);
    uint64_t myTiles = 0;
    for (const auto& L : p.levels)
        for (uint64_t key : L.keys) myTiles += rankOfTile(g, cuts, key) == rank;
    if (share) *share = {cuts[size_t(rank) + 1] - cuts[size_t(rank)], myTiles, clock.seconds()};
    if (rank != 0) {
        // Per level, the samples of this rank's tiles in key order (rank 0 knows which tiles they are).
        for (size_t t = 0; t < p.levels.size(); ++t) {
            const auto& L = p.levels[t];
            const size_t tileFloats = channels * size_t(L.tileSide) * size_t(L.tileSide);
            std::vector<float> out;
            for (size_t tile = 0; tile < L.tileCount(); ++tile)
                if (rankOfTile(g, cuts, L.keys[tile]) == rank)
                    out.insert(out.end(), L.samples.begin() + ptrdiff_t(tile * tileFloats), L.samples.begin() + ptrdiff_t((tile + 1) * tileFloats));
            ranks::sendToRoot(out);
        }
        return {};
    }
    for (int r = 1; r < count; ++r)
        for (size_t t = 0; t < p.levels.size(); ++t) {
            const auto& L = p.levels[t];
            const size_t tileFloats = channels * size_t(L.tileSide) * size_t(L.tileSide);
            const std::vector<float> in = ranks::receiveVectorFrom<float>(r);
            size_t at = 0;
            for (size_t tile = 0; tile < L.tileCount(); ++tile) {
                if (rankOfTile(g, cuts, L.keys[tile]) != r) continue;
                if (at + tileFloats > in.size()) throw Error("rank " + std::to_string(r + 1) + " sent fewer pyramid samples than its tiles hold");
                std::copy(in.begin() + ptrdiff_t(at), in.begin() + ptrdiff_t(at + tileFloats), storage.samples[t].begin() + ptrdiff_t(tile * tileFloats));
                at += tileFloats;
            }
            if (at != in.size()) throw Error("rank " + std::to_string(r + 1) + " sent more pyramid samples than its tiles hold");
        }
    detail::measureParentErrors(p, threads);
    return waterOnly ? waterPyramidOf(p) : p;
}

}  // namespace hc::influence
