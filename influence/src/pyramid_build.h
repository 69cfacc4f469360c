// influence/src/pyramid_build.h: the surface pyramid's build in its two passes, for builders that share the tiles
// out (the ranks of mpirun, on_ranks.cpp): sampling the tiles, then each tile's bound against its parent level.
#pragma once

#include <cstdint>
#include <functional>

#include "heightcast/influence/pyramid.h"

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

}  // namespace hc::influence::detail
