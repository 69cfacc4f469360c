// influence/src/pyramid_build.h: the surface pyramid's build in its two passes, for builders that share the tiles
// out (the ranks of mpirun, on_ranks.cpp): sampling the tiles, then each tile's bound against its parent level.
#pragma once

#include <cstdint>
#include <functional>

#include "heightcast/influence/pyramid.h"
#include "kernel_sums.h"
#include "list_index.h"

namespace hc::influence::detail {

// Which tiles a process samples: those of level t and key `key` for which it returns true.
using TileFilter = std::function<bool(int t, uint64_t key)>;

// Every tile of the pyramid (its keys: pyramid.h's rule, or only those a wet cell's kernel reaches), sampled where
// `owns` (nullptr: everywhere) says, the others left 0; parent errors 0 until measureParentErrors. Throws hc::Error
// for invalid parameters.
SurfacePyramid samplePyramid(const Grid& g, const KernelParams& params, unsigned threads, bool progress, bool wetReachedOnly,
                             const TileFilter* owns);
// Fills parentErrorM of every tile below the top from the samples (every tile must be sampled): a pyramid of
// samplePyramid only (its storage is its own).
void measureParentErrors(SurfacePyramid& p, unsigned threads);

// The pieces, for builders that sample tiles from parts of a grid (a region read around them, on_ranks.cpp):

// Appends to `out` the keys of the tiles of level t (side samples a side; top: the pyramid's top level) that cells
// [lo, hi) of g keep (pyramid.h's rule: the tile's node holds a cell of level <= t; any cell at the top), in their
// order, each once for consecutive cells.
void tileKeysOfCells(const Grid& g, size_t lo, size_t hi, int t, int top, int side, std::vector<uint64_t>& out);
// Appends the keys of the tiles of level t that the kernel of a wet cell among [lo, hi) reaches, grown by one tile on
// each side (buildWaterPyramid's rule; unsorted, with repeats). depthLayer: g's water_depth layer.
void wetMarkedTiles(const Grid& g, const KernelParams& params, int depthLayer, size_t lo, size_t hi, int t, int side,
                    std::vector<uint64_t>& out);

// One worker's memory for buildTile.
struct PyramidWorkspace {
    ListIndex::Scratch wide;
    Gathered block;  // one block's candidates, in the local frame
};
// Samples per side of a block that gathers its candidates once (pyramid.cpp): kPyramidBlock where the spacing of level t
// is below the kernel reach of the coarsest cells, where a block's candidates are mostly shared by its samples; 1 (each
// sample its own candidates) from the level where the spacing reaches it: a block of 3 spacings there would gather every
// cell in its box while each cell reaches a few samples at most (at the top level, 3/16 of the domain a block).
constexpr int kPyramidBlock = 4;
int pyramidBlockSide(const Grid& shape, const KernelParams& params, int t);
// Fills the samples of one tile (all `channels` planes at `out`) of level t with corner key `key`, from the cells of g
// through `index` (a ListIndex of g); onlyBlock >= 0: only that block (pyramidBlockSide samples a side, row-major in
// the tile), whose candidates g must then hold (a region around the block). The samples are the same bits whatever
// part of the grid g is, if it holds every cell whose kernel reaches the block (region.h's argument).
void buildTile(const Grid& g, const ListIndex& index, const KernelParams& params, int t, int side, uint64_t key, int channels,
               int depthLayer, float* out, PyramidWorkspace& w, int onlyBlock);

}  // namespace hc::influence::detail
