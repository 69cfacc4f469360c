// heightcast/influence/on_ranks.h: the influence lists and the surface pyramid built by the ranks of
// `mpirun -np N hc-influence` (docs/design.md section 7; core/ranks/ranks.h), the same bytes as one process builds.
//
// No rank reads the whole grid. The domain is cut into the nodes of one quadtree level (partitionOf: the coarsest
// level with enough nodes holding cells, never finer than the coarsest cell or a pyramid tile's node), and the nodes,
// in Morton order, into N runs of about equal cell count. For each of its nodes a rank reads from the grid file the
// cells of the node and its halo (every cell whose kernel reaches the node: R sigma c around it, region.h), builds
// the lists of the node's cells and the pyramid tiles inside the node, then drops the region. Tiles larger than a
// node (the few coarsest levels) are shared out one by one, each block of 4 x 4 samples from a region read around it.
// Every list and sample is then the same bits as from the whole grid (region.h's argument; tests/cli/mpi.cmake
// compares the files). Nothing is assembled on one rank: each rank keeps its nodes' lists and writes them at their
// place in the file rank 0 opens (writeInfluenceCacheOnRanks), so no rank holds more than its share (the lists: ~200
// bytes a cell). The pyramid's tiles go, a node at a time, to a temporary file of the rank's, and from there to their
// place in the file (writePyramidOnRanks): a rank holds one node's tiles, the tiles on its nodes' edges and the few
// coarse levels. Each rank measures its tiles' parent errors; the ranks share for it the tiles of the coarse levels
// and the first row and column of their tiles on the low edges of their nodes (what the tiles of the nodes beside
// them read as parent samples).
//
// One process (no mpirun) takes this path as rank 0 of 1 where it builds no lists (hc-influence's default above 4.5 M
// cells); with lists it reads the grid whole and calls buildInfluenceLists and build{Surface,Water}Pyramid.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/pyramid.h"

namespace hc::influence {

// The quadtree nodes the ranks share out: level `level`, those holding cells, in Morton order.
struct RankPartition {
    int level = 0;
    std::vector<uint64_t> keys;   // corner keys
    std::vector<uint64_t> cells;  // cells inside each
    std::vector<int> rank;        // the rank that builds it: runs of about equal cell count, in order
};
RankPartition partitionOf(const GridRegionReader& file, int ranks);

// What one rank did (its share), for its log line.
struct RankShare {
    uint64_t nodes = 0;      // partition nodes built
    uint64_t cells = 0;      // cells of those nodes (lists built)
    uint64_t cellsRead = 0;  // cells read, halos and coarse tiles' regions included
    uint64_t tiles = 0;      // pyramid tiles sampled
    double seconds = 0;      // building (not waiting or sending)
};

// One rank's share of the influence lists: the lists of the cells [firstCell, firstCell + cellCount()) of the file, in
// the whole lists' CSR form (offsets count entries from the first cell of the file: offsets.front() is the entries of
// the cells before the part), with file cell indices.
struct InfluenceListsPart {
    KernelParams params;
    uint64_t structureHash = 0, contentHash = 0;  // of the grid
    uint64_t totalCells = 0, totalEntries = 0;    // of the whole lists
    uint64_t firstCell = 0;
    std::vector<uint64_t> offsets;  // cellCount() + 1
    // The entries, node by node in order, each node's as built: not one buffer grown by copies, whose last growth held
    // the old and the new buffer at once (up to 3 times the entries: one rank's peak far above the other's).
    struct Entries {
        std::unique_ptr<uint32_t[]> indices;
        size_t count = 0;
    };
    std::vector<Entries> entries;
    size_t cellCount() const { return offsets.empty() ? 0 : offsets.size() - 1; }
    uint64_t entryCount() const { return offsets.empty() ? 0 : offsets.back() - offsets.front(); }
};

// Collective: every rank calls them with the same file (opened at the grid's water step) and arguments, and gets its
// part, bit for bit that of one process over the grid read whole; one process gets the whole.
// The lists: each rank's nodes' cells (a run of the file's cells; the ranks' runs in rank order).
InfluenceListsPart buildInfluenceListsOnRanks(const GridRegionReader& file, const KernelParams& params,
                                              unsigned threads, bool progress, RankShare* share = nullptr);
// Collective: writes the lists whose parts the ranks hold to `path`, the bytes writeInfluenceCache writes of the whole
// (rank 0 places the sections and appends its part, the others write theirs into rank 0's temporary in place, which
// must lie on a file system every rank sees; nothing appears at `path` if any rank fails), and returns the whole lists'
// Stats on every rank.
InfluenceLists::Stats writeInfluenceCacheOnRanks(const InfluenceListsPart& part, const std::string& path);
// The figures of a pyramid file writePyramidOnRanks wrote (the whole pyramid's, on every rank), as hc-influence prints
// them.
struct PyramidFileSummary {
    int channels = 1;
    std::vector<uint64_t> tiles;  // per level
    std::vector<float> worstM;    // per level: the largest parent error of the first channel
    uint64_t samples = 0, bytes = 0;
    double buildSeconds = 0, writeSeconds = 0;  // this rank's
};
// Collective: builds the pyramid (waterOnly: what buildWaterPyramid builds, a scenario's later step; else
// buildSurfacePyramid) and writes it to `path`, the bytes writeSurfacePyramid writes of the whole (as
// writeInfluenceCacheOnRanks: rank 0 places the sections, the others write theirs in place; nothing appears at `path`
// if any rank fails). A node at a time: each node's tiles go to a temporary file beside `path` (unlinked at once; as
// large as the rank's share of the pyramid) once their parent errors are measured, and a rank holds in memory one
// node's region and tiles, every tile's key and error, the tiles on its nodes' edges and the few coarse levels
// (pyramid_on_ranks.cpp), not its share of the samples.
PyramidFileSummary writePyramidOnRanks(const GridRegionReader& file, const KernelParams& params, unsigned threads,
                                       bool progress, bool waterOnly, const std::string& path,
                                       RankShare* share = nullptr);

}  // namespace hc::influence
