// The OpenGL compute backend against the CPU backend (docs/design.md section 5: "tested against each
// other"): the shared std430 layouts as the driver sees them, the same pixels hit at the same depth
// with the same colours on real DEMs from several cameras, finite outputs, a 1e7 m shifted grid, and
// shader failures reported with the driver's log.
//
// The tests run headless (EGL: a GPU device where there is one, else Mesa's surfaceless llvmpipe). Where no OpenGL
// 4.3 context can be had they fail, unless HC_GL_TESTS=skip says that is expected.
#include "render_gl_world.h"

namespace {

using namespace hc::render;
using namespace hc::test::gl;

// ------------------------------------------------------------------------------------ layouts

TEST_F(RenderGl, Std430LayoutsAgreeWithTheCppStructs) {
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
    HC_FRAME(eyeX), HC_FRAME(eyeY), HC_FRAME(finestM), HC_FRAME(domainM), HC_FRAME(eyeZ), HC_FRAME(tanHalfX),
        HC_FRAME(tanHalfY);
    HC_FRAME(nearM), HC_FRAME(farM), HC_FRAME(dirX), HC_FRAME(dirY), HC_FRAME(tail);
    HC_FRAME_ARRAY(forward), HC_FRAME_ARRAY(right), HC_FRAME_ARRAY(up), HC_FRAME_ARRAY(sun);
    HC_FRAME(width), HC_FRAME(height), HC_FRAME(cascades), HC_FRAME(hasWater), HC_FRAME(cellCount), HC_FRAME(rootLevel);
    HC_FRAME(indexChunkShift);
    HC_FRAME(minDepthM), HC_FRAME(fogDistM), HC_FRAME(elevationMin), HC_FRAME(zRange), HC_FRAME(dRange),
        HC_FRAME(pixelAngle);
    HC_FRAME(colorMode), HC_FRAME(cellOutlines), HC_FRAME(legendRamp), HC_FRAME(legendX0), HC_FRAME(legendY0);
    HC_FRAME(legendBarW), HC_FRAME(legendBarH), HC_FRAME(legendScale), HC_FRAME(labelHiLen), HC_FRAME(labelLoLen);
    HC_FRAME_ARRAY(labelHi), HC_FRAME_ARRAY(labelLo), HC_FRAME_ARRAY(elevationRamp), HC_FRAME_ARRAY(depthRamp);
    HC_FRAME_ARRAY(skyHorizon), HC_FRAME_ARRAY(skyZenith), HC_FRAME_ARRAY(dryColor), HC_FRAME(zFloor),
        HC_FRAME_ARRAY(wallColor), HC_FRAME(beamTile);
    HC_FRAME(overlay), HC_FRAME(layerLo), HC_FRAME(layerRange), HC_FRAME(layerOnWater), HC_FRAME_ARRAY(layerRamp);
#define HC_CASCADE(m) \
    expectAt("raycast", "cascades[0]." #m, cas + long(offsetof(gpu::GpuCascade, m)), long(sizeof(gpu::GpuCascade)))
#define HC_CASCADE_ARRAY(m)                                                                \
    expectAt("raycast", "cascades[0]." #m "[0]", cas + long(offsetof(gpu::GpuCascade, m)), \
             long(sizeof(gpu::GpuCascade)))
    HC_CASCADE(x0Eye), HC_CASCADE(y0Eye), HC_CASCADE(texelF), HC_CASCADE(n), HC_CASCADE(splitNear),
        HC_CASCADE(splitFar);
    HC_CASCADE(farWithOverlap), HC_CASCADE(levels), HC_CASCADE(terrainOffset), HC_CASCADE(waterOffset),
        HC_CASCADE(depthOffset);
    HC_CASCADE_ARRAY(terrainMip), HC_CASCADE_ARRAY(waterMip), HC_CASCADE_ARRAY(mipSide);
    // The double members and the visibility offset are read by the approximation.
    for (auto [name, off] : {std::pair{"x0", offsetof(gpu::GpuCascade, x0)},
                             {"y0", offsetof(gpu::GpuCascade, y0)},
                             {"texelM", offsetof(gpu::GpuCascade, texelM)},
                             {"visibleOffset", offsetof(gpu::GpuCascade, visibleOffset)}})
        expectAt("approximate", std::string("cascades[0].") + name, cas + long(off), long(sizeof(gpu::GpuCascade)));
#define HC_CELL(m) expectAt("approximate", "cells[0]." #m, long(offsetof(gpu::GpuCell, m)), long(sizeof(gpu::GpuCell)))
    HC_CELL(ix), HC_CELL(iy), HC_CELL(level), HC_CELL(listBegin), HC_CELL(a), HC_CELL(r2), HC_CELL(z), HC_CELL(depth);
#define HC_PIXEL(m) expectAt("shade", "pixels[0]." #m, long(offsetof(gpu::GpuPixel, m)), long(sizeof(gpu::GpuPixel)))
    HC_PIXEL(t), HC_PIXEL(relX), HC_PIXEL(relY), HC_PIXEL(relZ), HC_PIXEL(nx), HC_PIXEL(ny), HC_PIXEL(nz),
        HC_PIXEL(depth);
    HC_PIXEL(cascade), HC_PIXEL(water), HC_PIXEL(wall);
#define HC_OVERLAY(m) \
    expectAt("shade", "overlay[0]." #m, long(offsetof(gpu::GpuOverlay, m)), long(sizeof(gpu::GpuOverlay)))
    HC_OVERLAY(layer), HC_OVERLAY(dim), HC_OVERLAY(valued);
    // Whole sizes: the frame block, and (through the unsized arrays' strides above) each struct.
    EXPECT_EQ(gl.bufferBlockSize("shade", "FrameBlock"), long(sizeof(gpu::FrameBlock)));
    EXPECT_EQ(gl.bufferBlockSize("raycast", "FrameBlock"), long(sizeof(gpu::FrameBlock)));
    EXPECT_GE(checked, 80);
}

TEST_F(RenderGl, SameAsCpuOnTheAlpineDemFromFourCameras) {
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
    const Camera water = Camera::lookAt({g.originWorldX + x, g.originWorldY + y - 1500, z + 800},
                                        {g.originWorldX + x, g.originWorldY + y, z}, 50, 320, 200);
    RenderOptions o = smallOptions();
    o.color = ColorMode::WaterDepth;
    expectSame(w, water, "hef_water", o);
    Timings t;
    const Frame f = w.gl->render(water, o, t);
    const size_t wet = size_t(std::count_if(f.waterDepthM.begin(), f.waterDepthM.end(), [](float d) { return d > 0; }));
    EXPECT_GT(wet, f.waterDepthM.size() / 10) << "the water camera sees water";
}

TEST_F(RenderGl, NearAndFarPlanesAsOnTheCpu) {
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
TEST_F(RenderGl, StageTimesAreConsistent) {
    World& w = hef();
    HC_REQUIRE_GL(w);
    const Camera cam = overviewCamera(*w.scene, 320, 200);
    for (bool readBack : {false, true}) {
        Timings t;
        if (readBack)
            w.gl->render(cam, smallOptions(), t);
        else
            w.gl->renderToTexture(cam, smallOptions(), t);
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

TEST_F(RenderGl, SameAsCpuOnLidarWithCellOutlines) {
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

// Holes and extreme cell-size ratios (docs/design.md section 8): 72 % nodata around a gully, seen from just
// outside the valid cells (rays into the holes see nothing, on both backends alike), and the synthetic
// cell-size ratio 128 grid with its hole.
TEST_F(RenderGl, SameAsCpuNextToHolesAndAtCellSizeRatio128) {
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
TEST_F(RenderGl, CameraInsideTheTerrainSeesNothing) {
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
// floating pixels of a blend between two surfaces. The bound as render_hits_test's: twice bilinearBound()
// (surface_bound.h) with the coarser cascade's texel of a blended pixel; no claim next to a hole.
size_t floatingPixels(const World& w, const hc::influence::SurfaceEvaluator& eval, const Frame& f, const Timings& t,
                      double& worst) {
    size_t floating = 0;
    for (size_t i = 0; i < f.distanceM.size(); ++i) {
        if (!std::isfinite(f.distanceM[i]) || f.wall[i] != 0 || f.waterDepthM[i] > 0) continue;
        const double x = f.posX[i], y = f.posY[i];
        const auto exact = eval.value(x, y, {});
        if (!exact) continue;
        const size_t k = size_t(f.cascade[i]);
        const double s =
            k + 1 < t.cascades.size() ? std::max(t.cascades[k].texelM, t.cascades[k + 1].texelM) : t.cascades[k].texelM;
        const std::optional<double> claim = hc::test::bilinearBound(eval, {}, x, y, s);
        if (!claim) continue;
        const double bound = 2 * *claim;
        const double above = f.posZ[i] - *exact;
        if (above > std::max(3 * bound, 1.0)) ++floating, worst = std::max(worst, above);
    }
    (void)w;
    return floating;
}

// Issue 11 on the GL backend, against the CPU: no floating pixels where cascades overlap (low cameras looking
// across the alpine DEM's ridges, as in render_hits_test); the same walls where a camera 25 m outside the domain and a
// camera in a hole look at the edges (hit/miss, depth and colour as expectSame, and the wall flag on 99.5 % of
// the pixels, the same allowance as hit/miss); and a camera below the terrain evaluates nothing.
TEST_F(RenderGl, WallsBlendsAndCameraBelowAsOnTheCpu) {
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
        const double x = s.xMin + (0.2 + 0.6 * u(rng)) * (s.xMax - s.xMin),
                     y = s.yMin + (0.2 + 0.6 * u(rng)) * (s.yMax - s.yMin);
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
        const Frame cpu = renderFrame(*world.scene, c, smallOptions(), tc),
                    gl = world.gl->render(c, smallOptions(), tg);
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
    below.xWorld = w.grid.originWorldX + 0.5 * (s.xMin + s.xMax),
    below.yWorld = w.grid.originWorldY + 0.5 * (s.yMin + s.yMax);
    below.zWorld = eval.value(0.5 * (s.xMin + s.xMax), 0.5 * (s.yMin + s.yMax), {}).value() - 50;
    Timings t;
    const Frame f = w.gl->render(below, smallOptions(), t);
    EXPECT_EQ(t.hits, 0u);
    EXPECT_TRUE(t.cascades.empty()) << "GL: a cascade was fitted for a camera inside the terrain";
}

// docs/design.md section 8: the GPU sees only local and eye-relative values, so a grid 1e7 m away renders
// the same. Tolerance: the same as CPU against GL (the cascade fit in double may move by an ulp).
TEST_F(RenderGl, ShiftedBy1e7MetresLooksTheSame) {
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
TEST_F(RenderGl, ChunkedListsGiveTheSamePicture) {
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

TEST_F(RenderGl, BadShaderGivesTheDriversLog) {
    World& w = lidar();
    HC_REQUIRE_GL(w);
    try {
        w.gl->compileForTest("broken.comp",
                             "#version 430\nlayout(local_size_x = 1) in;\nvoid main() { undeclaredThing = 1; }\n");
        FAIL() << "a shader with an undeclared identifier compiled";
    } catch (const hc::Error& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("broken.comp"), std::string::npos) << m;
        EXPECT_NE(m.find("undeclaredThing"), std::string::npos) << "the driver's log names the identifier: " << m;
    }
    EXPECT_NO_THROW(w.gl->compileForTest("fine.comp", "#version 430\nlayout(local_size_x = 1) in;\nvoid main() {}\n"));
}

TEST_F(RenderGl, BadCameraAndOptionsAreRefused) {
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
// The water level field (docs/design.md section 6; issue 11, "The water surface is not level"): approximate.comp
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
// pixels: RenderWater in render_frames_test.cpp).
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
    const size_t glWater =
        size_t(std::count_if(gl.waterDepthM.begin(), gl.waterDepthM.end(), [](float d) { return d > 0; }));
    std::printf("[ %s ] %zu water pixels, %zu water in both, GL water on the level %zu of %zu\n", name.c_str(), water,
                bothWater, onLevel, glWater);
    EXPECT_GT(water, gl.waterDepthM.size() / 20) << name << ": the camera sees the flood";
    EXPECT_GE(double(bothWater), 0.995 * double(water)) << name;
    EXPECT_GE(double(onLevel), 0.999 * double(glWater)) << name;
    EXPECT_EQ(above, 0u) << name << ": water above the level";
}

TEST_F(RenderGlWater, BathtubFloodAsOnTheCpuAndOnItsLevel) {
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

// raycast.comp's beams (RenderOptions::beamTilePx): each tile of P x P pixels marches its rays' beam over each
// cascade's max mipmaps first (beams.comp), and its rays start their walks where the march stopped, at the t the walk
// from the cascade's start enters that patch with; a cascade whose slab the march passed whole is not walked. The march
// passes only depths where every ray of the tile stays above every node's maximum by more than the walk's slack, so the
// walk from the start would have skipped every node there, and the hits are the same. Compared pixel by pixel, beams
// against none, from random cameras (rolled, with a near plane, straight down) on the flooded alpine DEM, the flooded
// LiDAR tile (shores everywhere: the water rules) and the gully with holes (walls), from outside the domain, level and
// looking up, for tiles of 2, 5 and 16 pixels (the image's edge, 100 x 70 pixels, cuts tiles; a 3 x 4 image is one tile
// of 5). In float a ray running exactly through a patch corner may be found entering by the other edge and round its
// hit differently: allowed in one pixel in 10^3, within 1e-5 of its distance; anything else is a wrong march. (With its
// margin made negative, 5 m too bold, it fails: checked when this test was written.)
TEST_F(RenderGl, BeamsGiveTheSameHits) {
    World gully;
    gully.grid = hc::test::ingestFile(hc::test::dataFile("west_bijou_gully_3m.asc"), 0.25);
    gully.init();
    std::mt19937_64 rng(47);
    hc::test::SameHits n;
    for (World* w : {&hef(), &lidarFlood(), &gully}) {
        HC_REQUIRE_GL(*w);
        const Scene& s = *w->scene;
        auto randomCamera =
            [&](std::mt19937_64& r) {  // 2 m .. half the extent above the top, looking down 3-83 degrees
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
        Camera level = lowOblique(s, 100, 70),
               up = level;  // rays level with the eye at the image's centre row, and rising
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
