// heightcast/influence/on_ranks.h: the influence lists and the surface pyramid built by the ranks of
// `mpirun -np N hc-influence` (DESIGN.md section 13; core/ranks/ranks.h), the same bytes as one process builds.
//
// No rank reads the whole grid. The domain is cut into the nodes of one quadtree level (partitionOf: the coarsest
// level with enough nodes holding cells, never finer than the coarsest cell or a pyramid tile's node), and the nodes,
// in Morton order, into N runs of about equal cell count. For each of its nodes a rank reads from the grid file the
// cells of the node and its halo (every cell whose kernel reaches the node: R sigma c around it, region.h), builds
// the lists of the node's cells and the pyramid tiles inside the node, then drops the region. Tiles larger than a
// node (the few coarsest levels) are shared out one by one, each block of 4 x 4 samples from a region read around it.
// Every list and sample is then the same bits as from the whole grid (region.h's argument; tests/cli/mpi.cmake
// compares the files). The ranks send their lists and samples to rank 0, which assembles them in order, measures each
// tile's parent error and writes: rank 0 alone holds what one process writes (the lists: ~200 bytes a cell).
//
// With one process (no mpirun) hc-influence reads the grid whole and calls buildInfluenceLists and
// build{Surface,Water}Pyramid, as before.
#pragma once

#include <cstdint>
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
    uint64_t nodes = 0;        // partition nodes built
    uint64_t cells = 0;        // cells of those nodes (lists built)
    uint64_t cellsRead = 0;    // cells read, halos and coarse tiles' regions included
    uint64_t tiles = 0;        // pyramid tiles sampled
    double seconds = 0;        // building (not waiting or sending)
};

// Collective: every rank calls them with the same file (opened at the grid's water step) and arguments; rank 0 gets
// the whole result, bit for bit that of one process over the grid read whole; the other ranks an empty one.
InfluenceLists buildInfluenceListsOnRanks(const GridRegionReader& file, const KernelParams& params, unsigned threads, bool progress,
                                          RankShare* share = nullptr);
// waterOnly: what buildWaterPyramid builds (a scenario's later step), else buildSurfacePyramid.
SurfacePyramid buildPyramidOnRanks(const GridRegionReader& file, const KernelParams& params, unsigned threads, bool progress,
                                   bool waterOnly, RankShare* share = nullptr);

}  // namespace hc::influence
