// The CPU renderer's texels against the exact surface (split from render_test, see render_world.h): the max
// mipmaps, the approximation's texels summed, copied from the surface pyramid and interpolated from it, the water
// level field at texels, and the cascades' fitting (stable lattice, the frame's view volume).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <random>
#include <string>

#include "heightcast/influence/pyramid.h"
#include "heightcast/render/gpu_layout.h"
#include "heightcast/render/camera.h"
#include "render_world.h"

namespace {

namespace fs = std::filesystem;
using hc::Grid;
using namespace hc::render;
using namespace hc::test;

// The timings JSON writes a bound where one is claimed (a cascade's or the frame's) and null where none is (NaN: none
// made), never 0, which would read as exact.
TEST_F(Render, TimingsJsonClaimsABoundOnlyWhereThereIsOne) {
    Timings t;
    t.cascades.resize(2);
    t.cascades[0].errorBoundM = 1.5e-4;
    t.cascades[1].errorBoundM = t.cascades[1].errorBoundPx = std::numeric_limits<double>::quiet_NaN();
    t.errorBoundM = t.errorBoundPx = std::numeric_limits<double>::quiet_NaN();
    const std::string json = t.toJson();
    EXPECT_NE(json.find("\"error_bound_m\": 0.00015"), std::string::npos) << json;
    EXPECT_NE(json.find("\"error_bound_m\": null"), std::string::npos) << json;
    EXPECT_EQ(json.find("\"error_bound_m\": 0,"), std::string::npos) << json;
    EXPECT_EQ(json.find("\"error_bound_m\": 0.0,"), std::string::npos) << json;
}

// The max mipmap (Heightfield::buildMip): every node of every level holds the largest height of the texels under its
// patches, found here by brute force, and the combined mipmap (buildBothMip) the larger of terrain's and water's; and
// the texels' error estimate (errorEstimateM) the largest of its patches'.
// Sides with odd levels (patches 1, 7, 8, 9, 16, 17, 99, 256, 399: the last on several workers), texels with holes
// (-inf), one worker and all.
TEST_F(Render, MaxMipmapHoldsTheLargestHeightUnderEveryNode) {
    std::mt19937 rng(11);
    for (auto [n, threads] : {std::pair{2, 0u},
                              {8, 0u},
                              {9, 0u},
                              {10, 0u},
                              {17, 0u},
                              {18, 0u},
                              {100, 0u},
                              {257, 0u},
                              {257, 1u},
                              {400, 0u}}) {
        detail::CascadeTextures tex;
        tex.hasWater = true;
        for (detail::Heightfield* hf : {&tex.terrain, &tex.water}) {
            hf->n = n;
            hf->h.resize(size_t(n) * size_t(n));
            for (float& v : hf->h) v = rng() % 10 == 0 ? -INFINITY : float(rng() % 100000) * 0.01f;
            hf->buildMip(threads);
        }
        tex.buildBothMip(threads);
        const detail::Heightfield& hf = tex.terrain;
        // The texels' error estimate (errorEstimateM) is the largest of every patch's, found here one by one.
        float estimate = 0;
        for (int j = 0; j + 2 < n; ++j)
            for (int i = 0; i + 2 < n; ++i) {
                const auto h = [&](int a, int b) { return hf.h[size_t(j + b) * size_t(hf.n) + size_t(i + a)]; };
                estimate = std::max(estimate, gpu::patchErrorEstimateM(h(0, 0), h(1, 0), h(2, 0), h(0, 1), h(0, 2)));
            }
        EXPECT_EQ(hf.errorEstimateM(threads), estimate) << "n " << n;
        if (n >= 100) {
            EXPECT_GT(estimate, 0.0f) << "n " << n;
        }
        ASSERT_EQ(hf.mipSide.front(), n - 1);
        ASSERT_EQ(hf.mipSide.back(), 1);
        for (size_t l = 0; l < hf.mip.size(); ++l) {
            const int side = hf.mipSide[l], span = 1 << l;
            ASSERT_EQ(hf.mip[l].size(), size_t(side) * size_t(side)) << "level " << l;
            for (int iv = 0; iv < side; ++iv)
                for (int iu = 0; iu < side; ++iu) {
                    const size_t at = size_t(iv) * size_t(side) + size_t(iu);
                    float want = -INFINITY;  // the texels under patches [iu span, (iu + 1) span) (clipped), likewise v
                    for (int j = iv * span; j <= std::min((iv + 1) * span, n - 1); ++j)
                        for (int i = iu * span; i <= std::min((iu + 1) * span, n - 1); ++i)
                            want = std::max(want, hf.h[size_t(j) * size_t(n) + size_t(i)]);
                    ASSERT_EQ(hf.mip[l][at], want) << "n " << n << " level " << l << " node " << iu << "," << iv;
                    ASSERT_EQ(tex.bothMip[l][at], std::max(want, tex.water.mip[l][at])) << "n " << n << " level " << l;
                }
        }
    }
}

TEST_F(Render, ApproximationEqualsTheExactSurfaceAtTexels) {
    // One cascade over the LiDAR grid, seen straight down from 1000 m: every ray hits, and every hit lies on the
    // exact surface within the bilinear interpolation bound of the texels around it (checkHits). The texels
    // themselves are compared with the exact surface in TexelsEqualTheExactSurfaceWithin1mm.
    World& w = lidar();
    Camera c;
    c.xWorld = w.grid.originWorldX + 200;
    c.yWorld = w.grid.originWorldY + 200;
    c.zWorld = 1000;
    c.pitchDeg = -90;
    c.fovYDeg = 30;
    c.width = 256;
    c.height = 256;
    RenderOptions o;
    o.cascades = 1;
    o.texelsPerSide = 512;
    Timings t;
    Frame f = renderFrame(*w.scene, c, o, t);
    EXPECT_EQ(t.hits, t.rays) << "straight down over the middle of a complete LiDAR grid every ray hits";
    HitCheck h = checkHits(w, f, t, 1);
    EXPECT_GT(h.checked, 60000u);
    EXPECT_EQ(h.bad, 0u) << "worst error / bound " << h.worstRatio;
    EXPECT_GT(t.cascades[0].gaussians, 1000000u);
}

// The texels themselves against the exact evaluator: every visible texel of the three cascades of an
// overview of the flooded demo DEM, terrain height and water depth. Tolerance 1 mm: the approximation
// sums in float32 with kernel offsets taken relative to each cell's centre (no large coordinates), so its
// error is a few float ulps of the values (0.25 mm at 2000-4000 m) plus the kernel weights' rounding.
TEST_F(Render, TexelsEqualTheExactSurfaceWithin1mm) {
    World& w = hef();
    const auto [setup, fit] = overviewFit(w);
    ASSERT_EQ(fit.cascades.size(), 3u);
    const auto depthLayer = hc::influence::Layer::byName(w.grid, "water_depth");
    double worstZ = 0, worstDepth = 0;
    size_t checked = 0, wet = 0;
    for (const Cascade& k : fit.cascades) {
        detail::CascadeTextures tex;
        detail::approximate(*w.scene, k, tex, 0.01, 0);
        for (int j = 0; j < k.n; ++j)
            for (int i = k.rows[size_t(j)].first; i <= k.rows[size_t(j)].last; ++i) {
                const double x = k.x0 + i * k.texelM, y = k.y0 + j * k.texelM;
                const size_t t = size_t(j) * size_t(k.n) + size_t(i);
                const auto z = w.eval->value(x, y, {});
                if (!z) {
                    EXPECT_TRUE(std::isinf(tex.terrain.h[t]) && tex.terrain.h[t] < 0)
                        << "no surface at " << x << "," << y;
                    continue;
                }
                ++checked;
                worstZ = std::max(worstZ, std::abs(double(tex.terrain.h[t]) - *z));
                const auto d = w.eval->value(x, y, depthLayer);
                if (d && *d > 0) ++wet;
                worstDepth = std::max(worstDepth, std::abs(double(tex.depth[t]) - std::max(0.0, d.value_or(0.0))));
            }
    }
    EXPECT_GT(checked, 50000u);
    EXPECT_GT(wet, 100u) << "the flood at 2600 m is in view";
    EXPECT_LE(worstZ, 1e-3) << "terrain texels [m]";
    EXPECT_LE(worstDepth, 1e-3) << "water depth texels [m]";
    std::printf("%zu texels (%zu wet): worst terrain error %.2e m, worst depth error %.2e m\n", checked, wet, worstZ,
                worstDepth);
}

// With the surface pyramid (docs/design.md section 4): cascade texel sizes are the pyramid's spacings, texels whose
// samples it holds are copies of the exact surface rounded to float (within one float ulp of the exact value:
// half an ulp of rounding plus the double sums' own 1e-12), the rest are summed as without it (1 mm, above), and
// the water drawn from the copied channels follows the same rule. 64 texels a side put the demo DEM's cascades on
// levels 1-3 (127-509 m; its cells are 64-254 m).
TEST_F(Render, PyramidTexelsAreCopiesOfTheExactSurface) {
    World& w = hef();
    const hc::influence::SurfacePyramid pyramid = hc::influence::buildSurfacePyramid(w.grid, w.lists.params());
    const Scene scene(w.grid, w.lists, &pyramid);
    const Camera c = overviewCamera(scene, 320, 200);
    const detail::FrameSetup setup = detail::setUpFrame(scene, c);
    ASSERT_EQ(setup.view.ladderStepsPerOctave, 1);
    const CascadeFit fit = fitCascades(setup.view, 3, 64);
    // The ladder: texels never coarser than without a pyramid (more of them), or with coarserTexels never finer (N).
    detail::FrameSetup plain = setup;
    plain.view.ladderStepsPerOctave = 8;
    const CascadeFit eighth = fitCascades(plain.view, 3, 64);
    detail::FrameSetup coarse = setup;
    coarse.view.coarserTexels = true;
    const CascadeFit coarser = fitCascades(coarse.view, 3, 64);
    ASSERT_EQ(fit.cascades.size(), eighth.cascades.size());
    for (size_t k = 0; k < fit.cascades.size(); ++k) {
        EXPECT_LE(fit.cascades[k].texelM, eighth.cascades[k].texelM);
        EXPECT_GT(fit.cascades[k].texelM, eighth.cascades[k].texelM / 2);
        EXPECT_GE(fit.cascades[k].n, 64);
        EXPECT_LE(fit.cascades[k].n, 2 * 64);
        EXPECT_GE(coarser.cascades[k].texelM, eighth.cascades[k].texelM);
        EXPECT_LT(coarser.cascades[k].texelM, eighth.cascades[k].texelM * 2);
        EXPECT_EQ(coarser.cascades[k].n, 64);
    }
    const auto depthLayer = hc::influence::Layer::byName(w.grid, "water_depth");
    uint64_t copiedSeen = 0, copiedCounted = 0, summed = 0, wet = 0, ties = 0;
    for (const Cascade& k : fit.cascades) {
        const double t = std::log2(k.texelM / w.grid.finestCellM);
        ASSERT_EQ(t, std::round(t)) << "texel " << k.texelM << " m is not a pyramid spacing";
        detail::CascadeTextures tex;
        const detail::ApproximationWork work = detail::approximate(scene, k, tex, 0.01, 0);
        const int level = work.pyramidLevel;
        ASSERT_EQ(level, int(t));
        copiedCounted += work.pyramidTexels;
        for (int j = 0; j < k.n; ++j)
            for (int i = k.rows[size_t(j)].first; i <= k.rows[size_t(j)].last; ++i) {
                double x = k.x0 + i * k.texelM, y = k.y0 + j * k.texelM;
                const size_t at = size_t(j) * size_t(k.n) + size_t(i);
                const bool held =
                    x >= 0 && y >= 0 &&
                    pyramid.sample(level, uint64_t(std::llround(x / k.texelM)), uint64_t(std::llround(y / k.texelM)),
                                   hc::influence::PyramidChannel::Elevation);
                // A copy is the sample at its lattice point, which x0 + i s may miss by a rounding: on the east or
                // north edge of a cell next to a hole the two lie on either side of the edge (half-open cells).
                if (held)
                    x = double(std::llround(x / k.texelM)) * k.texelM,
                    y = double(std::llround(y / k.texelM)) * k.texelM;
                const auto z = w.eval->value(x, y, {});
                if (!z) {
                    EXPECT_TRUE(std::isinf(tex.terrain.h[at]) && tex.terrain.h[at] < 0)
                        << "no surface at " << x << "," << y;
                    continue;
                }
                const double tol = held ? std::ldexp(std::abs(*z), -23) + 1e-9 : 1e-3;
                ASSERT_NEAR(double(tex.terrain.h[at]), *z, tol)
                    << (held ? "copied" : "summed") << " texel at " << x << "," << y;
                const double d = std::max(0.0, w.eval->value(x, y, depthLayer).value_or(0.0));
                // The water rule's wet share threshold decides a tie at exactly 1/2 (a point symmetric between wet
                // and dry cells) by rounding: the exact evaluator sums wet and all weights apart, the pyramid in one
                // loop. Such texels are counted, not compared.
                if (held) {
                    const float share =
                        *pyramid.sample(level, uint64_t(std::llround(x / k.texelM)),
                                        uint64_t(std::llround(y / k.texelM)), hc::influence::PyramidChannel::WetShare);
                    if (std::abs(double(share) - hc::influence::kWetShareMin) < 1e-6) {
                        ++ties;
                        continue;
                    }
                }
                EXPECT_NEAR(double(tex.depth[at]), d, held ? std::ldexp(std::abs(*z), -22) + 1e-9 : 1e-3)
                    << "depth at " << x << "," << y;
                held ? ++copiedSeen : ++summed;
                wet += d > 0;
            }
    }
    EXPECT_GT(copiedSeen, 2000u);
    // Ties are lattice points equidistant from wet and dry cells of one size along straight shores of the flat lake: a
    // few per thousand wet texels (22 in 4664 with the finer texels), never a large share.
    EXPECT_LT(ties, wet / 100);
    EXPECT_GE(copiedCounted, copiedSeen * 9 / 10) << "copied texels must not be summed again";
    EXPECT_GT(wet, 20u) << "the flood at 2600 m is in view";
    std::printf("%llu texels copied from the pyramid, %llu summed, %llu wet, %llu on the wet share tie\n",
                (unsigned long long)copiedSeen, (unsigned long long)summed, (unsigned long long)wet,
                (unsigned long long)ties);
}

// Texels finer than every pyramid level stored around them are interpolated (bicubic, Catmull-Rom) from the nearest
// coarser level stored (RenderOptions::pyramidInterpolateLevels). Compared texel by texel with the exact evaluator and
// with the kernel path (interpolation off, tested above), from an overview and a nearer camera at 64 and 256 texels
// a side, on the 1 m LiDAR tile flooded at 397 m (shores everywhere; 1 m texels over 2 m cells) and on the grid of
// cells 0.75-96 m with a hole (test_grids.h: texels up to 3 levels finer than the cells under them).
//
// The tolerance: an interpolated texel of a cascade whose texels came from up to `up` levels higher must err no more
// than a bilinear patch at that level's spacing s = 2^up texels would (s^2 / 8 (|v_xx| + |v_yy|), the bound of the
// hits tests, from the exact surface's curvature): what the cascade would give with texels that coarse, which
// --pyramid-coarse accepts; the rendered error (hc-bench --accuracy, docs/benchmarks.md) stays that of the finer
// texels. A wrong stencil (a sample off by one, a swapped weight) errs by the relief between samples, above that bound.
// The water depth is level minus terrain, each interpolated: within the two bounds where both this texel and the exact
// surface hold water; where only one does (the edge moved by the interpolation) it is counted and must be rare.
// Every other texel is the kernel path's to the bit: holes' and floods' edges are left to the kernels.
TEST_F(Render, InterpolatedPyramidTexelsStayWithinACoarserPatchError) {
    static World ratio = [] {
        World w;
        w.grid = hc::test::ratio128Grid();
        w.init();
        return w;
    }();
    uint64_t interpolated = 0, counted = 0, wet = 0, edge = 0;
    double worst = 0, worstDepth = 0;
    int mostUp = 0;
    for (World* w : {&lidarFlood(), &ratio}) {
        const hc::influence::SurfacePyramid pyramid = hc::influence::buildSurfacePyramid(w->grid, w->lists.params());
        const Scene scene(w->grid, w->lists, &pyramid);
        const auto depthLayer =
            scene.hasWater() ? hc::influence::Layer::byName(w->grid, "water_depth") : hc::influence::Layer{};
        const auto surface =
            scene.hasWater() ? hc::influence::Layer::byName(w->grid, "water_surface") : hc::influence::Layer{};
        for (int cam = 0; cam < 2; ++cam) {
            Camera c = overviewCamera(scene, 320, 200);
            if (cam == 1) {  // 0.35 of the way from the middle of the scene: the near cascade finer than the cells
                double mx, my;
                w->grid.localToWorld(0.5 * (scene.xMin + scene.xMax), 0.5 * (scene.yMin + scene.yMax), mx, my);
                const double mz = 0.5 * (scene.zMin + scene.zMax);
                c.xWorld = mx + 0.35 * (c.xWorld - mx), c.yWorld = my + 0.35 * (c.yWorld - my),
                c.zWorld = mz + 0.35 * (c.zWorld - mz);
            }
            const detail::FrameSetup setup = detail::setUpFrame(scene, c);
            for (int texels : {64, 256}) {
                const CascadeFit fit = fitCascades(setup.view, 3, texels);
                for (const Cascade& k : fit.cascades) {
                    detail::CascadeTextures plain, fast;
                    detail::approximate(scene, k, plain, 0.01, 0);
                    const detail::ApproximationWork work = detail::approximate(scene, k, fast, 0.01, 0, nullptr, 3);
                    const double s = std::ldexp(k.texelM, work.pyramidInterpolatedUp);
                    uint64_t seen = 0;
                    for (int j = 0; j < k.n; ++j)
                        for (int i = k.rows[size_t(j)].first; i <= k.rows[size_t(j)].last; ++i) {
                            const size_t at = size_t(j) * size_t(k.n) + size_t(i);
                            if (plain.terrain.h[at] == fast.terrain.h[at] &&
                                (!scene.hasWater() || plain.depth[at] == fast.depth[at]))
                                continue;
                            ++seen;
                            const double x = k.x0 + i * k.texelM, y = k.y0 + j * k.texelM;
                            const auto z = w->eval->value(x, y, {});
                            ASSERT_TRUE(z) << "interpolated where there is no surface, at " << x << "," << y;
                            const std::optional<double> claim = bilinearBound(*w->eval, {}, x, y, s);
                            if (!claim) continue;  // next to a hole: the bound makes no claim
                            const double bound = *claim;
                            const double err = std::abs(double(fast.terrain.h[at]) - *z);
                            worst = std::max(worst, err / bound);
                            ASSERT_LE(err, bound) << "terrain at " << x << "," << y << " (texel " << k.texelM
                                                  << " m, from up to " << s << " m)";
                            if (!scene.hasWater()) continue;
                            const double d = std::max(0.0, w->eval->value(x, y, depthLayer).value_or(0.0));
                            if (d > 0 && fast.depth[at] > 0) {
                                ++wet;
                                const double depthErr = std::abs(double(fast.depth[at]) - d);
                                worstDepth = std::max(worstDepth, depthErr);
                                const std::optional<double> surfaceClaim = bilinearBound(*w->eval, surface, x, y, s);
                                if (surfaceClaim) {
                                    EXPECT_LE(depthErr, bound + *surfaceClaim) << "water depth at " << x << "," << y;
                                }
                            } else if (d > 0 || fast.depth[at] > 0) {
                                ++edge;
                            }
                        }
                    // A texel interpolated may still equal the kernel path's value in float (a flat lake).
                    EXPECT_LE(seen, work.pyramidInterpolated)
                        << "only interpolated texels may differ from the kernel path";
                    interpolated += seen, counted += work.pyramidInterpolated;
                    mostUp = std::max(mostUp, work.pyramidInterpolatedUp);
                }
            }
        }
    }
    EXPECT_GT(interpolated, 50000u);
    EXPECT_GE(mostUp, 2) << "texels interpolated from two levels up or more";
    EXPECT_GT(wet, 10000u) << "the flood is in view";
    EXPECT_LT(edge, wet / 100) << "texels wet in the exact surface or the interpolation only";
    std::printf(
        "%llu texels interpolated (%llu counted), up to %d levels up, %llu wet (%llu on an edge moved); worst terrain "
        "error "
        "%.3f of its bound, worst depth error %.4f m\n",
        (unsigned long long)interpolated, (unsigned long long)counted, mostUp, (unsigned long long)wet,
        (unsigned long long)edge, worst, worstDepth);
}

// Wherever the approximation puts water in a texel its level is at or above the terrain's texel, from every fill path
// (the kernels, pyramid samples copied, texels interpolated from a coarser level) and with the minimum depth drawn at 0
// as well as the default: the water drawn stands above the terrain; only the shore texels made after it
// (ShoreTexelsHoldTheLevelWhereTheGroundRisesAboveIt) lie below it, and the ray walk's shortcut under water
// (raycast.cpp, PatchWalk::endsAt) checks for them.
TEST_F(Render, WaterTexelsLieAtOrAboveTheTerrain) {
    uint64_t wet = 0, strictlyAbove = 0;
    for (World* w : {&lidarFlood(), &hef()}) {
        const hc::influence::SurfacePyramid pyramid = hc::influence::buildSurfacePyramid(w->grid, w->lists.params());
        const Scene withPyramid(w->grid, w->lists, &pyramid);
        for (const Scene* scene : {static_cast<const Scene*>(w->scene.get()), &withPyramid}) {
            const Camera c = overviewCamera(*scene, 320, 200);
            const detail::FrameSetup setup = detail::setUpFrame(*scene, c);
            for (int texels : {64, 256}) {
                const CascadeFit fit = fitCascades(setup.view, 3, texels);
                for (const Cascade& k : fit.cascades)
                    for (double minDepth : {0.0, 0.01})
                        for (int interpolate : {0, 3}) {
                            detail::CascadeTextures tex;
                            detail::approximate(*scene, k, tex, minDepth, 0, nullptr, interpolate);
                            ASSERT_TRUE(tex.hasWater);
                            for (size_t at = 0; at < tex.water.h.size(); ++at) {
                                if (!std::isfinite(tex.water.h[at])) continue;
                                ++wet;
                                ASSERT_GE(tex.water.h[at], tex.terrain.h[at])
                                    << "texel " << at << " of a cascade of " << k.texelM << " m";
                                strictlyAbove += tex.water.h[at] > tex.terrain.h[at];
                            }
                        }
            }
        }
    }
    EXPECT_GT(wet, 100000u) << "the floods are in view";
    std::printf("%llu wet texels, %llu strictly above the terrain\n", (unsigned long long)wet,
                (unsigned long long)strictlyAbove);
}

// The water at the shores (CascadeTextures::extendWaterToShores, water_rule.h), on both floods' cascades against the
// rule applied texel by texel: a texel whose water does not stand above its terrain holds the highest level of its 8
// neighbours' that do where its terrain rises above that level, else none; the others keep their level; made again
// from textures it already ran on (a kept cascade's), nothing changes.
TEST_F(Render, ShoreTexelsHoldTheLevelWhereTheGroundRisesAboveIt) {
    uint64_t shore = 0, hollow = 0;
    for (World* w : {&lidarFlood(), &hef()}) {
        const Camera c = overviewCamera(*w->scene, 320, 200);
        const CascadeFit fit = fitCascades(detail::setUpFrame(*w->scene, c).view, 3, 256);
        for (const Cascade& k : fit.cascades) {
            detail::CascadeTextures tex;
            detail::approximate(*w->scene, k, tex, 0.01, 0);
            const hc::render::detail::Texels drawn = tex.water.h;
            tex.extendWaterToShores(0);
            const int n = k.n;
            for (int j = 0; j < n; ++j)
                for (int i = 0; i < n; ++i) {
                    const size_t at = size_t(j) * size_t(n) + size_t(i);
                    const float terrain = tex.terrain.h[at];
                    if (drawn[at] > terrain) {
                        ASSERT_EQ(tex.water.h[at], drawn[at]) << "a drawn texel keeps its level";
                        continue;
                    }
                    float around = -std::numeric_limits<float>::infinity();
                    for (int y = std::max(j - 1, 0); y <= std::min(j + 1, n - 1); ++y)
                        for (int x = std::max(i - 1, 0); x <= std::min(i + 1, n - 1); ++x) {
                            const size_t q = size_t(y) * size_t(n) + size_t(x);
                            if (drawn[q] > tex.terrain.h[q]) around = std::max(around, drawn[q]);
                        }
                    const float expected = around < terrain ? around : -std::numeric_limits<float>::infinity();
                    ASSERT_EQ(tex.water.h[at], expected) << "texel " << i << ", " << j << " of " << k.texelM << " m";
                    shore += std::isfinite(expected);
                    hollow += std::isfinite(around) && !std::isfinite(expected);
                }
            const hc::render::detail::Texels once = tex.water.h;
            tex.extendWaterToShores(1);
            EXPECT_TRUE(once == tex.water.h) << "made again, the shore is the same";
        }
    }
    std::printf("%llu shore texels, %llu beside water but below its level\n", (unsigned long long)shore,
                (unsigned long long)hollow);
    EXPECT_GT(shore, 1000u) << "both floods have shores in view";
}

TEST_F(Render, StableFittingKeepsTexelsOnTheLattice) {
    World& w = hef();
    Camera a = overviewCamera(*w.scene, 320, 200);
    Camera b = a;
    b.xWorld += 3.7;  // far less than a texel
    b.yWorld -= 1.9;
    auto fitOf = [&](const Camera& c) {
        const CameraBasis basis = basisOf(c);
        ViewVolume v;
        v.eyeLocal = {c.xWorld - w.grid.originWorldX, c.yWorld - w.grid.originWorldY, c.zWorld};
        v.forward = basis.forward, v.right = basis.right, v.up = basis.up;
        v.tanHalfX = basis.tanHalfX, v.tanHalfY = basis.tanHalfY;
        v.nearM = 1, v.farM = 200000;
        v.yawRad = c.yawDeg * M_PI / 180;
        v.boxMin = {w.scene->xMin, w.scene->yMin, w.scene->zMin};
        v.boxMax = {w.scene->xMax, w.scene->yMax, w.scene->zMax};
        v.finestCellM = w.grid.finestCellM;
        return fitCascades(v, 3, 1024);
    };
    CascadeFit fa = fitOf(a), fb = fitOf(b);
    ASSERT_EQ(fa.cascades.size(), 3u);
    for (size_t k = 0; k < 3; ++k) {
        const Cascade &ca = fa.cascades[k], &cb = fb.cascades[k];
        ASSERT_EQ(ca.texelM, cb.texelM) << "cascade " << k << ": the texel size must not change for a small move";
        // Both corners on the global lattice of multiples of s: every texel centre of one frame that lies
        // inside the other's texture is a texel centre there too.
        const double qa = ca.x0 / ca.texelM, qb = cb.x0 / cb.texelM;
        EXPECT_EQ(qa, std::round(qa));
        EXPECT_EQ(qb, std::round(qb));
        EXPECT_EQ(ca.y0 / ca.texelM, std::round(ca.y0 / ca.texelM));
    }
    EXPECT_NEAR(ladderTexelSize(1000, 1024, 1.0) / ladderTexelSize(999.9, 1024, 1.0), 1.0, 0.1);
}

// Stage 1 of both backends (detail::fitFrame): the cascades fitCascades gives for the frame's view volume, with the
// view direction in Timings; for a camera below the terrain none at all.
TEST_F(Render, FitFrameFitsTheViewVolumeOrNothingBelowTheTerrain) {
    World& w = hef();
    RenderOptions o;
    o.texelsPerSide = 256;
    const Camera c = overviewCamera(*w.scene, 320, 200);
    const detail::FrameSetup setup = detail::setUpFrame(*w.scene, c);
    Timings t;
    const CascadeFit fit = detail::fitFrame(*w.scene, c, setup, o, t);
    const CascadeFit want = fitCascades(setup.view, o.cascades, o.texelsPerSide);
    ASSERT_EQ(fit.cascades.size(), 3u);
    ASSERT_EQ(fit.cascades.size(), want.cascades.size());
    for (size_t k = 0; k < fit.cascades.size(); ++k) {
        EXPECT_EQ(fit.cascades[k].texelM, want.cascades[k].texelM) << "cascade " << k;
        EXPECT_EQ(fit.cascades[k].x0, want.cascades[k].x0) << "cascade " << k;
        EXPECT_EQ(fit.cascades[k].y0, want.cascades[k].y0) << "cascade " << k;
    }
    EXPECT_EQ(t.viewDirX, fit.dir.x);
    EXPECT_EQ(t.viewDirY, fit.dir.y);
    EXPECT_NEAR(std::hypot(t.viewDirX, t.viewDirY), 1.0, 1e-12);
    const Camera below = above(w, -50, -10);
    Timings tb;
    const CascadeFit none = detail::fitFrame(*w.scene, below, detail::setUpFrame(*w.scene, below), o, tb);
    EXPECT_TRUE(none.cascades.empty());
    EXPECT_LT(none.hull.size(), 3u);
}

// The texels agree with the exact level field (influence/surface.h) wherever both draw water, and draw it at
// the same texels: those where the exact depth exceeds the 1 cm drawn minimum by 1 mm (the texels' error bound,
// TexelsEqualTheExactSurfaceWithin1mm) and whose wet share is not within float rounding of 1/2 (there the two
// may decide differently: counted, at most 0.1 % of the wet texels).
TEST_F(RenderWater, TexelsDrawTheExactLevelField) {
    World& w = lidarFlood();
    const Camera c = overviewCamera(*w.scene, 320, 200);
    const detail::FrameSetup setup = detail::setUpFrame(*w.scene, c);
    const CascadeFit fit = fitCascades(setup.view, 3, 256);
    const auto surface = hc::influence::Layer::byName(w.grid, "water_surface");
    const auto depth = hc::influence::Layer::byName(w.grid, "water_depth");
    size_t wet = 0, differ = 0;
    double worst = 0;
    for (const Cascade& k : fit.cascades) {
        detail::CascadeTextures tex;
        detail::approximate(*w.scene, k, tex, 0.01, 0);
        for (int j = 0; j < k.n; ++j)
            for (int i = k.rows[size_t(j)].first; i <= k.rows[size_t(j)].last; ++i) {
                const double x = k.x0 + i * k.texelM, y = k.y0 + j * k.texelM;
                const size_t t = size_t(j) * size_t(k.n) + size_t(i);
                const auto s = w.eval->value(x, y, surface);
                const auto d = w.eval->value(x, y, depth);
                const bool texWater = std::isfinite(tex.water.h[t]);
                if (!d) {
                    EXPECT_FALSE(texWater) << "water in a hole";
                    continue;
                }
                if (*d > 0.011) {
                    ++wet;
                    if (!texWater) {
                        ++differ;
                        continue;
                    }
                    worst = std::max(worst, std::abs(double(tex.water.h[t]) - *s));
                } else if (*d < 0.009 && texWater) {
                    ++differ;
                }
            }
    }
    std::printf("%zu wet texels, %zu drawn differently, worst level error %.2e m\n", wet, differ, worst);
    EXPECT_GT(wet, 10000u);
    EXPECT_LE(differ * 1000, wet);
    EXPECT_LE(worst, 1e-3);
}

}  // namespace
