// heightcast/influence/on_ranks.h: the influence lists and the surface pyramid built by the ranks of
// `mpirun -np N hc-influence` (DESIGN.md section 13; core/ranks/ranks.h), the same bytes as one process builds.
//
// The split: the grid's cells in Morton order are cut into N shares of about equal cell count, each cut at the start
// of a node of the coarsest cell level (Grid::maxLevel), so no coarsest-level tile is split. Rank K builds the lists of
// the cells in its share (whole super-blocks of the list builder, owned by their first cell) and the pyramid tiles
// whose first cell lies in its share; every other cell a list or a sample needs (the halo: R sigma c_max around the
// share) it reads from the grid like any cell. The others send their lists and samples to rank 0, which places
// them, measures every tile's parent error (it needs the parent level's samples of other shares) and writes.
//
// With one process (no mpirun) these are buildInfluenceLists and build{Surface,Water}Pyramid themselves.
#pragma once

#include <cstdint>
#include <vector>

#include "heightcast/grid/grid.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/pyramid.h"

namespace hc::influence {

// What one rank did (its share), for its log line.
struct RankShare {
    uint64_t cells = 0;       // lists built
    uint64_t tiles = 0;       // pyramid tiles sampled
    double seconds = 0;       // building (not waiting or sending)
};

// The cuts of `g`'s cells into `ranks` shares (above): ranks + 1 cell indices, first 0, last cellCount().
std::vector<size_t> rankCellCuts(const Grid& g, int ranks);

// Every rank calls them with the same grid and arguments (collective): rank 0 gets the whole result, bit for bit
// that of one process; the other ranks an empty one. `share` (optional) gets this rank's share.
InfluenceLists buildInfluenceListsOnRanks(const Grid& g, const KernelParams& params, unsigned threads, bool progress,
                                          RankShare* share = nullptr);
// waterOnly: buildWaterPyramid (a scenario's later step), else buildSurfacePyramid.
SurfacePyramid buildPyramidOnRanks(const Grid& g, const KernelParams& params, unsigned threads, bool progress, bool waterOnly,
                                   RankShare* share = nullptr);

}  // namespace hc::influence
