// The lists and the pyramid on the ranks of mpirun (on_ranks.h): each rank its nodes, each node from a region of the
// grid file around it; each rank writes its lists and tiles at their place in the files rank 0 opens.
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
#include "pyramid_build.h"
#include "pyramid_storage.h"

namespace hc::influence {

namespace {

constexpr int kNodesPerRank = 16;                      // enough nodes to balance cell counts between ranks
constexpr int kMaxPartitionDepth = 6;                  // at most 4^6 nodes looked at
constexpr uint64_t kMaxNodeCells = uint64_t{1} << 22;  // a node's cells, read at once: its region's memory

// Keeps the grid file's pages that many small regions touch from piling up in resident memory: they are released
// (GridRegionReader::releasePages) every 32 regions, and sooner once the regions read since the last release hold about
// 64 MB of the file (their cells at 8 bytes of code and 4 of each value, and the blocks their reads checksummed, a
// block whole). A region's binary searches touch pages beyond its cells: without this, the coarse tiles' many small
// regions left far more of the file resident than the cells they read. Any thread may call after(); a region read
// meanwhile reads its pages back from the page cache.
class PageReleaser {
public:
    explicit PageReleaser(const GridRegionReader& file) : file_(file), checkedAt_(file.bytesChecked()) {}
    void after(const Grid& region) {
        const uint64_t bytes = region.cellCount() * (8 + 4 * uint64_t(std::max<size_t>(1, region.values.size())));
        const uint64_t touched = touched_.fetch_add(bytes) + bytes;
        const uint64_t checked = file_.bytesChecked();
        if (++regions_ % kRegions != 0 && touched + (checked - std::min(checked, checkedAt_.load())) < kBytes)
            return;  // min: a race
        touched_ = 0, checkedAt_ = checked;
        file_.releasePages();
    }

private:
    static constexpr uint64_t kBytes = uint64_t{64} << 20, kRegions = 32;
    const GridRegionReader& file_;
    std::atomic<uint64_t> touched_{0}, checkedAt_, regions_{0};
};

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

// A run of bytes a rank writes: bytes [at, at + bytes.size()) of section `section` of a placed layout.
struct Run {
    size_t section;
    uint64_t at;
    std::span<const std::byte> bytes;
};

// Collective: writes the file at `path` whose sections (`layout`, of `format`) the ranks' runs fill, each rank's runs
// in order, the ranks' runs of a section in rank order and rank 0's first: rank 0 places the sections in its temporary
// and appends its runs, the others write theirs into that temporary in place (SectionedFilePart: a file system every
// rank sees), then rank 0 takes their pieces' CRCs in rank order, as if it had appended their bytes, and commits with
// `header` (rank 0's). A failure on any rank stops every rank at the next step and leaves no file (rank 0's writer
// removes its temporary).
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
            for (const Run& r : runs) out->append(r.section, r.bytes);
            return;
        }
        SectionedFilePart mine(FilePlacement::decode(where));
        for (const Run& r : runs) mine.writeAt(r.section, r.at, r.bytes);
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

// Empties the levels whose tiles are larger than a node of partition level `level` (rank 0 writes those).
void dropCoarseLevels(SurfacePyramid& p, int level) {
    for (SurfacePyramid::Level& L : p.levels)
        if (L.level + std::countr_zero(unsigned(L.tileSide)) > level) L.keys = {}, L.samples = {}, L.parentErrorM = {};
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

SurfacePyramid buildPyramidOnRanks(const GridRegionReader& file, const KernelParams& params, unsigned threads,
                                   bool progress, bool waterOnly, RankShare* share) {
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
    // Margins: every cell whose kernel reaches the node; for a water pyramid also those one tile further (the tiles a
    // wet cell marks are grown by one: wetMarkedTiles), a tile of a level inside the node being at most the node's
    // side.
    std::vector<double> margins = kernelReachM(shape, params);
    if (waterOnly)
        for (double& m : margins) m += shape.levelSizeM(part.level);
    const std::vector<double> reach = kernelReachM(shape, params);
    int lastInside = -1;  // the levels whose tiles lie inside a partition node: 0..lastInside
    while (lastInside < top && nodeLevelOf(lastInside + 1) <= part.level) ++lastInside;

    RankShare s;
    // What this rank sends: per level, its tiles' keys and samples.
    std::vector<std::vector<uint64_t>> keys(size_t(top) + 1);
    std::vector<std::vector<float>> samples(size_t(top) + 1);
    // Coarse levels (tiles larger than a node): the tiles this rank's nodes keep, and (water) mark.
    std::vector<std::vector<uint64_t>> coarseKept(size_t(top) + 1), coarseMarked(size_t(top) + 1);
    const std::vector<size_t> mine = myNodes(part);
    ranks::together([&] {
        Progress bar("surface pyramid", mine.size(), progress && rank == 0);
        std::vector<detail::PyramidWorkspace> scratch(threads);
        for (size_t j : mine) {
            const uint64_t nodeKey = part.keys[j];
            const IndexedRegion r =
                readIndexed(file, nodeSquare(shape, nodeKey, part.level), margins, nodeKey, part.level, false);
            const detail::ListIndex index(r.grid, params);
            // Every level's tile keys at once: inside the node from every cell read (the node's and its margin's),
            // above it from the node's own cells.
            std::vector<std::vector<uint64_t>> levelKeys(size_t(top) + 1);
            detail::tileKeysOnThreads(r.grid, params, 0, r.grid.cellCount(), 0, lastInside, top, sides, threads,
                                      levelKeys);
            detail::tileKeysOnThreads(r.grid, params, r.lo, r.hi, lastInside + 1, top, top, sides, threads, levelKeys);
            for (int t = 0; t <= top; ++t) {
                const int side = sides[size_t(t)];
                std::vector<uint64_t> k = std::move(levelKeys[size_t(t)]);
                if (t > lastInside) {  // a coarse tile: decided once every node has spoken for its own cells
                    coarseKept[size_t(t)].insert(coarseKept[size_t(t)].end(), k.begin(), k.end());
                    if (waterOnly)
                        detail::wetMarkedTiles(r.grid, params, depthLayer, r.lo, r.hi, t, side,
                                               coarseMarked[size_t(t)]);
                    continue;
                }
                // A tile inside the node: kept by a cell of the node or of its margin, whose kernel may reach into it.
                const uint64_t nodeMask = ~(mortonSpan(part.level) - 1);
                std::erase_if(k, [&](uint64_t key) { return (key & nodeMask) != nodeKey; });
                std::sort(k.begin(), k.end());
                k.erase(std::unique(k.begin(), k.end()), k.end());
                std::erase_if(
                    k, [&](uint64_t key) { return file.cellsInNode(key, nodeLevelOf(t)) == 0; });  // all NaN there
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
                        detail::buildTile(r.grid, index, params, t, side, k[i], channels, depthLayer,
                                          &samples[size_t(t)][at + i * floats], scratch[worker], -1);
                });
                keys[size_t(t)].insert(keys[size_t(t)].end(), k.begin(), k.end());
                s.tiles += k.size();
            }
            s.nodes += 1, s.cells += r.hi - r.lo, s.cellsRead += r.grid.cellCount();
            file.releasePages();  // the node's cells were copied out: the file's pages need not stay resident
            bar.advance(1);
        }
        bar.finish();
    });

    // The coarse tiles: kept where some node keeps them (and, for water, some wet cell marks them), then shared out one
    // by one; each of their blocks is sampled from a region read around the block.
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
    ranks::together([&] {
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
            const int t = ours[i].t, block = detail::pyramidBlockSide(shape, params, t),
                      blocks = (sides[size_t(t)] + block - 1) / block;
            at[i] = samples[size_t(t)].size();
            samples[size_t(t)].resize(at[i] + size_t(channels) * planeOf(t));
            keys[size_t(t)].push_back(ours[i].key);
            for (int b = 0; b < blocks * blocks; ++b) jobs.push_back({i, b});
        }
        s.tiles += ours.size();
        std::vector<uint64_t> readPerWorker(threads, 0);
        std::vector<detail::PyramidWorkspace> scratch(threads);
        PageReleaser release(file);
        parallelFor(jobs.size(), 1, threads, [&](size_t b, size_t e, unsigned worker) {
            for (size_t q = b; q < e; ++q) {
                const CoarseTile& c = ours[jobs[q].tile];
                const int side = sides[size_t(c.t)], block = detail::pyramidBlockSide(shape, params, c.t),
                          blocks = (side + block - 1) / block;
                const int bi = (jobs[q].block % blocks) * block, bj = (jobs[q].block / blocks) * block;
                const int bi1 = std::min(side, bi + block), bj1 = std::min(side, bj + block);
                const double h = shape.levelSizeM(c.t);
                const double x0 = double(mortonX(c.key)) * shape.finestCellM,
                             y0 = double(mortonY(c.key)) * shape.finestCellM;
                const Grid::Square box{x0 + bi * h, y0 + bj * h, x0 + (bi1 - 1) * h, y0 + (bj1 - 1) * h};
                const Grid region = file.region(box, reach);
                readPerWorker[worker] += region.cellCount();
                release.after(region);
                const detail::ListIndex index(region, params);
                detail::buildTile(region, index, params, c.t, side, c.key, channels, depthLayer,
                                  &samples[size_t(c.t)][at[jobs[q].tile]], scratch[worker], jobs[q].block);
            }
        });
        for (uint64_t n : readPerWorker) s.cellsRead += n;
    });

    // Every rank gets every tile of the coarse levels (a few thousand at most: one per node of a level coarser than the
    // partition's), for the parent errors of its own tiles and, on rank 0, to write.
    auto owned = std::make_shared<SurfacePyramid::Storage>();
    owned->keys.resize(size_t(top) + 1);
    owned->samples.resize(size_t(top) + 1);
    for (int t = 0; t <= top; ++t) {
        if (nodeLevelOf(t) <= part.level) {
            owned->keys[size_t(t)] = std::move(keys[size_t(t)]);
            owned->samples[size_t(t)] = std::move(samples[size_t(t)]);
            continue;
        }
        const size_t floats = size_t(channels) * planeOf(t);
        const auto k = ranks::allGatherVectors(keys[size_t(t)]);
        const auto v = ranks::allGatherVectors(samples[size_t(t)]);
        std::vector<std::pair<uint64_t, std::pair<size_t, size_t>>> order;  // key, (rank, tile)
        for (size_t r = 0; r < k.size(); ++r)
            for (size_t i = 0; i < k[r].size(); ++i) order.push_back({k[r][i], {r, i}});
        std::sort(order.begin(), order.end());
        for (size_t i = 1; i < order.size(); ++i)
            if (order[i].first == order[i - 1].first)
                throw Error("two ranks sampled the same pyramid tile of level " + std::to_string(t));
        auto& outKeys = owned->keys[size_t(t)];
        auto& outSamples = owned->samples[size_t(t)];
        outSamples.resize(order.size() * floats);
        for (size_t i = 0; i < order.size(); ++i) {
            outKeys.push_back(order[i].first);
            const auto [r, tile] = order[i].second;
            std::copy_n(v[r].begin() + ptrdiff_t(tile * floats), floats, outSamples.begin() + ptrdiff_t(i * floats));
        }
    }
    const SurfacePyramid halo = haloOf(part, shape, *owned, sides, channels);
    s.seconds = clock.seconds();
    if (share) *share = s;

    SurfacePyramid p;
    p.finestCellM = shape.finestCellM;
    p.rootLevel = shape.rootLevel;
    p.params = params;
    p.structureHash = file.info().structureHash;
    p.contentHash = file.info().contentHash;
    p.channels = channels;
    SurfacePyramid done = detail::finishPyramid(std::move(p), std::move(owned), sides, threads, &halo);
    if (rank != 0) dropCoarseLevels(done, part.level);  // rank 0 writes them
    return waterOnly ? waterPyramidOf(done) : done;
}

void writePyramidOnRanks(const SurfacePyramid& part, const std::string& path) {
    const int rank = ranks::rank(), count = ranks::count();
    const size_t levels = part.levels.size();
    std::vector<uint64_t> tiles(levels);
    std::vector<int> sides(levels);
    for (size_t t = 0; t < levels; ++t) tiles[t] = part.levels[t].tileCount(), sides[t] = part.levels[t].tileSide;
    // Every rank's tiles per level: where each rank's run of each section starts (rank 0's first; ranks in Morton
    // order).
    const auto perRank = ranks::allGatherVectors(tiles);
    std::vector<uint64_t> total(levels, 0), before(levels, 0);
    for (int r = 0; r < count; ++r)
        for (size_t t = 0; t < levels; ++t) {
            if (perRank[size_t(r)].size() != levels)
                throw Error("rank " + std::to_string(r + 1) + " holds a pyramid of another height");
            total[t] += perRank[size_t(r)][t];
            if (r < rank) before[t] += perRank[size_t(r)][t];
        }
    std::vector<Run> runs;
    for (size_t t = 0; t < levels; ++t) {
        const SurfacePyramid::Level& L = part.levels[t];
        if (L.tileCount() == 0) continue;
        const uint64_t ch = uint64_t(part.channels), plane = uint64_t(L.tileSide) * uint64_t(L.tileSide);
        runs.push_back({3 * t, before[t] * 8, std::as_bytes(L.keys)});
        runs.push_back({3 * t + 1, before[t] * ch * 4, std::as_bytes(L.parentErrorM)});
        runs.push_back({3 * t + 2, before[t] * ch * plane * 4, std::as_bytes(L.samples)});
    }
    writeByParts(path, detail::pyramidFileFormat(), detail::pyramidFileLayout(total, sides, part.channels), runs,
                 detail::pyramidFileHeader(part));
}

}  // namespace hc::influence
