// Per-cascade textures shared by the CPU stages (private to render/).
#pragma once

#include <vector>

#include "heightcast/render/cascades.h"
#include "heightcast/render/renderer.h"

namespace hc::render::detail {

// One heightfield in a cascade: heights at texel centres and its max mipmap over patches.
// -inf marks "no surface" (a hole, dry land for water, or a texel outside the visible polygon).
struct Heightfield {
    int n = 0;                             // texels per side; patches per side = n - 1
    std::vector<float> h;                  // n * n [m, local z]
    std::vector<std::vector<float>> mip;   // mip[0]: (n-1)^2 patch maxima, then halving to 1 x 1
    std::vector<int> mipSide;              // side of each mip level
    void buildMip();
};

struct CascadeTextures {
    Heightfield terrain, water;            // water: surface height where wet (depth > min), else -inf
    std::vector<float> depth;              // water depth at texels (0 where dry)
    bool hasWater = false;
};

// Approximation (approximate.cpp): fills the textures of one cascade; returns Gaussians evaluated.
uint64_t approximate(const Scene& scene, const Cascade& c, CascadeTextures& tex, double waterMinDepthM, unsigned threads);

// One ray through the cascades (raycast.cpp).
struct Hit {
    bool hit = false;
    double t = 0;                          // distance along the ray [m]
    double nx = 0, ny = 0, nz = 1;         // unit normal
    double depth = 0;                      // water depth at the hit (water hits), else 0
    bool water = false;
    int cascade = -1;
};

struct RayContext {
    const CascadeFit* fit;
    const std::vector<CascadeTextures>* tex;
    double eye[3];
    double nearM, farM;
};

Hit castRay(const RayContext& ctx, const double dir[3]);

}  // namespace hc::render::detail
