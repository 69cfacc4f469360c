// The OpenGL compute backend against the CPU backend (DESIGN.md section 5: "tested against each
// other"): the shared std430 layouts as the driver sees them, the same pixels hit at the same depth
// with the same colours on real DEMs from several cameras, finite outputs, a 1e7 m shifted grid, and
// shader failures reported with the driver's log.
//
// The tests run headless (EGL: a GPU device where there is one, else Mesa's surfaceless llvmpipe). Where no OpenGL
// 4.3 context can be had they fail, unless HC_GL_TESTS=skip says that is expected.
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
#include <unistd.h>

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
#include "../render/src/textures.h"
#include "test_data.h"
#include "same_hits.h"
#include "test_grids.h"

namespace {

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

bool skipWanted() {
    const char* v = std::getenv("HC_GL_TESTS");
    return v && std::string(v) == "skip";
}

// Ends the test where there is no GL renderer: a failure, or a skip where HC_GL_TESTS=skip.
#define HC_REQUIRE_GL(w)                                                                                  \
    if (!(w).gl) {                                                                                        \
        if (skipWanted()) {                                                                               \
            GTEST_SKIP() << "no OpenGL 4.3 context (HC_GL_TESTS=skip): " << (w).glError;                  \
        }                                                                                                 \
        FAIL() << "no OpenGL 4.3 context: " << (w).glError << " (set HC_GL_TESTS=skip where that is expected)"; \
    }

World& hef() {  // alpine SRTM, bathtub flood at 2600 m (the bundled demo DEM, as in render_test)
    static World w = [] {
        World x;
        x.grid = hc::test::ingestFile(hc::test::dataFile("hef_srtm.tif"), 0.5, 2600);
        x.init();
        return x;
    }();
    return w;
}
World& lidar() {  // 1 m LiDAR, adaptive cells 1..16 m
    static World w = [] {
        World x;
        x.grid = hc::test::ingestFile(hc::test::dataFile("lidar1m_minnesota_utm15.tif"), 0.25);
        x.init();
        return x;
    }();
    return w;
}

// ------------------------------------------------------------------------------------ layouts

TEST(RenderGl, Std430LayoutsAgreeWithTheCppStructs) {
    World& w = lidar();
    HC_REQUIRE_GL(w);
    const GlRenderer& gl = *w.gl;
    int checked = 0;
    auto expectAt = [&](const char* program, const std::string& name, long expected, long stride = -1) {
        const auto l = gl.bufferVariableLayout(program, name);
        ASSERT_GE(l.offset, 0) << program << ": the driver has no buffer variable " << name;
        EXPECT_EQ(l.offset, expected) << program << ": offset of " << name;
        if (stride >= 0) {
            EXPECT_EQ(l.topLevelArrayStride, stride) << program << ": top-level array stride of " << name;
        }
        ++checked;
    };
    // GpuFrame and GpuCascade inside FrameBlock, as the shading program (which reads most of them) sees them.
    const long cas = long(offsetof(gpu::FrameBlock, cascades));
#define HC_FRAME(m) expectAt("shade", "frame." #m, long(offsetof(gpu::GpuFrame, m)))
#define HC_FRAME_ARRAY(m) expectAt("shade", "frame." #m "[0]", long(offsetof(gpu::GpuFrame, m)))
    HC_FRAME(eyeX), HC_FRAME(eyeY), HC_FRAME(finestM), HC_FRAME(domainM), HC_FRAME(eyeZ), HC_FRAME(tanHalfX), HC_FRAME(tanHalfY);
    HC_FRAME(nearM), HC_FRAME(farM), HC_FRAME(dirX), HC_FRAME(dirY), HC_FRAME(tail);
    HC_FRAME_ARRAY(forward), HC_FRAME_ARRAY(right), HC_FRAME_ARRAY(up), HC_FRAME_ARRAY(sun);
    HC_FRAME(width), HC_FRAME(height), HC_FRAME(cascades), HC_FRAME(hasWater), HC_FRAME(cellCount), HC_FRAME(rootLevel);
    HC_FRAME(indexChunkShift);
    HC_FRAME(minDepthM), HC_FRAME(fogDistM), HC_FRAME(elevationMin), HC_FRAME(zRange), HC_FRAME(dRange), HC_FRAME(pixelAngle);
    HC_FRAME(colorMode), HC_FRAME(cellOutlines), HC_FRAME(legendRamp), HC_FRAME(legendX0), HC_FRAME(legendY0);
    HC_FRAME(legendBarW), HC_FRAME(legendBarH), HC_FRAME(legendScale), HC_FRAME(labelHiLen), HC_FRAME(labelLoLen);
    HC_FRAME_ARRAY(labelHi), HC_FRAME_ARRAY(labelLo), HC_FRAME_ARRAY(elevationRamp), HC_FRAME_ARRAY(depthRamp);
    HC_FRAME_ARRAY(skyHorizon), HC_FRAME_ARRAY(skyZenith), HC_FRAME_ARRAY(dryColor), HC_FRAME(zFloor), HC_FRAME_ARRAY(wallColor), HC_FRAME(beamTile);
#define HC_CASCADE(m) expectAt("raycast", "cascades[0]." #m, cas + long(offsetof(gpu::GpuCascade, m)), long(sizeof(gpu::GpuCascade)))
#define HC_CASCADE_ARRAY(m) expectAt("raycast", "cascades[0]." #m "[0]", cas + long(offsetof(gpu::GpuCascade, m)), long(sizeof(gpu::GpuCascade)))
    HC_CASCADE(x0Eye), HC_CASCADE(y0Eye), HC_CASCADE(texelF), HC_CASCADE(n), HC_CASCADE(splitNear), HC_CASCADE(splitFar);
    HC_CASCADE(farWithOverlap), HC_CASCADE(levels), HC_CASCADE(terrainOffset), HC_CASCADE(waterOffset), HC_CASCADE(depthOffset);
    HC_CASCADE_ARRAY(terrainMip), HC_CASCADE_ARRAY(waterMip), HC_CASCADE_ARRAY(mipSide);
    // The double members and the visibility offset are read by the approximation.
    for (auto [name, off] : {std::pair{"x0", offsetof(gpu::GpuCascade, x0)}, {"y0", offsetof(gpu::GpuCascade, y0)},
                             {"texelM", offsetof(gpu::GpuCascade, texelM)}, {"visibleOffset", offsetof(gpu::GpuCascade, visibleOffset)}})
        expectAt("approximate", std::string("cascades[0].") + name, cas + long(off), long(sizeof(gpu::GpuCascade)));
#define HC_CELL(m) expectAt("approximate", "cells[0]." #m, long(offsetof(gpu::GpuCell, m)), long(sizeof(gpu::GpuCell)))
    HC_CELL(ix), HC_CELL(iy), HC_CELL(level), HC_CELL(listBegin), HC_CELL(a), HC_CELL(r2), HC_CELL(z), HC_CELL(depth);
#define HC_PIXEL(m) expectAt("shade", "pixels[0]." #m, long(offsetof(gpu::GpuPixel, m)), long(sizeof(gpu::GpuPixel)))
    HC_PIXEL(t), HC_PIXEL(relX), HC_PIXEL(relY), HC_PIXEL(relZ), HC_PIXEL(nx), HC_PIXEL(ny), HC_PIXEL(nz), HC_PIXEL(depth);
    HC_PIXEL(cascade), HC_PIXEL(water), HC_PIXEL(wall);
    // Whole sizes: the frame block, and (through the unsized arrays' strides above) each struct.
    EXPECT_EQ(gl.bufferBlockSize("shade", "FrameBlock"), long(sizeof(gpu::FrameBlock)));
    EXPECT_EQ(gl.bufferBlockSize("raycast", "FrameBlock"), long(sizeof(gpu::FrameBlock)));
    EXPECT_GE(checked, 80);
}

// ------------------------------------------------------------------------- CPU against GL

struct Comparison {
    size_t pixels = 0, agree = 0, bothHit = 0, depthOk = 0, nonFinite = 0;
    double psnr = 0, worstDepthRatio = 0, medianRelDepth = 0;
    std::string diffPng;
};

double psnrOf(const Frame& a, const Frame& b) {
    double se = 0;
    for (size_t i = 0; i < a.rgb.size(); ++i) se += std::pow(double(a.rgb[i]) - double(b.rgb[i]), 2);
    const double mse = se / double(a.rgb.size());
    return mse == 0 ? 99.0 : 10 * std::log10(255.0 * 255.0 / mse);
}

// Depth tolerance for a hit at distance t [m], derived from float on the GPU (the CPU casts in double):
// t is a float sum of steps along the ray, good to a few ulps (1.2e-7 relative each); the surface height
// at the hit carries the float rounding of the approximation and of the bilinear intersection, about
// 1e-7 of the elevation (hef: 4 mm at 3800 m), which a ray at elevation angle a turns into a depth error
// of that over sin(a). With 1e-5 * t we allow rays down to about 1/50 rad at the distances these cameras
// see (100 m .. 30 km), plus 1 cm for the texel-scale rounding near the camera. Rays grazing more than that
// (silhouettes) are the outliers the 0.5 % allowance is for.
double depthTolerance(double t) { return 1e-5 * t + 0.01; }

Comparison compare(const Frame& cpu, const Frame& gl, const std::string& name) {
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
        for (int k = 0; k < 3; ++k) d[k] = uint8_t(std::min(255, 8 * std::abs(int(cpu.rgb[i * 3 + size_t(k)]) - int(gl.rgb[i * 3 + size_t(k)]))));
        if (hc == hg) ++c.agree;
        else d[0] = 255, d[1] = 0, d[2] = 255;  // hit/miss disagreement: magenta
        if (hc && hg) {
            ++c.bothHit;
            const double t = cpu.distanceM[i], err = std::abs(double(gl.distanceM[i]) - t);
            rel.push_back(err / t);
            c.worstDepthRatio = std::max(c.worstDepthRatio, err / depthTolerance(t));
            if (err <= depthTolerance(t)) ++c.depthOk;
            else d[0] = 255, d[1] = 255, d[2] = 0;  // depth beyond the tolerance: yellow
        }
    }
    if (!rel.empty()) {
        std::nth_element(rel.begin(), rel.begin() + std::ptrdiff_t(rel.size() / 2), rel.end());
        c.medianRelDepth = rel[rel.size() / 2];
    }
    c.psnr = psnrOf(cpu, gl);
    const bool bad = c.agree * 1000 < c.pixels * 995 || c.depthOk * 1000 < c.bothHit * 995 || c.psnr < 35 || c.nonFinite > 0;
    if (bad) {
        c.diffPng = (std::filesystem::path(testing::TempDir()) / ("gl_vs_cpu_" + name + ".png")).string();
        writePng(diff, c.diffPng);
        writePng(gl, (std::filesystem::path(testing::TempDir()) / ("gl_" + name + ".png")).string());
        writePng(cpu, (std::filesystem::path(testing::TempDir()) / ("cpu_" + name + ".png")).string());
    }
    return c;
}

// The CPU's frame `cpu` and the GL backend's `gl` of the same scene, camera and options show the same picture.
void expectSameFrames(const Frame& cpu, const Frame& gl, const Timings& tc, const Timings& tg, const std::string& name, bool mustSeeTerrain = true) {
    const Comparison c = compare(cpu, gl, name);
    const double agree = double(c.agree) / double(c.pixels), depthOk = c.bothHit ? double(c.depthOk) / double(c.bothHit) : 1.0;
    std::printf("[ %s ] hit/miss agree %.4f%%, depth within tolerance %.4f%% of %zu (median |dt|/t %.2e, worst %.1fx tolerance), PSNR %.2f dB\n",
                name.c_str(), 100 * agree, 100 * depthOk, c.bothHit, c.medianRelDepth, c.worstDepthRatio, c.psnr);
    const std::string where = c.diffPng.empty() ? "" : " (diff image: " + c.diffPng + ", magenta = hit/miss, yellow = depth)";
    if (mustSeeTerrain) {
        EXPECT_GT(c.bothHit, c.pixels / 4) << name << ": the camera should see the terrain" << where;
    } else {
        EXPECT_GT(c.bothHit, 0u) << name << where;
        EXPECT_LT(c.bothHit, c.pixels) << name << ": some rays go into the holes" << where;
    }
    EXPECT_GE(agree, 0.995) << name << ": hit/miss agree on " << c.agree << " of " << c.pixels << where;
    EXPECT_GE(depthOk, 0.995) << name << ": depth within 1e-5 t + 1 cm on " << c.depthOk << " of " << c.bothHit << where;
    EXPECT_GE(c.psnr, 35.0) << name << where;
    EXPECT_EQ(c.nonFinite, 0u) << name << ": NaN or infinite position/normal/depth values" << where;
    // The same work: the Gaussians evaluated agree exactly (the same visible texels, the same lists).
    ASSERT_EQ(tc.cascades.size(), tg.cascades.size());
    for (size_t k = 0; k < tc.cascades.size(); ++k) EXPECT_EQ(tc.cascades[k].gaussians, tg.cascades[k].gaussians) << name << " cascade " << k;
    const uint64_t hitsGl = uint64_t(std::count_if(gl.distanceM.begin(), gl.distanceM.end(), [](float d) { return std::isfinite(d); }));
    EXPECT_EQ(tg.hits, hitsGl) << "the hit counter counts the hits read back";
}

void expectSame(World& w, const Camera& cam, const std::string& name, const RenderOptions& o = {}, bool mustSeeTerrain = true) {
    Timings tc, tg;
    const Frame cpu = renderFrame(*w.scene, cam, o, tc);
    w.gl->forgetCascades();  // both from scratch: the same work (the Gaussians) is compared too
    const Frame gl = w.gl->render(cam, o, tg);
    expectSameFrames(cpu, gl, tc, tg, name, mustSeeTerrain);
}

Camera lowOblique(const Scene& s, int w, int h) {
    Camera c;
    const double cx = 0.5 * (s.xMin + s.xMax), ey = s.yMin + 0.15 * (s.yMax - s.yMin);
    const auto& g = s.grid();
    c.xWorld = g.originWorldX + cx;
    c.yWorld = g.originWorldY + ey;
    c.zWorld = s.zMax + 0.02 * (s.xMax - s.xMin);
    c.yawDeg = 15, c.pitchDeg = -8, c.fovYDeg = 50, c.width = w, c.height = h;
    return c;
}
Camera straightDown(const Scene& s, int w, int h) {
    Camera c;
    const auto& g = s.grid();
    c.xWorld = g.originWorldX + 0.5 * (s.xMin + s.xMax);
    c.yWorld = g.originWorldY + 0.5 * (s.yMin + s.yMax);
    c.zWorld = s.zMax + 0.4 * (s.xMax - s.xMin);
    c.yawDeg = 0, c.pitchDeg = -90, c.fovYDeg = 40, c.width = w, c.height = h;
    return c;
}

RenderOptions smallOptions() {
    RenderOptions o;
    o.texelsPerSide = 512;  // keeps the CPU reference and llvmpipe quick; the stages are the same
    return o;
}

TEST(RenderGl, SameAsCpuOnTheAlpineDemFromFourCameras) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    ASSERT_TRUE(w.scene->hasWater());
    const Scene& s = *w.scene;
    expectSame(w, overviewCamera(s, 320, 200), "hef_overview", smallOptions());
    expectSame(w, lowOblique(s, 320, 200), "hef_oblique_low", smallOptions());
    expectSame(w, straightDown(s, 240, 240), "hef_straight_down", smallOptions());
    // Over the deepest water, looking down at it from 1.5 km south and 800 m above: a water picture.
    const hc::Grid& g = w.grid;
    const int layer = s.waterLayer();
    size_t deepest = 0;
    for (size_t i = 0; i < g.cellCount(); ++i)
        if (g.values[size_t(layer)][i] > g.values[size_t(layer)][deepest]) deepest = i;
    double x = 0, y = 0;
    g.cellCenterLocal(deepest, x, y);
    const double z = g.values[0][deepest] + g.values[size_t(layer)][deepest];
    const Camera water = Camera::lookAt({g.originWorldX + x, g.originWorldY + y - 1500, z + 800}, {g.originWorldX + x, g.originWorldY + y, z}, 50, 320, 200);
    RenderOptions o = smallOptions();
    o.color = ColorMode::WaterDepth;
    expectSame(w, water, "hef_water", o);
    Timings t;
    const Frame f = w.gl->render(water, o, t);
    const size_t wet = size_t(std::count_if(f.waterDepthM.begin(), f.waterDepthM.end(), [](float d) { return d > 0; }));
    EXPECT_GT(wet, f.waterDepthM.size() / 10) << "the water camera sees water";
}

// A world's grid written to a temporary file (removed again when this goes, an assertion's early return too) and its
// surface pyramid: what an out-of-core scene reads.
struct GridOnDisk {
    std::filesystem::path path;
    hc::influence::SurfacePyramid pyramid;
    GridOnDisk(const World& w, const std::string& stem)
        : path(std::filesystem::temp_directory_path() / (stem + "_" + std::to_string(::getpid()) + ".hcg")),
          pyramid(hc::influence::buildSurfacePyramid(w.grid, {})) {
        hc::writeGrid(w.grid, path.string());
    }
    ~GridOnDisk() { std::filesystem::remove(path); }
};

// Out of core (a Scene over the grid file: no cells or lists in memory, as for 100 M cells) the GL backend fills the
// cascades on the CPU as renderFrame() does and casts and shades on the GPU: the same picture as the CPU backend on the
// same scene, the same texels copied from the pyramid, interpolated and summed (the Gaussians counted exactly), with and
// without a pyramid; a moving camera keeps texels from its last frame; cell outlines, which need the cells on the GPU,
// are refused with the file named.
TEST(RenderGl, OutOfCoreFillsTheCascadesOnTheCpuAndCastsOnTheGpu) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const GridOnDisk disk(w, "hc_gl_out_of_core");
    const std::filesystem::path& path = disk.path;
    const hc::influence::SurfacePyramid& pyramid = disk.pyramid;
    {
        const hc::GridRegionReader file(path.string());
        for (const hc::influence::SurfacePyramid* p : {static_cast<const hc::influence::SurfacePyramid*>(nullptr), &pyramid}) {
            const std::string tag = p ? "with the pyramid" : "without a pyramid";
            const Scene scene(file, {}, p);
            ASSERT_TRUE(scene.outOfCore());
            const std::unique_ptr<GlRenderer> gl = GlRenderer::headless(scene);
            const RenderOptions o = smallOptions();
            RenderOptions coarse = o;
            coarse.texelsPerSide = 128;  // texels as large as the cells (hef's are 64-254 m): copies where a pyramid is
            Camera moving = lowOblique(scene, 320, 200);
            uint64_t copied = 0, interpolated = 0, read = 0;
            for (const auto& [cam, opt] : {std::pair{overviewCamera(scene, 320, 200), o}, {lowOblique(scene, 320, 200), o},
                                           {overviewCamera(scene, 320, 200), coarse}}) {
                Timings tc, tg;
                const Frame cpu = renderFrame(scene, cam, opt, tc);
                gl->forgetCascades();  // fresh as the CPU's frame (the counts below): the coarse frame would keep texels of the one before
                const Frame g = gl->render(cam, opt, tg);
                expectSameFrames(cpu, g, tc, tg, "hef_out_of_core " + tag);
                for (size_t k = 0; k < tc.cascades.size(); ++k) {
                    EXPECT_EQ(tc.cascades[k].visibleTexels, tg.cascades[k].visibleTexels) << tag << " cascade " << k;
                    EXPECT_EQ(tc.cascades[k].pyramidTexels, tg.cascades[k].pyramidTexels) << tag << " cascade " << k;
                    EXPECT_EQ(tc.cascades[k].pyramidInterpolated, tg.cascades[k].pyramidInterpolated) << tag << " cascade " << k;
                    EXPECT_EQ(tc.cascades[k].texelM, tg.cascades[k].texelM) << tag << " cascade " << k << ": the pyramid's ladder";
                    copied += tg.cascades[k].pyramidTexels, interpolated += tg.cascades[k].pyramidInterpolated, read += tg.cascades[k].cellsRead;
                }
                EXPECT_GT(tg.approximationMs, 0.0);
            }
            if (p) {
                EXPECT_GT(copied, 0u) << "the GL backend's cascades copy the pyramid's samples";
                EXPECT_GT(interpolated, 0u) << "and interpolate them where texels are finer";
            } else {
                EXPECT_GT(read, 0u) << "without a pyramid the texels are summed from cells read from the file";
            }
            // The camera moves 20 m between two frames: the second keeps most texels (the first frame after the
            // overview starts afresh) and shows what a fresh CPU frame shows.
            Timings t0, t1, tc;
            (void)gl->render(moving, o, t0);
            moving.xWorld += 20;
            const Frame g = gl->render(moving, o, t1);
            const Frame cpu = renderFrame(scene, moving, o, tc);
            uint64_t kept = 0;
            for (const CascadeStats& cs : t1.cascades) kept += cs.reusedTexels;
            EXPECT_GT(kept, 0u) << tag << ": a moving camera keeps texels from its last frame";
            gl->forgetCascades();
            Timings t2;
            (void)gl->render(moving, o, t2);
            for (const CascadeStats& cs : t2.cascades) EXPECT_EQ(cs.reusedTexels, 0u) << tag << ": forgetCascades() starts afresh";
            const Comparison c = compare(cpu, g, "hef_out_of_core_moved " + tag);
            EXPECT_GE(double(c.agree) / double(c.pixels), 0.995) << tag;
            EXPECT_GE(c.psnr, 35.0) << tag;
            RenderOptions cells = o;
            cells.cellOutlines = true;
            try {
                Timings t;
                (void)gl->render(moving, cells, t);
                ADD_FAILURE() << "cell outlines out of core were not refused";
            } catch (const hc::Error& e) {
                EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
                EXPECT_NE(std::string(e.what()).find("--backend cpu"), std::string::npos) << e.what();
            }
        }
    }
}

// A cascade's textures from the GPU (GlRenderer::cascadeTexturesForTest) against the CPU's, texel by texel: those that
// differ, the first of them, and (counted apart, not as differing) those within a float rounding where the frame
// interpolated texels on the GPU from level 0 (interpolate.comp): its double sums there are fused multiply-adds, the
// CPU's where its compiler fuses them (GCC does for a CPU with FMA), else they may differ in their last bits and round
// to floats one ulp apart. The elevation then within one ulp, the depth (level - elevation) and the water level within
// one ulp of the larger of them each, and the water drawn on one side alone only at the depth threshold. Every other
// texel must be the same bits.
struct TexelDiff {
    size_t differ = 0, first = SIZE_MAX, rounded = 0;
};
TexelDiff diffTextures(const hc::render::detail::CascadeTextures& cpu, const GlRenderer::CascadeTexels& gpu, float minDepth, bool gpuInterpolated) {
    TexelDiff d;
    const auto bits = [](float v) { return std::bit_cast<uint32_t>(v); };
    for (size_t i = 0; i < cpu.terrain.h.size(); ++i) {
        const float z = cpu.terrain.h[i], water = cpu.water.h[i], depth = cpu.depth[i];
        const float gz = gpu.terrain[i], gWater = gpu.water[i], gDepth = gpu.depth[i];
        if (bits(z) == bits(gz) && bits(water) == bits(gWater) && bits(depth) == bits(gDepth)) continue;
        const float scale = std::max({std::abs(z), std::isfinite(water) ? std::abs(water) : 0.0f, 1.0f});
        const float ulp = std::nextafter(scale, INFINITY) - scale, tol = 2 * ulp;
        const bool near = std::abs(z - gz) <= ulp && std::abs(depth - gDepth) <= tol &&
                          (bits(water) == bits(gWater) || (std::isfinite(water) && std::isfinite(gWater) && std::abs(water - gWater) <= tol) ||
                           std::abs(depth - minDepth) <= tol);
        if (near && gpuInterpolated) {
            ++d.rounded;
            continue;
        }
        if (d.differ++ == 0) d.first = i;
    }
    return d;
}

// Out of core the GL backend keeps its cascades on the GPU and uploads only the texels a frame newly sees
// (assemble.comp places them beside the texels kept from the last frame). Over a flight (20 m steps, a 2 km jump that
// keeps part of a cascade or none, steps again, a frame after one that failed half-way, a frame after forgetCascades)
// every frame's textures on the GPU are the CPU's, texel for texel and bit for bit, but for the texels interpolated on
// the GPU from level 0 (interpolate.comp), which may differ by float rounding (below): the reference evaluates each
// cascade on the CPU with the texels it keeps copied from the reference's own last frame, as renderFrame() does with a
// CascadeCache (a texel evaluated afresh may differ from a kept one in its last bit: a few of a frame's do here). A
// 20 m step uploads under a tenth of the bytes of a fresh frame. Fails when a kept texel is shifted by one, when
// assemble.comp leaves the texels outside the rows' spans unwritten (the last frame but one's stay), when a frame keeps
// texels after a failed one (whose cascades, too large for any driver's storage block, failed after the heights
// buffers were swapped: the texels of two frames before), when the kept spans are uploaded again (the bytes), or when
// interpolate.comp takes a sample or weight one off, or leaves a block's texels to the CPU's unwritten ones.
TEST(RenderGl, OutOfCoreKeepsTheCascadesOnTheGpuAndUploadsOnlyNewTexels) {
    namespace detail = hc::render::detail;
    World& w = hef();
    HC_REQUIRE_GL(w);
    const GridOnDisk disk(w, "hc_gl_kept");
    {
        const hc::GridRegionReader file(disk.path.string());
        const Scene scene(file, {}, &disk.pyramid);
        ASSERT_TRUE(scene.outOfCore());
        ASSERT_TRUE(scene.hasWater());
        // Four flights: texels mostly finer than the pyramid's levels (interpolated from level 0 on the GPU where its
        // tiles around are all stored and alike, dry or wet: PyramidTiles::Block; else on the CPU); texels as large as
        // the cells (hef's are 64-254 m), which the pyramid holds, copied on the GPU from its tiles there (the atlas);
        // and both again with an atlas of 40 tiles, fewer than a frame needs: it drops tiles every frame, and copies
        // the tiles and interpolates the blocks it cannot place on the CPU.
        struct Flight {
            int texels;
            uint32_t atlasTiles;
        };
        uint64_t onGpuWithWholeAtlas = 0;
        for (const Flight flight : {Flight{512, 0}, Flight{128, 0}, Flight{128, 40}, Flight{512, 40}}) {
            const uint32_t atlasTiles = flight.atlasTiles;
            GlRenderer::limitAtlasForTest(atlasTiles);
            const std::unique_ptr<GlRenderer> gl = GlRenderer::headless(scene);
            GlRenderer::limitAtlasForTest(0);
            RenderOptions o = smallOptions();
            o.texelsPerSide = flight.texels;
            Camera cam = lowOblique(scene, 320, 200);
            // East (x) and up (z) [m] before each frame. The climbing frames grow the cascades: with the pyramid a cascade's
            // side follows its extent in steps of 64 texels, so some keep the texels of a last-frame cascade of another side.
            struct Move {
                double dx, dz;
            };
            const Move moves[] = {{0, 0},   {20, 0},  {20, 0},  {2000, 0}, {20, 0},  {-2000, 0}, {20, 0},  {20, 0},  {20, 0},
                                  {30, 40}, {30, 40}, {30, 40}, {30, 40},  {30, 40}, {30, 40},   {30, 40}, {30, 40}, {0, 0}};
            const size_t failedBefore = 8;  // a frame that fails after the swap comes before this one
            int sideChanges = 0;
            uint64_t freshBytes = 0, onGpuInterpolated = 0, roundedOtherwise = 0, interpolated = 0;
            std::vector<Cascade> lastCascades;  // the reference's last frame
            std::vector<detail::CascadeTextures> lastTextures;
            for (size_t f = 0; f < std::size(moves); ++f) {
                const std::string tag = "frame " + std::to_string(f) + ", " + std::to_string(flight.texels) + " texels" +
                                        (atlasTiles ? ", an atlas of 40 tiles" : "");
                cam.xWorld += moves[f].dx, cam.zWorld += moves[f].dz;
                const bool fresh = f == 0 || f + 1 == std::size(moves) || f == failedBefore;
                if (f == failedBefore) {
                    RenderOptions huge = o;
                    huge.cascades = 4, huge.texelsPerSide = 8192;  // over 2^31 bytes of textures: more than a storage block holds (llvmpipe 128 MiB, NVIDIA 2 GiB)
                    Timings th;
                    EXPECT_THROW((void)gl->render(cam, huge, th), hc::Error) << tag;
                }
                if (fresh) lastCascades.clear(), lastTextures.clear();
                if (fresh && f != failedBefore) gl->forgetCascades();  // after the failure the renderer must start afresh itself
                Timings t;
                (void)gl->render(cam, o, t);
                uint64_t kept = 0, visible = 0;
                for (const CascadeStats& cs : t.cascades) kept += cs.reusedTexels, visible += cs.visibleTexels, interpolated += cs.pyramidInterpolated;
                onGpuInterpolated += t.atlasInterpolated;
                if (fresh) {
                    EXPECT_EQ(kept, 0u) << tag << ": a fresh frame";
                    if (f == 0) freshBytes = t.uploadBytes;
                    if (flight.texels == 128) {
                        EXPECT_GT(t.atlasTexels, 0u) << tag << ": a fresh frame copies texels from the pyramid's tiles on the GPU";
                    }
                    if (f == 0 && flight.texels == 128) {
                        EXPECT_GT(t.atlasTilesUploaded, 0u) << tag;
                        if (atlasTiles) {
                            EXPECT_EQ(t.atlasTilesUploaded, 2 * atlasTiles) << tag << ": every slot of both atlases (elevation, water) taken";
                        }
                    }
                } else if (moves[f].dx == 20 && moves[f].dz == 0) {
                    EXPECT_GT(kept, visible * 9 / 10) << tag << ": a 20 m step keeps most texels";
                    if (!atlasTiles) {  // (an atlas too small uploads its tiles again)
                        EXPECT_LT(t.uploadBytes, freshBytes / 10) << tag << ": and uploads few";
                    }
                }
                // The reference: this frame's cascades on the CPU, each keeping the texels of the last frame's cascade of the
                // same texel size and lattice placed nearest to it, whatever its side (renderer.cpp's reusableCascade).
                const detail::FrameSetup setup = detail::setUpFrame(scene, cam);
                Timings tf;
                const CascadeFit fit = detail::fitFrame(scene, cam, setup, o, tf);
                const std::vector<GlRenderer::CascadeTexels> onGpu = gl->cascadeTexturesForTest();
                ASSERT_EQ(onGpu.size(), fit.cascades.size()) << tag;
                std::vector<detail::CascadeTextures> textures(fit.cascades.size());
                std::vector<bool> taken(lastCascades.size(), false);
                uint64_t keptOnCpu = 0;
                for (size_t k = 0; k < fit.cascades.size(); ++k) {
                    const Cascade& c = fit.cascades[k];
                    ASSERT_EQ(onGpu[k].n, c.empty() ? 0 : c.n) << tag << " cascade " << k;
                    if (c.empty()) continue;
                    std::optional<detail::TexelReuse> reuse;
                    size_t from = 0;
                    for (size_t e = 0; e < lastCascades.size(); ++e) {
                        const Cascade& old = lastCascades[e];
                        if (taken[e] || old.empty() || old.texelM != c.texelM) continue;
                        const double fi = (c.x0 - old.x0) / c.texelM, fj = (c.y0 - old.y0) / c.texelM;
                        if (std::abs(fi - std::round(fi)) >= 1e-6 || std::abs(fj - std::round(fj)) >= 1e-6) continue;
                        const detail::TexelReuse r{&old, &lastTextures[e], int(std::round(fi)), int(std::round(fj))};
                        if (!reuse || std::max(std::abs(r.di), std::abs(r.dj)) < std::max(std::abs(reuse->di), std::abs(reuse->dj))) reuse = r, from = e;
                    }
                    if (reuse) taken[from] = true, sideChanges += reuse->cascade->n != c.n;
                    detail::CascadeTextures& cpu = textures[k];
                    keptOnCpu += detail::approximate(scene, c, cpu, o.waterMinDepthM, 0, reuse ? &*reuse : nullptr, o.pyramidInterpolateLevels).reusedTexels;
                    const TexelDiff d = diffTextures(cpu, onGpu[k], float(o.waterMinDepthM), t.atlasInterpolated > 0);
                    roundedOtherwise += d.rounded;
                    const size_t differ = d.differ, first = d.first;
                    EXPECT_EQ(differ, 0u) << tag << " cascade " << k << ": first at texel " << first << " of " << cpu.terrain.h.size() << " (n " << c.n << ")";
                }
                EXPECT_EQ(keptOnCpu, kept) << tag << ": the GPU kept what the CPU keeps";
                lastCascades = fit.cascades;
                lastTextures = std::move(textures);
            }
            EXPECT_GT(sideChanges, 0) << "no frame kept texels of a cascade of another side: the climb checks nothing";
            std::printf("%d cascades kept texels of a last-frame cascade of another side\n", sideChanges);
            if (flight.texels == 512) {  // texels finer than level 0: those in blocks of level-0 tiles interpolated on the GPU
                EXPECT_GT(onGpuInterpolated, 0u) << "atlas " << atlasTiles;
                // The rest where level 0 is not stored (hef's finest cells are few), from levels above, on the CPU.
                EXPECT_LT(onGpuInterpolated, interpolated) << "atlas " << atlasTiles;
                if (!atlasTiles) onGpuWithWholeAtlas = onGpuInterpolated;
                else EXPECT_LT(onGpuInterpolated, onGpuWithWholeAtlas) << "an atlas of 40 tiles leaves blocks to the CPU";
            }
            std::printf("%d texels, atlas %u: %llu texels interpolated, %llu on the GPU, %llu of them rounded otherwise than on the CPU\n",
                        flight.texels, atlasTiles, (unsigned long long)interpolated, (unsigned long long)onGpuInterpolated,
                        (unsigned long long)roundedOtherwise);
        }
    }
}

// A later water step out of core (the first step's pyramid for the terrain, the step's own water pyramid, as
// hc-influence --step builds it: influence::buildWaterPyramid): the texels finer than level 0 that the GL backend
// interpolates on the GPU from level 0's terrain and water tiles give the CPU's textures (diffTextures), wet ones among
// them. Fails when interpolate.comp drops the water, or when the blocks' kinds are taken from the base's water (every
// block dry) instead of the step's.
TEST(RenderGlWater, OutOfCoreWaterStepInterpolatedOnTheGpuAsOnTheCpu) {
    namespace detail = hc::render::detail;
    World& w = hef();
    HC_REQUIRE_GL(w);
    const std::filesystem::path path = std::filesystem::temp_directory_path() / ("hc_gl_steps_" + std::to_string(::getpid()) + ".hcg");
    hc::ingest::Options in;
    in.input = hc::test::dataFile("hef_srtm.tif");
    in.toleranceM = 1;
    in.maxCellM = 512;
    in.water = hc::ingest::WaterSource::Level;
    in.waterLevelsM = {1900, 2000, 2800};
    hc::ingest::LoadReport rep;
    hc::ingest::ingestToFile(in, path.string(), rep);
    struct Remove {
        std::filesystem::path p;
        ~Remove() { std::filesystem::remove(p); }
    } remove{path};
    const hc::influence::KernelParams params{};
    const hc::influence::SurfacePyramid base = hc::influence::buildSurfacePyramid(hc::readGrid(path.string(), nullptr, 0), params);
    const hc::influence::SurfacePyramid water = hc::influence::buildWaterPyramid(hc::readGrid(path.string(), nullptr, 2), params);
    const hc::GridRegionReader file(path.string(), 2);
    const Scene scene(file, params, &base, &water);
    ASSERT_TRUE(scene.outOfCore() && scene.hasWater());
    const std::unique_ptr<GlRenderer> gl = GlRenderer::headless(scene);
    RenderOptions o = smallOptions();
    o.texelsPerSide = 512;  // a near cascade finer than level 0
    uint64_t onGpu = 0, wetInterpolated = 0, rounded = 0;
    for (const Camera& cam : {overviewCamera(scene, 320, 200), lowOblique(scene, 320, 200)}) {
        gl->forgetCascades();
        Timings t;
        (void)gl->render(cam, o, t);
        onGpu += t.atlasInterpolated;
        const detail::FrameSetup setup = detail::setUpFrame(scene, cam);
        Timings tf;
        const CascadeFit fit = detail::fitFrame(scene, cam, setup, o, tf);
        const std::vector<GlRenderer::CascadeTexels> textures = gl->cascadeTexturesForTest();
        ASSERT_EQ(textures.size(), fit.cascades.size());
        for (size_t k = 0; k < fit.cascades.size(); ++k) {
            const Cascade& c = fit.cascades[k];
            if (c.empty()) continue;
            detail::CascadeTextures cpu;
            const detail::ApproximationWork work = detail::approximate(scene, c, cpu, o.waterMinDepthM, 0, nullptr, o.pyramidInterpolateLevels);
            const TexelDiff d = diffTextures(cpu, textures[k], float(o.waterMinDepthM), t.atlasInterpolated > 0);
            EXPECT_EQ(d.differ, 0u) << "cascade " << k << ": first at texel " << d.first << " (n " << c.n << ")";
            rounded += d.rounded;
            if (work.pyramidLevel < 0 && work.pyramidInterpolated > 0)
                for (size_t i = 0; i < cpu.water.h.size(); ++i) wetInterpolated += std::isfinite(cpu.water.h[i]) && cpu.depth[i] > 0;
        }
    }
    std::printf("%llu texels interpolated on the GPU, %llu of them rounded otherwise than on the CPU; %llu wet texels in cascades finer than level 0\n",
                (unsigned long long)onGpu, (unsigned long long)rounded, (unsigned long long)wetInterpolated);
    EXPECT_GT(onGpu, 0u);
    EXPECT_GT(wetInterpolated, 0u) << "the flood must lie in the fine cascades for the comparison to mean anything";
}

// In memory the GL backend keeps its cascades on the GPU too (the incremental cascades of DESIGN.md section 6): a
// moving camera's frame sums only the texels it newly sees. Over 20 m steps each frame keeps over 90 % of its visible
// texels and evaluates under a tenth of a fresh frame's Gaussians; its textures are a fresh frame's (the same camera
// after forgetCascades) to 1 mm with no surface at the same texels (a kept texel was summed at a centre computed
// from another frame's lattice origin: equal to double rounding); and its picture is the CPU's. Fails when the kept
// texels are shifted, or summed again (the Gaussians), or when approximate.comp writes outside its spans.
TEST(RenderGl, InMemoryMovingCameraSumsOnlyTheNewTexels) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const RenderOptions o = smallOptions();
    Camera cam = lowOblique(*w.scene, 320, 200);
    w.gl->forgetCascades();
    Timings t0;
    (void)w.gl->render(cam, o, t0);
    uint64_t fresh = 0;
    for (const CascadeStats& cs : t0.cascades) fresh += cs.gaussians;
    ASSERT_GT(fresh, 0u);
    for (int f = 1; f <= 3; ++f) {
        const std::string tag = "frame " + std::to_string(f);
        cam.xWorld += 20;
        Timings t;
        const Frame g = w.gl->render(cam, o, t);
        uint64_t kept = 0, visible = 0, gaussians = 0;
        for (const CascadeStats& cs : t.cascades) kept += cs.reusedTexels, visible += cs.visibleTexels, gaussians += cs.gaussians;
        EXPECT_GT(kept, visible * 9 / 10) << tag;
        EXPECT_LT(gaussians, fresh / 10) << tag;
        const std::vector<GlRenderer::CascadeTexels> moving = w.gl->cascadeTexturesForTest();
        Timings tc;
        const Frame cpu = renderFrame(*w.scene, cam, o, tc);
        const Comparison c = compare(cpu, g, "hef_in_memory_moving");
        EXPECT_GE(double(c.agree) / double(c.pixels), 0.995) << tag;
        EXPECT_GE(c.psnr, 35.0) << tag;
        w.gl->forgetCascades();
        Timings tf;
        (void)w.gl->render(cam, o, tf);
        const std::vector<GlRenderer::CascadeTexels> again = w.gl->cascadeTexturesForTest();
        ASSERT_EQ(moving.size(), again.size()) << tag;
        for (size_t k = 0; k < moving.size(); ++k) {
            ASSERT_EQ(moving[k].n, again[k].n) << tag << " cascade " << k;
            size_t surfaceDiffers = 0;
            double worst = 0;
            for (size_t i = 0; i < moving[k].terrain.size(); ++i) {
                for (const auto& [ma, aa] : {std::pair{&moving[k].terrain, &again[k].terrain}, {&moving[k].water, &again[k].water}}) {
                    const float a = (*ma)[i], b = (*aa)[i];
                    if (std::isfinite(a) != std::isfinite(b)) ++surfaceDiffers;
                    else if (std::isfinite(a)) worst = std::max(worst, double(std::abs(a - b)));
                }
                worst = std::max(worst, double(std::abs(moving[k].depth[i] - again[k].depth[i])));
            }
            EXPECT_EQ(surfaceDiffers, 0u) << tag << " cascade " << k;
            EXPECT_LE(worst, 1e-3) << tag << " cascade " << k;
        }
        // Back to texels kept: the next step keeps this fresh frame's.
    }
}

// Given near and far planes reach the GL backend through the shared frame set-up: the same picture as the CPU's
// with the same planes, and no GL hit outside them.
TEST(RenderGl, NearAndFarPlanesAsOnTheCpu) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    Camera c = overviewCamera(*w.scene, 240, 150);
    Timings t;
    const Frame all = renderFrame(*w.scene, c, smallOptions(), t);
    std::vector<float> d;
    for (size_t i = 0; i < all.distanceM.size(); ++i)
        if (std::isfinite(all.distanceM[i]) && all.wall[i] == 0) d.push_back(all.distanceM[i]);
    ASSERT_GT(d.size(), all.distanceM.size() / 4);
    std::sort(d.begin(), d.end());
    // The middle half of the surface hits' distances. (Surface hits only, as before the walls of issue 11: with
    // the walls' hits counted the far plane moves to 36208.246 m, where cascade 0's Gaussians differ between the
    // backends, CPU 1914100 against GL 1910741: a texel assigned to different cells by the two approximations,
    // which is not this test's subject.)
    c.nearM = d[d.size() / 4], c.farM = d[3 * d.size() / 4];
    expectSame(w, c, "hef_near_far", smallOptions(), false);  // half the hits are clipped: "some terrain" is the check
    const Frame gl = w.gl->render(c, smallOptions(), t);
    size_t hits = 0;
    for (float v : gl.distanceM)
        if (std::isfinite(v)) {
            ++hits;
            EXPECT_GE(v, c.nearM * (1 - 1e-5));
            EXPECT_LE(v, c.farM * (1 + 1e-5));
        }
    EXPECT_LT(hits, d.size()) << "the planes clipped some of what the unclipped camera saw";
}

// The stage times: every stage took some time, the stages fit in the GPU's span, the span in the whole call,
// and the read-back is counted in the whole call. (On llvmpipe timer queries stamp at flushes: the backend times it
// with the clock after glFinish instead; before that, a window's context showed approximation and shading as 0.)
TEST(RenderGl, StageTimesAreConsistent) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const Camera cam = overviewCamera(*w.scene, 320, 200);
    for (bool readBack : {false, true}) {
        Timings t;
        if (readBack) w.gl->render(cam, smallOptions(), t);
        else w.gl->renderToTexture(cam, smallOptions(), t);
        SCOPED_TRACE(readBack ? "render()" : "renderToTexture()");
        ASSERT_EQ(t.cascades.size(), size_t(smallOptions().cascades));
        double cascadeSum = 0;
        for (const CascadeStats& c : t.cascades) {
            EXPECT_GT(c.approximationMs, 0.0);
            cascadeSum += c.approximationMs;
        }
        EXPECT_NEAR(cascadeSum, t.approximationMs, 1e-9);
        EXPECT_GT(t.mipmapMs, 0.0);
        EXPECT_GT(t.raycastMs, 0.0);
        EXPECT_GT(t.shadingMs, 0.0);
        // The stages are consecutive spans of the GPU's one: their sum is the span (timer resolution aside).
        EXPECT_NEAR(t.approximationMs + t.mipmapMs + t.raycastMs + t.shadingMs, t.gpuMs, 1e-3 + 1e-6 * t.gpuMs);
        EXPECT_LE(t.fittingMs + t.gpuMs, t.totalMs);
        if (readBack) {
            EXPECT_GT(t.readbackMs, 0.0);
            EXPECT_LE(t.fittingMs + t.gpuMs + t.readbackMs, t.totalMs);
        } else {
            EXPECT_EQ(t.readbackMs, 0.0);
        }
    }
}

TEST(RenderGl, SameAsCpuOnLidarWithCellOutlines) {
    World& w = lidar();
    HC_REQUIRE_GL(w);
    const Scene& s = *w.scene;
    expectSame(w, overviewCamera(s, 320, 200), "lidar_overview", smallOptions());
    expectSame(w, lowOblique(s, 320, 200), "lidar_oblique_low", smallOptions());
    RenderOptions o = smallOptions();
    o.cellOutlines = true;
    o.cascades = 4;
    expectSame(w, straightDown(s, 240, 240), "lidar_straight_down_cells", o);
}

// Holes and extreme cell-size ratios (DESIGN.md section 8): 72 % nodata around a gully, seen from just
// outside the valid cells (rays into the holes see nothing, on both backends alike), and the synthetic
// cell-size ratio 128 grid with its hole.
TEST(RenderGl, SameAsCpuNextToHolesAndAtCellSizeRatio128) {
    World gully;
    gully.grid = hc::test::ingestFile(hc::test::dataFile("west_bijou_gully_3m.asc"), 0.25);
    gully.init();
    HC_REQUIRE_GL(gully);
    const Scene& s = *gully.scene;
    Camera c;
    c.xWorld = gully.grid.originWorldX + s.xMin + 2;
    c.yWorld = gully.grid.originWorldY + 0.5 * (s.yMin + s.yMax);
    c.zWorld = s.zMax + 30;
    c.pitchDeg = -70, c.yawDeg = 90, c.width = 192, c.height = 128;
    expectSame(gully, c, "gully_hole_edge", smallOptions(), /*mustSeeTerrain=*/false);
    World ratio;
    ratio.grid = hc::test::ratio128Grid();
    ratio.init();
    HC_REQUIRE_GL(ratio);
    expectSame(ratio, overviewCamera(*ratio.scene, 256, 160), "ratio128_overview", smallOptions());
    RenderOptions o = smallOptions();
    o.cellOutlines = true;
    expectSame(ratio, straightDown(*ratio.scene, 200, 160), "ratio128_straight_down_cells", o);
}

// The terrain is solid: a camera 50 m under the surface sees nothing on either backend.
TEST(RenderGl, CameraInsideTheTerrainSeesNothing) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const hc::Grid& g = w.grid;
    const size_t mid = g.cellCount() / 2;
    double x = 0, y = 0;
    g.cellCenterLocal(mid, x, y);
    Camera c;
    c.xWorld = g.originWorldX + x, c.yWorld = g.originWorldY + y, c.zWorld = g.values[0][mid] - 50;
    c.pitchDeg = -20, c.width = 64, c.height = 48;
    Timings t;
    const Frame f = w.gl->render(c, smallOptions(), t);
    EXPECT_EQ(t.hits, 0u);
    for (float d : f.distanceM) EXPECT_TRUE(std::isinf(d) && d > 0);
}

// ------------------------------------------------------------ issue 11: hits that are not on the surface

// GL hits (not walls, not water) more than max(3x the discretisation bound, 1 m) above the exact surface: the
// floating pixels of a blend between two surfaces. The bound as render_test's bilinearBound(): s^2 / 8 times the
// largest second differences of the exact surface around the hit, doubled, twice that for a blended pixel with
// the coarser cascade's texel, plus 5 mm; no claim next to a hole.
size_t floatingPixels(const World& w, const hc::influence::SurfaceEvaluator& eval, const Frame& f, const Timings& t, double& worst) {
    size_t floating = 0;
    for (size_t i = 0; i < f.distanceM.size(); ++i) {
        if (!std::isfinite(f.distanceM[i]) || f.wall[i] != 0 || f.waterDepthM[i] > 0) continue;
        const double x = f.posX[i], y = f.posY[i];
        const auto exact = eval.value(x, y, {});
        if (!exact) continue;
        const size_t k = size_t(f.cascade[i]);
        const double s = k + 1 < t.cascades.size() ? std::max(t.cascades[k].texelM, t.cascades[k + 1].texelM) : t.cascades[k].texelM;
        double vxx = 0, vyy = 0;
        bool defined = true;
        for (auto [ox, oy] : {std::pair{0.0, 0.0}, {0.5, 0.0}, {-0.5, 0.0}, {0.0, 0.5}, {0.0, -0.5}}) {
            auto v = [&](double dx, double dy) { return eval.value(x + ox * s + dx, y + oy * s + dy, {}); };
            const auto c = v(0, 0), xp = v(s, 0), xm = v(-s, 0), yp = v(0, s), ym = v(0, -s);
            if (!c || !xp || !xm || !yp || !ym) {
                defined = false;
                break;
            }
            vxx = std::max(vxx, std::abs(*xp - 2 * *c + *xm) / (s * s));
            vyy = std::max(vyy, std::abs(*yp - 2 * *c + *ym) / (s * s));
        }
        if (!defined) continue;
        const double bound = 2 * (2.0 * s * s / 8.0 * (vxx + vyy) + 5e-3);
        const double above = f.posZ[i] - *exact;
        if (above > std::max(3 * bound, 1.0)) ++floating, worst = std::max(worst, above);
    }
    (void)w;
    return floating;
}

// Issue 11 on the GL backend, against the CPU: no floating pixels where cascades overlap (low cameras looking
// across the alpine DEM's ridges, as in render_test); the same walls where a camera 25 m outside the domain and a
// camera in a hole look at the edges (hit/miss, depth and colour as expectSame, and the wall flag on 99.5 % of
// the pixels, the same allowance as hit/miss); and a camera below the terrain evaluates nothing.
TEST(RenderGl, WallsBlendsAndCameraBelowAsOnTheCpu) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const hc::influence::SurfaceEvaluator eval(w.grid, w.lists);
    const Scene& s = *w.scene;
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> u(0, 1);
    size_t floating = 0, frames = 0;
    double worst = 0;
    RenderOptions o;
    o.texelsPerSide = 256;
    while (frames < 8) {
        const double x = s.xMin + (0.2 + 0.6 * u(rng)) * (s.xMax - s.xMin), y = s.yMin + (0.2 + 0.6 * u(rng)) * (s.yMax - s.yMin);
        const auto ground = eval.value(x, y, {});
        if (!ground) continue;
        Camera c;
        c.xWorld = w.grid.originWorldX + x, c.yWorld = w.grid.originWorldY + y, c.zWorld = *ground + 30 + 400 * u(rng);
        c.yawDeg = 360 * u(rng), c.pitchDeg = -2 - 12 * u(rng), c.fovYDeg = 50, c.width = 240, c.height = 160;
        Timings t;
        floating += floatingPixels(w, eval, w.gl->render(c, o, t), t, worst);
        ++frames;
    }
    EXPECT_EQ(floating, 0u) << "GL: worst " << worst << " m above the exact surface";

    auto sameWalls = [](World& world, const Camera& c, const std::string& name) {
        expectSame(world, c, name, smallOptions(), false);
        Timings tc, tg;
        const Frame cpu = renderFrame(*world.scene, c, smallOptions(), tc), gl = world.gl->render(c, smallOptions(), tg);
        size_t same = 0, walls = 0;
        for (size_t i = 0; i < cpu.wall.size(); ++i) same += cpu.wall[i] == gl.wall[i], walls += gl.wall[i] != 0;
        EXPECT_GE(double(same), 0.995 * double(cpu.wall.size())) << name << ": the wall flag differs";
        EXPECT_GT(walls, cpu.wall.size() / 10) << name << ": the camera looks at an edge";
    };
    World& l = lidar();
    HC_REQUIRE_GL(l);
    const Scene& ls = *l.scene;
    const double ly = 0.5 * (ls.yMin + ls.yMax);
    const hc::influence::SurfaceEvaluator leval(l.grid, l.lists);
    Camera out;
    out.xWorld = l.grid.originWorldX + ls.xMin - 25, out.yWorld = l.grid.originWorldY + ly;
    out.zWorld = 0.5 * (ls.elevationMin + leval.value(ls.xMin + 0.5, ly, {}).value());
    out.yawDeg = 90, out.pitchDeg = 0, out.fovYDeg = 50, out.width = 192, out.height = 128;
    sameWalls(l, out, "lidar_outside_west_edge");

    World gully;
    gully.grid = hc::test::ingestFile(hc::test::dataFile("west_bijou_gully_3m.asc"), 0.25);
    gully.init();
    HC_REQUIRE_GL(gully);
    const Scene& gs = *gully.scene;
    const hc::influence::SurfaceEvaluator geval(gully.grid, gully.lists);
    const double gy = 0.5 * (gs.yMin + gs.yMax);
    double xEdge = gs.xMin + 2;
    while (xEdge < gs.xMax && !gully.grid.locate(xEdge, gy)) xEdge += 0.5;
    const double top = geval.value(xEdge + 3, gy, {}).value();
    Camera hole;
    hole.xWorld = gully.grid.originWorldX + xEdge - 20, hole.yWorld = gully.grid.originWorldY + gy;
    hole.zWorld = std::max(top - 3, gs.elevationMin + 0.5 * (top - gs.elevationMin));
    hole.yawDeg = 90, hole.pitchDeg = -5, hole.fovYDeg = 40, hole.width = 192, hole.height = 128;
    sameWalls(gully, hole, "gully_in_a_hole");

    Camera below = overviewCamera(s, 64, 48);
    below.xWorld = w.grid.originWorldX + 0.5 * (s.xMin + s.xMax), below.yWorld = w.grid.originWorldY + 0.5 * (s.yMin + s.yMax);
    below.zWorld = eval.value(0.5 * (s.xMin + s.xMax), 0.5 * (s.yMin + s.yMax), {}).value() - 50;
    Timings t;
    const Frame f = w.gl->render(below, smallOptions(), t);
    EXPECT_EQ(t.hits, 0u);
    EXPECT_TRUE(t.cascades.empty()) << "GL: a cascade was fitted for a camera inside the terrain";
}

// DESIGN.md section 2: the GPU sees only local and eye-relative values, so a grid 1e7 m away renders
// the same. Tolerance: the same as CPU against GL (the cascade fit in double may move by an ulp).
TEST(RenderGl, ShiftedBy1e7MetresLooksTheSame) {
    World& base = hef();
    HC_REQUIRE_GL(base);
    World shifted;
    shifted.grid = base.grid;
    shifted.grid.originWorldX += 1e7;
    shifted.grid.originWorldY += 1e7;
    shifted.init();
    HC_REQUIRE_GL(shifted);
    Camera a = overviewCamera(*base.scene, 240, 160), b = a;
    b.xWorld += 1e7;
    b.yWorld += 1e7;
    Timings t;
    const Frame fa = base.gl->render(a, smallOptions(), t), fb = shifted.gl->render(b, smallOptions(), t);
    const Comparison c = compare(fa, fb, "shifted_1e7");
    EXPECT_GE(c.psnr, 40.0) << c.diffPng;
    EXPECT_EQ(c.agree, c.pixels) << c.diffPng;
    EXPECT_EQ(c.depthOk, c.bothHit) << c.diffPng;
}

// Lists longer than one storage buffer are split into chunks (llvmpipe caps a buffer at 128 MiB). Forced
// into 3-4 chunks on a small grid, the picture must be bit for bit the one from a single chunk: the same
// entries in the same order, only fetched from other buffers.
TEST(RenderGl, ChunkedListsGiveTheSamePicture) {
    World& w = lidar();
    HC_REQUIRE_GL(w);
    const uint64_t entries = w.lists.entryCount();
    const uint64_t chunk = std::bit_ceil(entries / 4 + 1);
    ASSERT_GT(entries, 2 * chunk) << "the lists span at least three chunks";
    GlRenderer::limitIndexChunksForTest(chunk);
    std::unique_ptr<GlRenderer> chunked;
    try {
        chunked = GlRenderer::headless(*w.scene);
    } catch (...) {
        GlRenderer::limitIndexChunksForTest(0);
        throw;
    }
    GlRenderer::limitIndexChunksForTest(0);
    const Camera cam = overviewCamera(*w.scene, 200, 120);
    Timings t1, t2;
    const Frame a = w.gl->render(cam, smallOptions(), t1), b = chunked->render(cam, smallOptions(), t2);
    EXPECT_EQ(a.rgb, b.rgb);
    EXPECT_EQ(a.distanceM, b.distanceM);
    EXPECT_GT(t1.hits, t1.rays / 4);
}

// ------------------------------------------------------------------------------ failures

TEST(RenderGl, BadShaderGivesTheDriversLog) {
    World& w = lidar();
    HC_REQUIRE_GL(w);
    try {
        w.gl->compileForTest("broken.comp", "#version 430\nlayout(local_size_x = 1) in;\nvoid main() { undeclaredThing = 1; }\n");
        FAIL() << "a shader with an undeclared identifier compiled";
    } catch (const hc::Error& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("broken.comp"), std::string::npos) << m;
        EXPECT_NE(m.find("undeclaredThing"), std::string::npos) << "the driver's log names the identifier: " << m;
    }
    EXPECT_NO_THROW(w.gl->compileForTest("fine.comp", "#version 430\nlayout(local_size_x = 1) in;\nvoid main() {}\n"));
}

TEST(RenderGl, BadCameraAndOptionsAreRefused) {
    World& w = lidar();
    HC_REQUIRE_GL(w);
    Timings t;
    Camera c = overviewCamera(*w.scene, 32, 32);
    c.fovYDeg = 0;
    EXPECT_THROW(w.gl->render(c, {}, t), hc::Error);
    RenderOptions o;
    o.cascades = 9;
    EXPECT_THROW(w.gl->render(overviewCamera(*w.scene, 32, 32), o, t), hc::Error);
}

// ---------------------------------------------------------------------------------------------------------
// The water level field (DESIGN.md section 12; issue 11, "The water surface is not level"): approximate.comp
// draws water as approximate.cpp does, from the wet cells' level. On a bathtub flood the GL picture agrees
// with the CPU's (expectSame), draws water at the same pixels, and its water hits lie on the level.

World& lidarFlood() {  // the 1 m LiDAR tile flooded at 397 m (its range is 379.7 - 410.8 m: shores everywhere)
    static World w = [] {
        World x;
        x.grid = hc::test::ingestFile(hc::test::dataFile("lidar1m_minnesota_utm15.tif"), 0.25, 397);
        x.init();
        return x;
    }();
    return w;
}

// How far a GL water hit at distance t [m] may lie from the level: 1 mm as on the CPU, plus the GPU's float
// hit position (relative to the eye: a few ulps of t, 1.2e-7 relative each, as in depthTolerance).
double levelTolerance(double t) { return 1e-3 + 5e-7 * t; }

// Water pixels of the GL frame against the CPU frame of the same camera: the same pixels are water (up to
// 0.5 %, expectSame's allowance for hit/miss), and the GL water hits lie on the level within levelTolerance
// except rays that enter the water from its side at an edge, below the level (at most 0.1 % of the water
// pixels: RenderWater in render_test.cpp).
void expectLevelWater(World& w, const Camera& cam, double level, const std::string& name) {
    RenderOptions o = smallOptions();
    o.color = ColorMode::WaterDepth;
    expectSame(w, cam, name, o);
    Timings tc, tg;
    const Frame cpu = renderFrame(*w.scene, cam, o, tc);
    const Frame gl = w.gl->render(cam, o, tg);
    size_t water = 0, bothWater = 0, onLevel = 0, above = 0;
    for (size_t i = 0; i < gl.waterDepthM.size(); ++i) {
        const bool wc = cpu.waterDepthM[i] > 0, wg = gl.waterDepthM[i] > 0;
        water += wc || wg;
        bothWater += wc && wg;
        if (!wg) continue;
        const double err = double(gl.posZ[i]) - level;
        const double tol = levelTolerance(gl.distanceM[i]);
        onLevel += std::abs(err) <= tol;
        above += err > tol;
    }
    const size_t glWater = size_t(std::count_if(gl.waterDepthM.begin(), gl.waterDepthM.end(), [](float d) { return d > 0; }));
    std::printf("[ %s ] %zu water pixels, %zu water in both, GL water on the level %zu of %zu\n", name.c_str(), water, bothWater, onLevel,
                glWater);
    EXPECT_GT(water, gl.waterDepthM.size() / 20) << name << ": the camera sees the flood";
    EXPECT_GE(double(bothWater), 0.995 * double(water)) << name;
    EXPECT_GE(double(onLevel), 0.999 * double(glWater)) << name;
    EXPECT_EQ(above, 0u) << name << ": water above the level";
}

TEST(RenderGlWater, BathtubFloodAsOnTheCpuAndOnItsLevel) {
    for (auto [world, level, name] : {std::tuple{&hef(), 2600.0, "hef"}, std::tuple{&lidarFlood(), 397.0, "lidar"}}) {
        World& w = *world;
        HC_REQUIRE_GL(w);
        ASSERT_TRUE(w.scene->hasWater());
        const Scene& s = *w.scene;
        expectLevelWater(w, overviewCamera(s, 240, 150), level, std::string(name) + "_flood_overview");
        expectLevelWater(w, lowOblique(s, 240, 150), level, std::string(name) + "_flood_oblique_low");
        // Along a shore: from above the first wet cell whose neighbour to the east is dry, looking east.
        const hc::Grid& g = w.grid;
        const auto& depth = g.values[size_t(s.waterLayer())];
        for (size_t i = 0; i < g.cellCount(); ++i) {
            double x, y;
            g.cellCenterLocal(i, x, y);
            const auto east = g.locate(x + g.cellSizeM(i), y);
            if (!(depth[i] > 0) || !east || depth[*east] > 0 || x < 0.3 * (s.xMax - s.xMin)) continue;
            const double d = 0.1 * (s.xMax - s.xMin);
            const Camera shore = Camera::lookAt({g.originWorldX + x - d, g.originWorldY + y - 0.3 * d, level + 0.4 * d},
                                                {g.originWorldX + x, g.originWorldY + y, level}, 50, 240, 150);
            expectLevelWater(w, shore, level, std::string(name) + "_flood_shore");
            break;
        }
    }
}

// ------------------------------------------------------------------------- the GL walk's beams

// raycast.comp's beams (RenderOptions::beamTilePx): each tile of P x P pixels marches its rays' beam over each cascade's
// max mipmaps first (beams.comp), and its rays start their walks where the march stopped, at the t the walk from
// the cascade's start enters that patch with; a cascade whose slab the march passed whole is not walked. The march passes
// only depths where every ray of the tile stays above every node's maximum by more than the walk's slack, so the walk
// from the start would have skipped every node there, and the hits are the same. Compared pixel by pixel, beams against
// none, from random cameras (rolled, with a near plane, straight down) on the flooded alpine DEM, the flooded LiDAR tile
// (shores everywhere: the water rules) and the gully with holes (walls), from outside the domain, level and looking up,
// for tiles of 2, 5 and 16 pixels (the image's edge, 100 x 70 pixels, cuts tiles; a 3 x 4 image is one tile of 5). In float a ray running exactly through a patch corner may be found entering by the other
// edge and round its hit differently: allowed in one pixel in 10^3, within 1e-5 of its distance; anything else is a
// wrong march. (With its margin made negative, 5 m too bold, it fails: checked when this test was written.)
TEST(RenderGl, BeamsGiveTheSameHits) {
    World gully;
    gully.grid = hc::test::ingestFile(hc::test::dataFile("west_bijou_gully_3m.asc"), 0.25);
    gully.init();
    std::mt19937_64 rng(47);
    hc::test::SameHits n;
    for (World* w : {&hef(), &lidarFlood(), &gully}) {
        HC_REQUIRE_GL(*w);
        const Scene& s = *w->scene;
        auto randomCamera = [&](std::mt19937_64& r) {  // 2 m .. half the extent above the top, looking down 3-83 degrees
            std::uniform_real_distribution<double> u(0, 1);
            Camera c;
            const double x = s.xMin + u(r) * (s.xMax - s.xMin), y = s.yMin + u(r) * (s.yMax - s.yMin);
            const double extent = std::max(s.xMax - s.xMin, s.yMax - s.yMin);
            c.xWorld = w->grid.originWorldX + x, c.yWorld = w->grid.originWorldY + y;
            c.zWorld = s.zMax + std::exp(std::log(2.0) + u(r) * std::log(extent / 2.0));
            c.yawDeg = 360 * u(r), c.pitchDeg = -3 - 80 * u(r), c.fovYDeg = 30 + 40 * u(r);
            c.width = 100, c.height = 70;
            return c;
        };
        std::vector<Camera> cameras = hc::test::beamTestCameras(s, w->grid, 8, rng, randomCamera);
        cameras.push_back(lowOblique(s, 100, 70));
        Camera level = lowOblique(s, 100, 70), up = level;  // rays level with the eye at the image's centre row, and rising
        level.pitchDeg = 0, level.zWorld = s.elevationMin + 0.7 * (s.zMax - s.elevationMin);
        up.pitchDeg = 25, up.zWorld = level.zWorld;
        cameras.push_back(level), cameras.push_back(up);
        Camera tiny = lowOblique(s, 3, 4);  // one tile, and one block of tiles
        tiny.fovYDeg = 5, tiny.pitchDeg = -20;
        cameras.push_back(tiny);
        auto draw = [&](const Camera& c, const RenderOptions& o) {  // every frame from scratch
            Timings t;
            w->gl->forgetCascades();
            return w->gl->render(c, o, t);
        };
        for (const Camera& c : cameras) {
            RenderOptions o;
            o.texelsPerSide = 256;
            n.addTiles(draw, c, o, {2, 5, 16}, 1e-5, 0.0);
        }
    }
    std::printf("%s\n", n.summary().c_str());
    EXPECT_GT(n.hits, n.pixels / 4);
    EXPECT_GT(n.walls, 500u) << "the comparison covers walls";
    EXPECT_GT(n.water, 1000u) << "the comparison covers water";
    EXPECT_EQ(n.different, 0u);
    EXPECT_LE(n.rounded, n.pixels / 1000);
}

}  // namespace
