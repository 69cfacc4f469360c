// influence/src/pyramid_build.h: the surface pyramid's build in pieces, for builders that sample the tiles from parts
// of a grid and assemble them (the ranks of mpirun, on_ranks.cpp): the tiles kept, one tile's samples, then the pyramid
// over them with each tile's bound against its parent level.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "heightcast/influence/pyramid.h"
#include "kernel_sums.h"
#include "list_index.h"
#include "pyramid_storage.h"

namespace hc::influence::detail {

// Whether water is drawn at some sample of a 3-channel tile (its planes of `plane` samples at `tile`: elevation, water
// level, wet share) by the water rule (surface.h): the tiles a water pyramid (2 channels) keeps.
bool waterDrawnIn(const float* tile, size_t plane);
// Tile sides per level 0..top of a grid of this shape (kPyramidTileSide; less where the domain is smaller than a tile).
std::vector<int> pyramidTileSides(const Grid& shape);
// The pyramid p (its fields but levels and storage set) over `owned` (per level its tile keys, ascending, and their
// samples; errors are filled here): the levels pointed at the storage and every tile's parent error measured from the
// samples (pyramid.h). `halo`: where p holds part of each level (a rank's, on_ranks.cpp), the parent-level tiles beside
// them that others hold (same sides and channels; only their first row and column are read: a tile's parent samples
// lie in its parent tile and, at its far edges, that tile's first row and column of the neighbours in +x, +y, +x+y).
SurfacePyramid finishPyramid(SurfacePyramid p, std::shared_ptr<SurfacePyramid::Storage> owned,
                             const std::vector<int>& sides, unsigned threads, const SurfacePyramid* halo = nullptr);

// The pieces, for builders that sample tiles from parts of a grid (a region read around them, on_ranks.cpp):

// Appends to out[t], for each level t in [t0, t1], the keys of the tiles of level t (sides[t] samples a side; top: the
// pyramid's top level) that cells [lo, hi) of g keep, by pyramid.h's rule: below the top, every tile that the kernel
// reach box of a cell of level <= t meets (the square of half-side params.radiusM(cell size) about the cell's centre);
// at the top, the tiles holding a cell. Unsorted, with repeats (consecutive cells reaching the same tiles add them
// once). One pass over the cells for every level: a cell's centre and reach are found once.
void tileKeysOfCells(const Grid& g, const KernelParams& params, size_t lo, size_t hi, int t0, int t1, int top,
                     const std::vector<int>& sides, std::vector<std::vector<uint64_t>>& out);
// tileKeysOfCells with the cells split among `threads` workers, their keys appended in turn (a repeat at a seam may
// appear: callers sort the keys and make them unique).
void tileKeysOnThreads(const Grid& g, const KernelParams& params, size_t lo, size_t hi, int t0, int t1, int top,
                       const std::vector<int>& sides, unsigned threads, std::vector<std::vector<uint64_t>>& out);
// Appends the keys of the tiles of level t that the kernel of a wet cell among [lo, hi) reaches, grown by one tile on
// each side (buildWaterPyramid's rule; unsorted, with repeats). depthLayer: g's water_depth layer.
void wetMarkedTiles(const Grid& g, const KernelParams& params, int depthLayer, size_t lo, size_t hi, int t, int side,
                    std::vector<uint64_t>& out);

// One worker's memory for buildTile.
struct PyramidWorkspace {
    ListIndex::Scratch tile;  // a whole tile's candidates (buildTile narrows them to each row of blocks, then block)
    ListIndex::Scratch row;
    ListIndex::Scratch wide;
    Gathered block;  // one block's candidates, in the local frame
};
// Samples per side of a block that gathers its candidates once (pyramid.cpp): kPyramidBlock where the spacing of level
// t is below the kernel reach of the coarsest cells, where a block's candidates are mostly shared by its samples; 1
// (each sample its own candidates) from the level where the spacing reaches it: a block of 3 spacings there would
// gather every cell in its box while each cell reaches a few samples at most (at the top level, 3/16 of the domain a
// block).
constexpr int kPyramidBlock = 4;
int pyramidBlockSide(const Grid& shape, const KernelParams& params, int t);
// Fills the samples of one tile (all `channels` planes at `out`) of level t with corner key `key`, from the cells of g
// through `index` (a ListIndex of g); onlyBlock >= 0: only that block (pyramidBlockSide samples a side, row-major in
// the tile), whose candidates g must then hold (a region around the block). The samples are the same bits whatever
// part of the grid g is, if it holds every cell whose kernel reaches the block (region.h's argument).
void buildTile(const Grid& g, const ListIndex& index, const KernelParams& params, int t, int side, uint64_t key,
               int channels, int depthLayer, float* out, PyramidWorkspace& w, int onlyBlock);

}  // namespace hc::influence::detail
