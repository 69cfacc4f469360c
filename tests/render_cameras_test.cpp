// The CPU renderer's cameras (split from render_test, see render_world.h): near and far planes, roll, the extremes of
// docs/design.md section 8 (inside the terrain, straight down and up, grazing, 100 km up, looking out of the domain, a
// split near 0, a grid shifted by 1e7 m, a cell-size ratio of 128, a single cell, holes next to the camera) and the
// cameras and options refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <vector>

#include "heightcast/core/error.h"
#include "heightcast/ingest/build.h"
#include "image_compare.h"
#include "render_world.h"

namespace {

namespace fs = std::filesystem;
using hc::Grid;
using namespace hc::render;
using namespace hc::test;

// Given near and far planes clip every ray: hits only between them; a ray whose surface lies between
// them still hits it (1 % margins either side: the two frames fit their cascades to different volumes).
TEST_F(Render, NearAndFarPlanesClipEveryRay) {
    World& w = lidar();
    Camera c;
    c.xWorld = w.grid.originWorldX + 200;
    c.yWorld = w.grid.originWorldY + 100;
    c.zWorld = 420;
    c.pitchDeg = -40;
    c.fovYDeg = 50;
    c.width = 96;
    c.height = 64;
    RenderOptions o;
    o.texelsPerSide = 256;
    Timings t;
    const Frame all = renderFrame(*w.scene, c, o, t);
    std::vector<float> d;
    for (float v : all.distanceM)
        if (std::isfinite(v)) d.push_back(v);
    ASSERT_GT(d.size(), all.distanceM.size() / 2);
    std::nth_element(d.begin(), d.begin() + long(d.size() / 2), d.end());
    const double median = d[d.size() / 2];
    for (int which = 0; which < 2; ++which) {
        Camera k = c;
        (which == 0 ? k.farM : k.nearM) = median;
        const Frame f = renderFrame(*w.scene, k, o, t);
        size_t inside = 0, kept = 0;
        for (size_t i = 0; i < f.distanceM.size(); ++i) {
            if (std::isfinite(f.distanceM[i])) {
                if (which == 0) {
                    EXPECT_LE(f.distanceM[i], median * (1 + 1e-6)) << "pixel " << i << " beyond the far plane";
                } else {
                    EXPECT_GE(f.distanceM[i], median * (1 - 1e-6)) << "pixel " << i << " before the near plane";
                }
            }
            const double full = all.distanceM[i];
            if (!std::isfinite(full)) continue;
            const bool between = which == 0 ? full < 0.99 * median : full > 1.01 * median;
            const bool outside = which == 0 ? full > 1.01 * median : full < 0.99 * median;
            if (between) {
                ++inside;
                kept += std::isfinite(f.distanceM[i]) && std::abs(f.distanceM[i] - full) < 0.01 * full;
            }
            if (outside) {
                EXPECT_FALSE(std::isfinite(f.distanceM[i])) << "pixel " << i << " should be clipped";
            }
        }
        EXPECT_GT(inside, 1000u);
        EXPECT_GE(double(kept), 0.995 * double(inside))
            << (which == 0 ? "far" : "near") << " plane: surface between the planes lost";
        EXPECT_EQ(checkHits(w, f, t, 1).bad, 0u);
    }
}

// Roll 180 degrees turns the picture upside down: pixel (x, y) sees what (W-1-x, H-1-y) saw. Roll +90
// banks the camera clockwise as seen from behind it: the ground of a level view moves to the image's right.
TEST_F(Render, RollTurnsThePicture) {
    World& w = lidar();
    Camera c = above(w, 30, -20);
    c.width = 64, c.height = 48;
    Timings t;
    const Frame a = renderWith(w, c, t);
    c.rollDeg = 180;
    const Frame b = renderWith(w, c, t);
    size_t same = 0;
    for (int y = 0; y < a.height; ++y)
        for (int x = 0; x < a.width; ++x) {
            const float da = a.distanceM[size_t(y) * size_t(a.width) + size_t(x)];
            const float db = b.distanceM[size_t(a.height - 1 - y) * size_t(a.width) + size_t(a.width - 1 - x)];
            same += (std::isinf(da) && std::isinf(db)) || std::abs(da - db) <= 1e-4f * da;
        }
    EXPECT_GE(double(same), 0.999 * double(a.distanceM.size()));
    c.rollDeg = 90, c.pitchDeg = 0, c.width = 48;
    const Frame r = renderWith(w, c, t);
    size_t left = 0, right = 0;
    for (int y = 0; y < r.height; ++y)
        for (int x = 0; x < r.width; ++x)
            if (std::isfinite(r.distanceM[size_t(y) * size_t(r.width) + size_t(x)])) ++(x < r.width / 2 ? left : right);
    EXPECT_GT(right, 20 * left + 100) << "left " << left << ", right " << right;
}

TEST(RenderExtremes, CameraInsideTheTerrainSeesNothing) {
    World& w = hef();
    Camera c = above(w, -50, -20);  // 50 m underground
    Timings t;
    Frame f = renderWith(w, c, t);
    EXPECT_EQ(t.hits, 0u) << "rays starting under the surface see nothing (the terrain is solid)";
    for (float d : f.distanceM) EXPECT_TRUE(std::isinf(d));
}

TEST(RenderExtremes, StraightDownAndStraightUp) {
    World& w = lidar();
    Timings t;
    Frame down = renderWith(w, above(w, 100, -90), t);
    EXPECT_EQ(t.hits, t.rays);
    const size_t centre = size_t(down.height / 2) * size_t(down.width) + size_t(down.width / 2);
    EXPECT_NEAR(down.distanceM[centre], 100.0, 0.5) << "the centre ray falls 100 m onto the surface";
    EXPECT_LE(checkHits(w, down, t, 1).bad, 0u);
    Frame up = renderWith(w, above(w, 100, 90), t);
    EXPECT_EQ(t.hits, 0u);
}

TEST(RenderExtremes, GrazingAtGroundLevel) {
    World& w = lidar();
    Timings t;
    Frame f = renderWith(w, above(w, 1.7, 0), t);  // eye height, looking level
    EXPECT_GT(t.hits, t.rays / 4) << "the ground ahead fills the lower part of the image";
    HitCheck h = checkHits(w, f, t, 1);
    EXPECT_LE(h.bad, h.checked / 100 + 1) << "worst ratio " << h.worstRatio;
}

TEST(RenderExtremes, HundredKilometresUp) {
    World& w = hef();
    Timings t;
    Camera c = above(w, 100000, -90);
    c.fovYDeg = 20;
    Frame f = renderWith(w, c, t);
    EXPECT_GT(t.hits, 0u);
    EXPECT_LT(t.hits, t.rays) << "from 100 km with a 20 degree view the grid does not fill the image";
    HitCheck h = checkHits(w, f, t, 1);
    EXPECT_EQ(h.bad, 0u) << "worst ratio " << h.worstRatio;
}

TEST(RenderExtremes, DomainEdgeLookingOut) {
    World& w = hef();
    Camera c;
    c.xWorld = w.grid.originWorldX + w.scene->xMax - 100;
    c.yWorld = w.grid.originWorldY + 0.5 * (w.scene->yMin + w.scene->yMax);
    c.zWorld = w.scene->zMax + 200;
    c.yawDeg = 90;  // east: out of the grid
    c.pitchDeg = -5;
    c.width = 64;
    c.height = 48;
    Timings t;
    Frame f = renderWith(w, c, t);
    EXPECT_LT(t.hits, t.rays / 4) << "looking out of the grid there is little to see";
    EXPECT_EQ(checkHits(w, f, t, 1).bad, 0u);
}

TEST(RenderExtremes, SplitNearZeroAndOneCascade) {
    World& w = lidar();
    for (int k : {1, 4}) {
        Timings t;
        Frame f = renderWith(w, above(w, 0.3, -30), t, k);  // 30 cm above the ground: n -> 0
        EXPECT_EQ(t.cascades.size(), size_t(k));
        EXPECT_GT(t.hits, t.rays / 2);
        HitCheck h = checkHits(w, f, t, 1);
        EXPECT_LE(h.bad, h.checked / 100 + 1) << k << " cascades, worst " << h.worstRatio;
    }
}

TEST(RenderExtremes, ShiftedBy1e7MetresLooksTheSame) {
    World& base = hef();
    World shifted;
    shifted.grid = base.grid;
    shifted.grid.originWorldX += 1e7;
    shifted.grid.originWorldY += 1e7;
    shifted.init();
    Camera a = overviewCamera(*base.scene, 160, 100), b = a;
    b.xWorld += 1e7;
    b.yWorld += 1e7;
    Timings t;
    Frame fa = renderWith(base, a, t), fb = renderWith(shifted, b, t);
    EXPECT_GE(psnr(fa, fb), 40.0);
}

TEST(RenderExtremes, CellSizeRatio128AndSingleCell) {
    const hc::ingest::Raster r = hc::test::makeRaster(512, 512, 0.75, 0, 384, [](size_t col, size_t row) {
        return (col > 240 && col < 260) ? 20.0f + float((row * 7 + col * 13) % 17) * 0.1f : 10.0f + 0.01f * float(col);
    });
    hc::ingest::BuildOptions b;
    b.maxLevel = 7;
    World w;
    w.grid = hc::ingest::buildGrid(r, nullptr, b);
    w.init();
    ASSERT_EQ(w.grid.cellsPerLevel().size(), 8u);
    Timings t;
    Frame f = renderWith(w, above(w, 150, -60), t);
    EXPECT_GT(t.hits, t.rays / 2);
    EXPECT_LE(checkHits(w, f, t, 1).bad, 0u);

    World one;
    const float v = 123.0f;
    one.grid.finestCellM = 10;
    one.grid.appendCell(0, 0, 0, &v);
    one.init();
    Frame g = renderWith(one, above(one, 20, -90), t);
    EXPECT_GT(t.hits, 0u);
    for (size_t i = 0; i < g.posZ.size(); ++i) {
        if (std::isfinite(g.distanceM[i])) {
            ASSERT_NEAR(g.posZ[i], 123.0, 1e-3) << "a single cell is a flat square";
        }
    }
}

TEST(RenderExtremes, HolesNextToTheCamera) {
    World w = fromFile("west_bijou_gully_3m.asc", 0.25);  // 72 % nodata around a gully
    Camera c;
    // Just outside the watershed's valid cells (a hole) over their edge, looking down.
    c.xWorld = w.grid.originWorldX + w.scene->xMin + 2;
    c.yWorld = w.grid.originWorldY + 0.5 * (w.scene->yMin + w.scene->yMax);
    c.zWorld = w.scene->zMax + 30;
    c.pitchDeg = -70;
    c.yawDeg = 90;
    c.width = 96;
    c.height = 64;
    Timings t;
    Frame f = renderWith(w, c, t);
    EXPECT_GT(t.hits, 0u);
    EXPECT_LT(t.hits, t.rays) << "rays into the holes see nothing";
    EXPECT_EQ(checkHits(w, f, t, 1).bad, 0u);
}

TEST_F(Render, BadCameraAndOptionsAreRefused) {
    World& w = lidar();
    Timings t;
    RenderOptions o;
    Camera c = above(w, 10, -30);
    c.fovYDeg = 0;
    EXPECT_THROW(renderFrame(*w.scene, c, o, t), hc::Error);
    c = above(w, 10, -30);
    c.pitchDeg = 120;
    EXPECT_THROW(renderFrame(*w.scene, c, o, t), hc::Error);
    c = above(w, 10, -30);
    c.zWorld = NAN;
    EXPECT_THROW(renderFrame(*w.scene, c, o, t), hc::Error);
    c = above(w, 10, -30);
    o.cascades = 5;
    EXPECT_THROW(renderFrame(*w.scene, c, o, t), hc::Error);
    EXPECT_THROW(Camera::lookAt({1, 2, 3}, {1, 2, 3}, 50, 10, 10), hc::Error);
    o.cascades = 3;
    c.nearM = -1;
    EXPECT_THROW(renderFrame(*w.scene, c, o, t), hc::Error);
    c.nearM = 50, c.farM = 50;
    EXPECT_THROW(renderFrame(*w.scene, c, o, t), hc::Error);
    c.farM = INFINITY;
    EXPECT_THROW(renderFrame(*w.scene, c, o, t), hc::Error);
    c = above(w, 10, -30);
    for (int tile : {-1, 65}) {
        o.beamTilePx = tile;
        EXPECT_NE(o.validate().find("--beam-tile"), std::string::npos) << tile;
        EXPECT_THROW(renderFrame(*w.scene, c, o, t), hc::Error) << tile;
    }
}

}  // namespace
