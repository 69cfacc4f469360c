// The lists on the ranks of mpirun (on_ranks.h), and the parts the pyramid's build shares with them
// (on_ranks_parts.h): each rank its nodes, each node from a region of the grid file around it; each rank writes its
// lists at their place in the file rank 0 opens. The pyramid: pyramid_on_ranks.cpp.
#include "heightcast/influence/on_ranks.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <limits>
#include <memory>
#include <numeric>

#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/ranks.h"
#include "heightcast/core/timer.h"
#include "heightcast/influence/region.h"
#include "file_layouts.h"
#include "list_index.h"
#include "on_ranks_parts.h"

namespace hc::influence {

namespace {

constexpr int kNodesPerRank = 16;                      // enough nodes to balance cell counts between ranks
constexpr int kMaxPartitionDepth = 6;                  // at most 4^6 nodes looked at
constexpr uint64_t kMaxNodeCells = uint64_t{1} << 22;  // a node's cells, read at once: its region's memory

}  // namespace

namespace detail {

Grid::Square nodeSquare(const Grid& shape, uint64_t key, int level) {
    const double x0 = double(mortonX(key)) * shape.finestCellM, y0 = double(mortonY(key)) * shape.finestCellM;
    const double side = shape.levelSizeM(level);
    return {x0, y0, x0 + side, y0 + side};
}

IndexedRegion readIndexed(const GridRegionReader& file, const Grid::Square& box, const std::vector<double>& margins,
                          uint64_t key, int level, bool wantIndex) {
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

namespace {

// Hands `put` run r's bytes with their place in the section: at once, or from a spill 64 MiB at a time, each chunk's
// pages released after it.
template <class Put>
void inChunks(const Run& r, Put&& put) {
    constexpr size_t kChunk = size_t{64} << 20;
    if (!r.spill) return put(r.at, r.bytes);
    for (size_t o = 0; o < r.bytes.size(); o += kChunk) {
        const std::span<const std::byte> chunk = r.bytes.subspan(o, std::min(kChunk, r.bytes.size() - o));
        put(r.at + o, chunk);
        r.spill->release(chunk);
    }
}

}  // namespace

void writeByParts(const std::string& path, const FileFormat& format, std::vector<FileSection> layout,
                  const std::vector<Run>& runs, std::vector<std::byte> header) {
    const int rank = ranks::rank(), count = ranks::count();
    std::unique_ptr<SectionedFileWriter> out;
    std::vector<std::byte> where;
    ranks::together([&] {
        if (rank != 0) return;
        out = std::make_unique<SectionedFileWriter>(path, format, std::move(layout));
        if (count > 1) where = out->placement().encode();
    });
    if (count > 1) where = std::move(ranks::allGather(where)[0]);
    std::vector<FilePiece> pieces;
    ranks::together([&] {
        if (rank == 0) {
            for (const Run& r : runs)
                inChunks(r, [&](uint64_t, std::span<const std::byte> b) { out->append(r.section, b); });
            return;
        }
        SectionedFilePart mine(FilePlacement::decode(where));
        for (const Run& r : runs)
            inChunks(r, [&](uint64_t at, std::span<const std::byte> b) { mine.writeAt(r.section, at, b); });
        pieces = mine.finish();
    });
    ranks::together([&] {
        if (rank != 0) {
            ranks::sendToRoot(pieces);
            return;
        }
        std::vector<std::vector<FilePiece>> all;
        for (int r = 1; r < count; ++r) all.push_back(ranks::receiveVectorFrom<FilePiece>(r));
        for (const auto& from : all) out->addPieces(from);
        out->commit(std::move(header));
    });
}

}  // namespace detail

using namespace detail;

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
        const uint64_t largest = p.cells.empty() ? 0 : *std::max_element(p.cells.begin(), p.cells.end());
        if ((p.keys.size() >= size_t(kNodesPerRank) * size_t(ranks) && largest <= kMaxNodeCells) || level <= lowest ||
            root - level >= kMaxPartitionDepth)
            break;
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

InfluenceListsPart buildInfluenceListsOnRanks(const GridRegionReader& file, const KernelParams& params,
                                              unsigned threads, bool progress, RankShare* share) {
    if (std::string why = params.validate(); !why.empty()) throw Error("influence parameters: " + why);
    if (file.cellCount() >= std::numeric_limits<uint32_t>::max())
        throw Error("grid has too many cells for 32-bit influence indices");
    const Stopwatch clock;
    const int rank = ranks::rank(), count = ranks::count();
    const RankPartition part = partitionOf(file, count);
    const std::vector<double> margins = kernelReachM(file.shape(), params);
    const std::vector<size_t> mine = myNodes(part);
    RankShare s;
    uint64_t myCells = 0;
    for (size_t j : mine) myCells += part.cells[j];
    std::vector<uint32_t> lengths;
    std::vector<InfluenceListsPart::Entries> entries;
    uint64_t entryCount = 0;
    ranks::together([&] {
        Progress bar("influence lists", myCells, progress && rank == 0);
        for (size_t j : mine) {
            const IndexedRegion r = readIndexed(file, nodeSquare(file.shape(), part.keys[j], part.level), margins,
                                                part.keys[j], part.level, true);
            const detail::ListIndex index(r.grid, params);
            const auto blocks =
                detail::splitNodes(r.grid, {part.keys[j], part.level, r.lo, r.hi}, detail::kSuperBlockCells);
            detail::ListPart lists = detail::buildListPart(index, blocks, 0, blocks.size(), threads, bar);
            for (size_t k = 0; k + 1 < lists.offsets.size(); ++k)
                lengths.push_back(uint32_t(lists.offsets[k + 1] - lists.offsets[k]));
            for (size_t e = 0; e < lists.entries; ++e)
                lists.indices[e] = r.fileIndex[lists.indices[e]];  // region -> file index
            entryCount += lists.entries;
            entries.push_back({std::move(lists.indices), lists.entries});
            s.nodes += 1, s.cells += r.hi - r.lo, s.cellsRead += r.grid.cellCount();
        }
        bar.finish();
    });
    s.seconds = clock.seconds();
    if (share) *share = s;
    // Every rank's cell and entry counts (a small table): where this rank's run of cells and entries starts.
    const auto counts = ranks::allGatherVectors(std::vector<uint64_t>{lengths.size(), entryCount});
    InfluenceListsPart out;
    out.params = params;
    out.structureHash = file.info().structureHash;
    out.contentHash = file.info().contentHash;
    uint64_t firstEntry = 0;
    for (int r = 0; r < count; ++r) {
        out.totalCells += counts[size_t(r)][0], out.totalEntries += counts[size_t(r)][1];
        if (r < rank) out.firstCell += counts[size_t(r)][0], firstEntry += counts[size_t(r)][1];
    }
    if (out.totalCells != file.cellCount())
        throw Error("the ranks built lists of " + std::to_string(out.totalCells) + " cells, not " +
                    std::to_string(file.cellCount()));
    out.offsets.resize(lengths.size() + 1);
    out.offsets[0] = firstEntry;
    for (size_t k = 0; k < lengths.size(); ++k) out.offsets[k + 1] = out.offsets[k] + lengths[k];
    out.entries = std::move(entries);
    return out;
}

InfluenceLists::Stats writeInfluenceCacheOnRanks(const InfluenceListsPart& part, const std::string& path) {
    // The whole lists' lengths as one histogram (every rank's added up), for the longest list (in the header) and the
    // summary's percentile: the same figures as InfluenceLists::stats() of the whole.
    std::vector<uint64_t> histogram;
    for (size_t k = 0; k < part.cellCount(); ++k) {
        const uint64_t length = part.offsets[k + 1] - part.offsets[k];
        if (length >= histogram.size()) histogram.resize(length + 1, 0);
        ++histogram[length];
    }
    std::vector<uint64_t> whole;
    for (const auto& from : ranks::allGatherVectors(histogram)) {
        if (from.size() > whole.size()) whole.resize(from.size(), 0);
        for (size_t l = 0; l < from.size(); ++l) whole[l] += from[l];
    }
    InfluenceLists::Stats stats;
    const uint64_t n = part.totalCells, m = part.totalEntries;
    stats.bytes = (n + 1) * 8 + m * 4;
    if (n > 0) {
        stats.meanLength = double(m) / double(n);
        stats.maxLength = whole.size() - 1;
        const uint64_t at =
            std::min(n - 1, n * 99 / 100);  // the element nth_element puts there (InfluenceLists::stats)
        uint64_t seen = 0;
        for (size_t l = 0; l < whole.size(); ++l)
            if ((seen += whole[l]) > at) {
                stats.p99Length = l;
                break;
            }
    }
    std::vector<Run> runs;
    if (ranks::rank() == 0) {
        runs.push_back({0, 0, std::as_bytes(std::span(part.offsets))});
    } else if (part.cellCount() > 0) {
        runs.push_back({0, (part.firstCell + 1) * 8, std::as_bytes(std::span(part.offsets).subspan(1))});
    }
    uint64_t at = part.offsets.empty() ? 0 : part.offsets.front();
    for (const InfluenceListsPart::Entries& e : part.entries) {
        if (e.count == 0) continue;
        runs.push_back({1, at * 4, std::as_bytes(std::span<const uint32_t>(e.indices.get(), e.count))});
        at += e.count;
    }
    writeByParts(
        path, detail::influenceCacheFormat(), detail::influenceCacheLayout(n, m), runs,
        detail::influenceCacheHeader(n, m, stats.maxLength, part.params, part.structureHash, part.contentHash));
    return stats;
}

}  // namespace hc::influence
