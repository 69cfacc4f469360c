// render/src/renderer_internal.h: what the CPU renderer's frame stages (renderer.cpp) share with its shading stage
// (shading.cpp). Private to render/src/.
#pragma once

#include <cstdint>
#include <vector>

#include "heightcast/render/camera.h"
#include "heightcast/render/renderer.h"

namespace hc::render::detail {

// What shading needs of each pixel's ray beyond the Frame's layers: its unit direction's z (the sky's colour) and
// whether it hit water.
struct PixelRays {
    std::vector<float> dirZ;
    std::vector<uint8_t> isWater;
};

// Stage 5: hillshade light, elevation or depth colours, distance fog, sky, outlines, legend into f.rgb.
void shadePixels(const Scene& scene, const RenderOptions& options, const CameraBasis& basis, const PixelRays& rays,
                 Frame& f, Timings& timings);

}  // namespace hc::render::detail
