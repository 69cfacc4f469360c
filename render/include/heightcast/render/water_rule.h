// heightcast/render/water_rule.h: the water rule as both backends write it into a cascade's textures, once, in the
// common subset of C++ and GLSL 4.30. render/src/ includes it; the build prepends it to every render/gl/shaders/*.comp
// (after gpu_layout.h, cmake/embed_shaders.cmake), so the CPU and the GPU cannot drift apart.
//
// The rule is the exact surface's (influence/surface.h): a texel is wet where the wet cells hold at least
// kWetShareMin of the kernel weight there (and the water level is a number). At a wet texel, d = level - terrain:
//   - the depth texture holds d where d > 0 (0 elsewhere: dry);
//   - the water heightfield holds the level where d > the minimum depth drawn (RenderOptions::waterMinDepthM; -inf
//     elsewhere), so that films thinner than it are not drawn over the terrain.
// Each function is the comparison as every call site made it before, so no texel changes bit.
#ifndef HEIGHTCAST_RENDER_WATER_RULE_H
#define HEIGHTCAST_RENDER_WATER_RULE_H

// influence::kWetShareMin (a macro: GLSL has no namespaces; the C++ side checks the two agree).
#define HC_WET_SHARE_MIN 0.5

#ifdef __cplusplus
#include "heightcast/influence/surface.h"
namespace hc::render::water {
static_assert(HC_WET_SHARE_MIN == influence::kWetShareMin, "the water rule's share is the exact surface's");
#define HC_WATER_FN inline
#else
#define HC_WATER_FN
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

#ifdef __cplusplus
}  // namespace hc::render::water
#endif
#undef HC_WATER_FN
#endif
