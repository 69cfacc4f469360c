// heightcast/render/water_rule.h: the water rule as both backends write it into a cascade's textures, once, in the
// common subset of C++ and GLSL 4.30. render/src/ includes it; the build prepends it to every render/gl/shaders/*.comp
// (after gpu_layout.h, cmake/embed_shaders.cmake), so the CPU and the GPU cannot drift apart.
//
// The rule is the exact surface's (influence/surface.h): a texel is wet where the wet cells hold at least
// kWetShareMin of the kernel weight there (and the water level is a number). At a wet texel, d = level - terrain:
//   - the depth texture holds d where d > 0 (0 elsewhere: dry);
//   - the water heightfield holds the level where d > the minimum depth drawn (RenderOptions::waterMinDepthM; -inf
//     elsewhere, but at a shore: shoreLevel below), so that films thinner than it are not drawn over the terrain.
// Each function is the comparison as every call site made it before, so no texel changes bit.
#ifndef HEIGHTCAST_RENDER_WATER_RULE_H
#define HEIGHTCAST_RENDER_WATER_RULE_H

// influence::kWetShareMin (a macro: GLSL has no namespaces; the C++ side checks the two agree).
#define HC_WET_SHARE_MIN 0.5

#ifdef __cplusplus
#include <limits>

#include "heightcast/influence/surface.h"
namespace hc::render::water {
static_assert(HC_WET_SHARE_MIN == influence::kWetShareMin, "the water rule's share is the exact surface's");
#define HC_WATER_FN inline
#define HC_NO_WATER (-std::numeric_limits<float>::infinity())
#else
#define HC_WATER_FN
#define HC_NO_WATER uintBitsToFloat(0xff800000u)
#endif

// Wet, from a stored share of the kernel weight (the pyramid's samples and tiles).
HC_WATER_FN bool wetShare(float share) { return share >= float(HC_WET_SHARE_MIN); }
// Wet, from the sums of the kernel weights: of the wet cells, and of all cells (the kernel path).
HC_WATER_FN bool wetWeights(double wetWeight, double allWeight) {
    return wetWeight > 0.0 && wetWeight >= HC_WET_SHARE_MIN * allWeight;
}
// At a wet texel whose water stands d = level - terrain above the terrain [m]: whether the depth texture holds d,
// and whether the water heightfield holds the level.
HC_WATER_FN bool holdsDepth(float d) { return d > 0.0f; }
HC_WATER_FN bool drawsWater(float d, float minDepthM) { return d > minDepthM; }

// The shore. A patch of water is drawn where its four texels hold a level, and a texel held its level only where its
// water is drawn: that stopped the drawn water up to a texel short of the exact shore, where a ray could reach the
// ground under the water (`--verify-error`'s shoreline count, docs/benchmarks.md). So a texel whose water is not drawn,
// beside texels (of its 8 neighbours) whose water is, holds the highest of their levels where its terrain rises above
// it: the patches at such a shore are drawn too, and the terrain cuts their water (the drawn shore is where the two
// bilinear surfaces meet). Where its ground lies below that level the texel holds none: that shore is set by the wet
// share, not by the ground meeting the level (water drawn on at the level would cover dry ground; lowered to the ground
// it would lie metres under the exact level).
// A texel's water stands above its terrain where it is drawn (drawsWater: d > minimum >= 0), never at a shore texel
// (shoreLevel < terrain): the backends tell the two apart by this alone, so a shore texel kept from the last frame is
// made again from its neighbours, and a patch whose four texels stand above their terrain has its water above its
// terrain everywhere (bilinear in both).
HC_WATER_FN bool standsAbove(float water, float terrain) { return water > terrain; }
// The water heightfield at a texel whose water does not stand above its terrain, from the highest level of its 8
// neighbours' that do (-inf where none does): that level where the terrain rises above it, else none (-inf).
HC_WATER_FN float shoreLevel(float terrain, float highestNeighbourLevel) {
    return highestNeighbourLevel < terrain ? highestNeighbourLevel : HC_NO_WATER;
}

#ifdef __cplusplus
}  // namespace hc::render::water
#endif
#undef HC_WATER_FN
#undef HC_NO_WATER
#endif
