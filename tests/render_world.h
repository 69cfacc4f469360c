// tests/render_world.h: what the CPU renderer's tests share (render_textures_test, render_hits_test,
// render_cameras_test, render_frames_test): real DEMs with their exact surface and a scene of them, the check of a
// frame's hits against that surface, cameras, and the suites' fixtures (each test's files in a directory of its own).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <utility>

#include "heightcast/influence/influence.h"
#include "heightcast/influence/surface.h"
#include "heightcast/render/cascades.h"
#include "heightcast/render/renderer.h"
// White box: the approximation's texel textures and a frame's set-up (the library's detail part).
#include "heightcast/render/detail/frame.h"
#include "surface_bound.h"
#include "temp_dir.h"
#include "test_data.h"
#include "test_grids.h"

namespace hc::test {

// The suites whose tests write files (the EXR layers, grid files): each test's into a directory of its own.
class Render : public TempDirTest {
protected:
    Render() : TempDirTest("hc_render_") {}
};
class RenderHits : public TempDirTest {
protected:
    RenderHits() : TempDirTest("hc_render_hits_") {}
};
class RenderWater : public TempDirTest {
protected:
    RenderWater() : TempDirTest("hc_render_water_") {}
};

// A grid with its influence lists, its exact surface and the renderer's scene of it.
struct World {
    Grid grid;
    influence::InfluenceLists lists;
    std::unique_ptr<influence::SurfaceEvaluator> eval;
    std::unique_ptr<render::Scene> scene;
    void init() {
        lists = influence::buildInfluenceLists(grid, {});
        eval = std::make_unique<influence::SurfaceEvaluator>(grid, lists);
        scene = std::make_unique<render::Scene>(grid, lists);
    }
};

// A raster of data/ (or ../shared/data) ingested at a tolerance, with a bathtub flood at waterLevel when given.
inline World fromFile(const std::string& name, double tol, double waterLevel = NAN) {
    World w;
    w.grid = ingestFile(dataFile(name), tol, waterLevel);
    w.init();
    return w;
}

inline World& hef() {  // alpine SRTM with a flood at 2600 m: the bundled demo DEM
    static World w = fromFile("hef_srtm.tif", 0.5, 2600);
    return w;
}
inline World& lidar() {  // 1 m LiDAR, adaptive cells 1..16 m
    static World w = fromFile("lidar1m_minnesota_utm15.tif", 0.25);
    return w;
}
inline World& lidarFlood() {  // the 1 m LiDAR tile flooded at 397 m (its range is 379.7 - 410.8 m: shores everywhere)
    static World w = fromFile("lidar1m_minnesota_utm15.tif", 0.25, 397);
    return w;
}

// Local surface height at a world position, or nullopt.
inline std::optional<double> exactAt(const World& w, double xLocal, double yLocal) {
    return w.eval->value(xLocal, yLocal, {});
}

struct HitCheck {
    size_t hits = 0, checked = 0, bad = 0;
    size_t unclaimed = 0;  // hits next to a hole or the edge, where bilinearBound makes no claim: not checked
    double worstRatio = 0;
};

// Every hit pixel lies on the exact surface within its cascade's bound (for a blended pixel, the
// larger of the two cascades' texels and twice the bound: the blend is a convex combination of two
// points each within their bound, on a ray at a small angle to the surface). Hits on the terrain block's
// walls (issue 11) are not on the surface: badWalls() (render_hits_test) checks those.
inline HitCheck checkHits(const World& w, const render::Frame& f, const render::Timings& t, size_t stride) {
    HitCheck hc;
    const auto water = w.scene->hasWater() ? influence::Layer::byName(w.grid, "water_surface") : influence::Layer{};
    for (size_t i = 0; i < f.distanceM.size(); i += stride) {
        EXPECT_FALSE(std::isnan(f.distanceM[i]));
        if (!std::isfinite(f.distanceM[i])) continue;
        ++hc.hits;
        if (f.wall[i] != 0) continue;
        const double x = f.posX[i], y = f.posY[i], z = f.posZ[i];
        EXPECT_TRUE(std::isfinite(x) && std::isfinite(y) && std::isfinite(z));
        EXPECT_NEAR(std::hypot(f.nX[i], f.nY[i], f.nZ[i]), 1.0, 1e-5);
        const int k = int(f.cascade[i]);
        EXPECT_GE(k, 0);
        double s = t.cascades[size_t(k)].texelM;
        double factor = 1;
        if (size_t(k) + 1 < t.cascades.size() && t.cascades[size_t(k) + 1].texelM > s) {
            s = std::max(s, t.cascades[size_t(k) + 1].texelM);
            factor = 2;
        }
        const bool isWater = f.waterDepthM[i] > 0;
        auto exact = w.eval->value(x, y, isWater ? water : influence::Layer{});
        if (!exact) continue;  // at a hole's or the domain's edge
        const std::optional<double> claim = bilinearBound(*w.eval, isWater ? water : influence::Layer{}, x, y, s);
        if (!claim) {
            ++hc.unclaimed;
            continue;
        }
        const double bound = factor * *claim;
        ++hc.checked;
        const double err = std::abs(z - *exact);
        hc.worstRatio = std::max(hc.worstRatio, err / bound);
        if (err > bound) ++hc.bad;
        if (err > 3 * bound && std::getenv("HC_DEBUG_RENDER"))
            std::printf(
                "pixel %zu: cascade %d err %.3f bound %.3f dist %.1f z %.2f exact %.2f water %d depth %.2f "
                "s %.2f\n",
                i, k, err, bound, double(f.distanceM[i]), z, *exact, int(isWater), double(f.waterDepthM[i]), s);
    }
    return hc;
}

inline render::Camera randomCamera(const World& w, std::mt19937_64& rng) {
    const render::Scene& s = *w.scene;
    std::uniform_real_distribution<double> u(0, 1);
    render::Camera c;
    const double x = s.xMin + u(rng) * (s.xMax - s.xMin), y = s.yMin + u(rng) * (s.yMax - s.yMin);
    auto ground = exactAt(w, x, y);
    const double extent = std::max(s.xMax - s.xMin, s.yMax - s.yMin);
    c.xWorld = w.grid.originWorldX + x;
    c.yWorld = w.grid.originWorldY + y;
    // 2 m .. extent/2 up
    c.zWorld = (ground ? *ground : s.zMax) + std::exp(std::log(2.0) + u(rng) * std::log(extent / 2.0));
    c.yawDeg = 360 * u(rng);
    c.pitchDeg = -5 - 80 * u(rng);
    c.fovYDeg = 30 + 40 * u(rng);
    c.width = 96;
    c.height = 64;
    return c;
}

// The overview camera of w at 320 x 200, and its three cascades of 256^2 texels.
inline std::pair<render::detail::FrameSetup, render::CascadeFit> overviewFit(World& w) {
    const render::Camera c = render::overviewCamera(*w.scene, 320, 200);
    const render::detail::FrameSetup setup = render::detail::setUpFrame(*w.scene, c);
    return {setup, render::fitCascades(setup.view, 3, 256)};
}

// ---- frames and cameras of the extremes (docs/design.md section 8), used since by most of the tests ----

inline render::Frame renderWith(const World& w, render::Camera c, render::Timings& t, int cascades = 3) {
    render::RenderOptions o;
    o.texelsPerSide = 256;
    o.cascades = cascades;
    return render::renderFrame(*w.scene, c, o, t);
}

// A camera `height` above the surface at the middle of w's domain, pitched by `pitch`, 64 x 48.
inline render::Camera above(const World& w, double height, double pitch) {
    render::Camera c;
    const double x = 0.5 * (w.scene->xMin + w.scene->xMax), y = 0.5 * (w.scene->yMin + w.scene->yMax);
    c.xWorld = w.grid.originWorldX + x;
    c.yWorld = w.grid.originWorldY + y;
    c.zWorld = exactAt(w, x, y).value_or(w.scene->zMax) + height;
    c.pitchDeg = pitch;
    c.fovYDeg = 40;
    c.width = 64;
    c.height = 48;
    return c;
}

}  // namespace hc::test
