// tests/render_gl_world.h: what the GL backend's tests share: the worlds (real DEMs with their GL renderer), the
// fixtures, HC_REQUIRE_GL, and the comparison of a GL frame with the CPU's (render_gl_test.cpp,
// render_gl_out_of_core_test.cpp).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <optional>
#include <random>
#include <tuple>
#include <utility>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/pyramid.h"
#include "heightcast/influence/surface.h"
#include "heightcast/ingest/ingest.h"
#include "heightcast/render/gl/gl_renderer.h"
#include "heightcast/render/gpu_layout.h"
#include "heightcast/render/image_io.h"
#include "heightcast/render/renderer.h"
#include "heightcast/render/detail/frame.h"
#include "image_compare.h"
#include "same_hits.h"
#include "surface_bound.h"
#include "temp_dir.h"
#include "test_data.h"
#include "test_grids.h"

namespace hc::test::gl {

using namespace hc::render;
namespace gpu = hc::render::gpu;

using namespace hc::render;
namespace gpu = hc::render::gpu;

struct World {
    hc::Grid grid;
    hc::influence::InfluenceLists lists;
    std::unique_ptr<Scene> scene;
    std::unique_ptr<GlRenderer> gl;
    std::string glError;  // why no GL renderer could be made
    void init() {
        lists = hc::influence::buildInfluenceLists(grid, {});
        scene = std::make_unique<Scene>(grid, lists);
        try {
            gl = GlRenderer::headless(*scene);
        } catch (const hc::Error& e) {
            glError = e.what();
        }
    }
};

// The suites, each test's files (grid files) in a directory of its own.
class RenderGl : public hc::test::TempDirTest {
protected:
    RenderGl() : TempDirTest("hc_render_gl_") {}
};
class RenderGlWater : public hc::test::TempDirTest {
protected:
    RenderGlWater() : TempDirTest("hc_render_gl_water_") {}
};

inline bool skipWanted() {
    const char* v = std::getenv("HC_GL_TESTS");
    return v && std::string(v) == "skip";
}

// Ends the test where there is no GL renderer: a failure, or a skip where HC_GL_TESTS=skip.
#define HC_REQUIRE_GL(w)                                                                                        \
    if (!(w).gl) {                                                                                              \
        if (skipWanted()) {                                                                                     \
            GTEST_SKIP() << "no OpenGL 4.3 context (HC_GL_TESTS=skip): " << (w).glError;                        \
        }                                                                                                       \
        FAIL() << "no OpenGL 4.3 context: " << (w).glError << " (set HC_GL_TESTS=skip where that is expected)"; \
    }

inline World& hef() {  // alpine SRTM, bathtub flood at 2600 m (the bundled demo DEM, as in render_world.h)
    static World w = [] {
        World x;
        x.grid = hc::test::ingestFile(hc::test::dataFile("hef_srtm.tif"), 0.5, 2600);
        x.init();
        return x;
    }();
    return w;
}
inline World& lidar() {  // 1 m LiDAR, adaptive cells 1..16 m
    static World w = [] {
        World x;
        x.grid = hc::test::ingestFile(hc::test::dataFile("lidar1m_minnesota_utm15.tif"), 0.25);
        x.init();
        return x;
    }();
    return w;
}

// ------------------------------------------------------------------------- CPU against GL

struct Comparison {
    size_t pixels = 0, agree = 0, bothHit = 0, depthOk = 0, nonFinite = 0;
    double psnr = 0, worstDepthRatio = 0, medianRelDepth = 0;
    std::string diffPng;
};

// Depth tolerance for a hit at distance t [m], derived from float on the GPU (the CPU casts in double):
// t is a float sum of steps along the ray, good to a few ulps (1.2e-7 relative each); the surface height
// at the hit carries the float rounding of the approximation and of the bilinear intersection, about
// 1e-7 of the elevation (hef: 4 mm at 3800 m), which a ray at elevation angle a turns into a depth error
// of that over sin(a). With 1e-5 * t we allow rays down to about 1/50 rad at the distances these cameras
// see (100 m .. 30 km), plus 1 cm for the texel-scale rounding near the camera. Rays grazing more than that
// (silhouettes) are the outliers the 0.5 % allowance is for.
inline double depthTolerance(double t) { return 1e-5 * t + 0.01; }

inline Comparison compare(const Frame& cpu, const Frame& gl, const std::string& name) {
    Comparison c;
    c.pixels = size_t(cpu.width) * size_t(cpu.height);
    std::vector<double> rel;
    Frame diff = cpu;
    for (size_t i = 0; i < c.pixels; ++i) {
        const bool hc = std::isfinite(cpu.distanceM[i]), hg = std::isfinite(gl.distanceM[i]);
        for (const auto* v : {&gl.posX, &gl.posY, &gl.posZ, &gl.nX, &gl.nY, &gl.nZ, &gl.waterDepthM, &gl.cascade})
            if (!std::isfinite((*v)[i])) ++c.nonFinite;
        if (std::isnan(gl.distanceM[i]) || (std::isinf(gl.distanceM[i]) && gl.distanceM[i] < 0)) ++c.nonFinite;
        uint8_t* d = &diff.rgb[i * 3];
        for (int k = 0; k < 3; ++k)
            d[k] =
                uint8_t(std::min(255, 8 * std::abs(int(cpu.rgb[i * 3 + size_t(k)]) - int(gl.rgb[i * 3 + size_t(k)]))));
        if (hc == hg)
            ++c.agree;
        else
            d[0] = 255, d[1] = 0, d[2] = 255;  // hit/miss disagreement: magenta
        if (hc && hg) {
            ++c.bothHit;
            const double t = cpu.distanceM[i], err = std::abs(double(gl.distanceM[i]) - t);
            rel.push_back(err / t);
            c.worstDepthRatio = std::max(c.worstDepthRatio, err / depthTolerance(t));
            if (err <= depthTolerance(t))
                ++c.depthOk;
            else
                d[0] = 255, d[1] = 255, d[2] = 0;  // depth beyond the tolerance: yellow
        }
    }
    if (!rel.empty()) {
        std::nth_element(rel.begin(), rel.begin() + std::ptrdiff_t(rel.size() / 2), rel.end());
        c.medianRelDepth = rel[rel.size() / 2];
    }
    c.psnr = hc::test::psnr(cpu, gl);
    const bool bad =
        c.agree * 1000 < c.pixels * 995 || c.depthOk * 1000 < c.bothHit * 995 || c.psnr < 35 || c.nonFinite > 0;
    if (bad) {
        c.diffPng = (std::filesystem::path(testing::TempDir()) / ("gl_vs_cpu_" + name + ".png")).string();
        writePng(diff, c.diffPng);
        writePng(gl, (std::filesystem::path(testing::TempDir()) / ("gl_" + name + ".png")).string());
        writePng(cpu, (std::filesystem::path(testing::TempDir()) / ("cpu_" + name + ".png")).string());
    }
    return c;
}

// The CPU's frame `cpu` and the GL backend's `gl` of the same scene, camera and options show the same picture.
inline void expectSameFrames(const Frame& cpu, const Frame& gl, const Timings& tc, const Timings& tg,
                             const std::string& name, bool mustSeeTerrain = true) {
    const Comparison c = compare(cpu, gl, name);
    const double agree = double(c.agree) / double(c.pixels),
                 depthOk = c.bothHit ? double(c.depthOk) / double(c.bothHit) : 1.0;
    std::printf(
        "[ %s ] hit/miss agree %.4f%%, depth within tolerance %.4f%% of %zu (median |dt|/t %.2e, worst %.1fx "
        "tolerance), PSNR %.2f dB\n",
        name.c_str(), 100 * agree, 100 * depthOk, c.bothHit, c.medianRelDepth, c.worstDepthRatio, c.psnr);
    const std::string where =
        c.diffPng.empty() ? "" : " (diff image: " + c.diffPng + ", magenta = hit/miss, yellow = depth)";
    if (mustSeeTerrain) {
        EXPECT_GT(c.bothHit, c.pixels / 4) << name << ": the camera should see the terrain" << where;
    } else {
        EXPECT_GT(c.bothHit, 0u) << name << where;
        EXPECT_LT(c.bothHit, c.pixels) << name << ": some rays go into the holes" << where;
    }
    EXPECT_GE(agree, 0.995) << name << ": hit/miss agree on " << c.agree << " of " << c.pixels << where;
    EXPECT_GE(depthOk, 0.995) << name << ": depth within 1e-5 t + 1 cm on " << c.depthOk << " of " << c.bothHit
                              << where;
    EXPECT_GE(c.psnr, 35.0) << name << where;
    EXPECT_EQ(c.nonFinite, 0u) << name << ": NaN or infinite position/normal/depth values" << where;
    // The same work: the Gaussians evaluated agree exactly (the same visible texels, the same lists).
    ASSERT_EQ(tc.cascades.size(), tg.cascades.size());
    for (size_t k = 0; k < tc.cascades.size(); ++k)
        EXPECT_EQ(tc.cascades[k].gaussians, tg.cascades[k].gaussians) << name << " cascade " << k;
    const uint64_t hitsGl =
        uint64_t(std::count_if(gl.distanceM.begin(), gl.distanceM.end(), [](float d) { return std::isfinite(d); }));
    EXPECT_EQ(tg.hits, hitsGl) << "the hit counter counts the hits read back";
}

inline void expectSame(World& w, const Camera& cam, const std::string& name, const RenderOptions& o = {},
                       bool mustSeeTerrain = true) {
    Timings tc, tg;
    const Frame cpu = renderFrame(*w.scene, cam, o, tc);
    w.gl->forgetCascades();  // both from scratch: the same work (the Gaussians) is compared too
    const Frame gl = w.gl->render(cam, o, tg);
    expectSameFrames(cpu, gl, tc, tg, name, mustSeeTerrain);
}

inline Camera lowOblique(const Scene& s, int w, int h) {
    Camera c;
    const double cx = 0.5 * (s.xMin + s.xMax), ey = s.yMin + 0.15 * (s.yMax - s.yMin);
    const auto& g = s.grid();
    c.xWorld = g.originWorldX + cx;
    c.yWorld = g.originWorldY + ey;
    c.zWorld = s.zMax + 0.02 * (s.xMax - s.xMin);
    c.yawDeg = 15, c.pitchDeg = -8, c.fovYDeg = 50, c.width = w, c.height = h;
    return c;
}
inline Camera straightDown(const Scene& s, int w, int h) {
    Camera c;
    const auto& g = s.grid();
    c.xWorld = g.originWorldX + 0.5 * (s.xMin + s.xMax);
    c.yWorld = g.originWorldY + 0.5 * (s.yMin + s.yMax);
    c.zWorld = s.zMax + 0.4 * (s.xMax - s.xMin);
    c.yawDeg = 0, c.pitchDeg = -90, c.fovYDeg = 40, c.width = w, c.height = h;
    return c;
}

inline RenderOptions smallOptions() {
    RenderOptions o;
    o.texelsPerSide = 512;  // keeps the CPU reference and llvmpipe quick; the stages are the same
    return o;
}

}  // namespace hc::test::gl
