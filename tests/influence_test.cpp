// Influence lists against brute force, the exact surface against a sum over every cell, its
// mathematical properties (constants, bounds, continuity, holes, shifts, gradients) and the water level field. The
// .hci cache format: cache_file_test.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

#include "heightcast/core/checksum.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/surface.h"
#include "heightcast/ingest/build.h"
#include "heightcast/ingest/ingest.h"
#include "temp_dir.h"
#include "test_data.h"
#include "test_grids.h"

namespace {

namespace fs = std::filesystem;
using hc::Grid;
using hc::influence::InfluenceLists;
using hc::influence::KernelParams;
using hc::influence::Layer;
using hc::influence::SurfaceEvaluator;

using hc::test::ingestFile;
using hc::test::ratio128Grid;

struct Case {
    std::string name;
    Grid grid;
};

std::vector<Case> grids() {
    std::vector<Case> out;
    out.push_back({"ratio128", ratio128Grid()});
    for (auto [file, tol] : {std::pair{"tin_valid_3857.tif", 0.25},
                             {"west_bijou_gully_3m.asc", 0.25},
                             {"lux_elev.tif", 5.0},
                             {"lidar1m_minnesota_utm15.tif", 0.25}}) {
        std::string p = hc::test::dataFile(file);
        if (!p.empty()) out.push_back({file, ingestFile(p, tol)});
    }
    return out;
}

TEST(InfluenceLists, Ratio128GridSpansTheExtremes) {
    Grid g = ratio128Grid();
    auto perLevel = g.cellsPerLevel();
    EXPECT_GT(perLevel.front(), 1000u);
    EXPECT_GT(perLevel.back(), 0u);
    EXPECT_EQ(g.levelSizeM(7) / g.levelSizeM(0), 128.0);
}

TEST(InfluenceLists, EqualBruteForce) {
    for (const Case& c : grids()) {
        SCOPED_TRACE(c.name);
        const Grid& g = c.grid;
        for (double sigma : {1.0, 0.5}) {
            KernelParams p;
            p.sigma = sigma;
            InfluenceLists lists = hc::influence::buildInfluenceLists(g, p);
            ASSERT_EQ(lists.cellCount(), g.cellCount());
            // Every cell against every cell on small grids; a fixed sample of cells k on large ones.
            const size_t n = g.cellCount();
            const size_t step = n > 5000 ? n / 1500 : 1;
            for (size_t k = 0; k < n; k += step) {
                std::vector<uint32_t> got(lists.list(k).begin(), lists.list(k).end());
                std::sort(got.begin(), got.end());
                ASSERT_TRUE(std::adjacent_find(got.begin(), got.end()) == got.end()) << "duplicate entry in cell " << k;
                std::vector<uint32_t> want;
                for (size_t i = 0; i < n; ++i)
                    if (hc::influence::influences(g, p, i, k)) want.push_back(static_cast<uint32_t>(i));
                ASSERT_EQ(got, want) << "cell " << k << ", sigma " << sigma;
            }
        }
    }
}

TEST(InfluenceLists, RejectParametersThatLeaveGaps) {
    Grid g = ratio128Grid();
    KernelParams p;
    p.sigma = 0.2;  // R sigma = 0.7 < sqrt(2)/2: a cell's corners would get no weight from anyone
    EXPECT_THROW(hc::influence::buildInfluenceLists(g, p), hc::Error);
    p.sigma = -1;
    EXPECT_THROW(hc::influence::buildInfluenceLists(g, p), hc::Error);
}

// Random points in the domain, plus points exactly on cell edges and corners.
std::vector<std::pair<double, double>> probePoints(const Grid& g, size_t count, unsigned seed) {
    std::mt19937_64 rng(seed);
    double x0, y0, x1, y1;
    g.boundsLocal(x0, y0, x1, y1);
    std::uniform_real_distribution<double> ux(x0, x1), uy(y0, y1);
    std::vector<std::pair<double, double>> pts;
    for (size_t i = 0; i < count; ++i) pts.emplace_back(ux(rng), uy(rng));
    for (size_t i = 0; i < g.cellCount(); i += std::max<size_t>(1, g.cellCount() / 200)) {
        auto q = g.cellSquare(i);
        pts.emplace_back(q.x0, q.y0);
        pts.emplace_back(q.x1 - 1e-9, (q.y0 + q.y1) / 2);
    }
    return pts;
}

TEST(Surface, EqualsBruteForceOverEveryCell) {
    for (const Case& c : grids()) {
        SCOPED_TRACE(c.name);
        InfluenceLists lists = hc::influence::buildInfluenceLists(c.grid, KernelParams{});
        SurfaceEvaluator eval(c.grid, lists);
        const Layer elevation = Layer::byName(c.grid, "elevation");
        size_t defined = 0;
        for (auto [x, y] : probePoints(c.grid, c.grid.cellCount() > 5000 ? 300 : 2000, 11)) {
            auto fast = eval.value(x, y, elevation);
            auto brute = eval.valueBruteForce(x, y, elevation);
            ASSERT_EQ(fast.has_value(), brute.has_value()) << x << "," << y;
            if (!fast) continue;
            ++defined;
            // 1e-12 relative: the same terms summed in another order, relative to another base.
            ASSERT_NEAR(*fast, *brute, 1e-12 * std::max(1.0, std::abs(*brute))) << x << "," << y;
        }
        EXPECT_GT(defined, 100u);
    }
}

TEST(Surface, ConstantFieldIsExactlyConstant) {
    Grid g = ratio128Grid();
    for (float& v : g.values[0]) v = 1234.5678f;
    InfluenceLists lists = hc::influence::buildInfluenceLists(g, KernelParams{});
    SurfaceEvaluator eval(g, lists);
    for (auto [x, y] : probePoints(g, 5000, 12)) {
        auto v = eval.valueGradient(x, y, Layer{});
        if (!v) continue;
        ASSERT_EQ(v->value, static_cast<double>(1234.5678f)) << x << "," << y;
        ASSERT_EQ(v->dx, 0.0);
        ASSERT_EQ(v->dy, 0.0);
    }
}

TEST(Surface, StaysWithinTheValuesThatInfluenceIt) {
    for (const Case& c : grids()) {
        SCOPED_TRACE(c.name);
        const Grid& g = c.grid;
        KernelParams p;
        InfluenceLists lists = hc::influence::buildInfluenceLists(g, p);
        SurfaceEvaluator eval(g, lists);
        for (auto [x, y] : probePoints(g, 2000, 13)) {
            auto v = eval.value(x, y, Layer{});
            if (!v) continue;
            const uint32_t k = *g.locate(x, y);
            double lo = HUGE_VAL, hi = -HUGE_VAL;
            for (uint32_t i : lists.list(k)) {
                double cx, cy;
                g.cellCenterLocal(i, cx, cy);
                double d = std::hypot(x - cx, y - cy);
                if (d >= p.radiusM(g.cellSizeM(i))) continue;  // weight zero here
                lo = std::min(lo, double(g.values[0][i]));
                hi = std::max(hi, double(g.values[0][i]));
            }
            // A convex combination: inside [lo, hi] up to rounding (1e-12 relative).
            const double slack = 1e-12 * std::max(std::abs(lo), std::abs(hi));
            ASSERT_GE(*v, lo - slack);
            ASSERT_LE(*v, hi + slack);
        }
    }
}

TEST(Surface, ContinuousAcrossCellBoundaries) {
    // Pairs of points straddling an edge converge as they approach it: |v+ - v-| <= 2 G delta, with
    // G the largest gradient seen nearby (the surface is Lipschitz; only the list changes at the edge).
    for (const Case& c : grids()) {
        SCOPED_TRACE(c.name);
        const Grid& g = c.grid;
        InfluenceLists lists = hc::influence::buildInfluenceLists(g, KernelParams{});
        SurfaceEvaluator eval(g, lists);
        std::mt19937 rng(14);
        size_t checked = 0;
        for (size_t t = 0; t < 400 && g.cellCount() > 1; ++t) {
            const size_t i = rng() % g.cellCount();
            const auto q = g.cellSquare(i);
            const double y = q.y0 + (q.y1 - q.y0) * (0.1 + 0.8 * double(rng() % 1000) / 1000.0);
            double gmax = 0;
            for (double dd : {-0.01, 0.0, 0.01}) {
                auto vg = eval.valueGradient(q.x1 + dd * (q.x1 - q.x0) - 1e-9, y, Layer{});
                if (vg) gmax = std::max(gmax, std::hypot(vg->dx, vg->dy));
            }
            for (double delta : {1e-2, 1e-5, 1e-8}) {
                auto left = eval.value(q.x1 - delta, y, Layer{});
                auto right = eval.value(q.x1 + delta, y, Layer{});
                if (!left || !right) continue;  // a hole or the domain edge on one side
                ASSERT_LE(std::abs(*left - *right), 2.5 * gmax * delta + 1e-9 * std::abs(*left))
                    << "edge x = " << q.x1 << ", y = " << y << ", delta " << delta;
                ++checked;
            }
        }
        EXPECT_GT(checked, 100u);
    }
}

TEST(Surface, HolesAreUndefinedTheirEdgesAreNot) {
    Grid g = ratio128Grid();
    InfluenceLists lists = hc::influence::buildInfluenceLists(g, KernelParams{});
    SurfaceEvaluator eval(g, lists);
    // The hole: columns 500..519, rows 100..139 of the 0.75 m raster (row 0 north, 512 rows).
    const double c = 0.75, top = 512 * c;
    const double hx0 = 500 * c, hx1 = 520 * c, hyTop = top - 100 * c, hyBottom = top - 140 * c;
    EXPECT_FALSE(eval.value((hx0 + hx1) / 2, (hyTop + hyBottom) / 2, Layer{}));
    EXPECT_FALSE(eval.value(hx0 + 1e-6, hyBottom + 1e-6, Layer{}));
    for (double inside : {hx0 - 1e-6, hx0 - 0.3}) {  // just west of the hole: inside a cell
        auto v = eval.value(inside, (hyTop + hyBottom) / 2, Layer{});
        ASSERT_TRUE(v);
        EXPECT_TRUE(std::isfinite(*v));
        EXPECT_GT(*v, 99.0);
        EXPECT_LT(*v, 211.0);
    }
    EXPECT_FALSE(eval.value(-1, 10, Layer{})) << "outside the domain";
    EXPECT_FALSE(eval.value(1e9, 10, Layer{}));
    EXPECT_FALSE(eval.value(NAN, 10, Layer{}));
}

TEST(Surface, ShiftedBy1e7MetresGivesTheSameValues) {
    Grid a = ratio128Grid();
    Grid b = a;
    b.originWorldX += 1e7;
    b.originWorldY += 1e7;
    InfluenceLists la = hc::influence::buildInfluenceLists(a, KernelParams{});
    InfluenceLists lb = hc::influence::buildInfluenceLists(b, KernelParams{});
    SurfaceEvaluator ea(a, la), eb(b, lb);
    for (auto [x, y] : probePoints(a, 2000, 15)) {
        // The same world offsets from each origin: probes take world - origin, computed in double.
        const double wxA = a.originWorldX + x, wyA = a.originWorldY + y;
        const double wxB = b.originWorldX + x, wyB = b.originWorldY + y;
        auto va = ea.value(wxA - a.originWorldX, wyA - a.originWorldY, Layer{});
        auto vb = eb.value(wxB - b.originWorldX, wyB - b.originWorldY, Layer{});
        ASSERT_EQ(va.has_value(), vb.has_value());
        // World coordinates of 1e7 m keep 2e-9 m of resolution: values agree to 1e-9 relative.
        if (va) {
            ASSERT_NEAR(*va, *vb, 1e-9 * std::abs(*va));
        }
    }
}

TEST(Surface, GradientMatchesFiniteDifferences) {
    // The report's kernel subtracts its tail, so each weight is continuous at the truncation radius
    // but its slope jumps there by 2 a R sigma c e^(-R^2/2): the surface is smooth except on those
    // circles, where the gradient jumps by about 1e-3 (m per m, for metre-scale relief). Random
    // points straddle such a circle within h only rarely: at most 2 % may differ by more than the
    // central-difference tolerance, and none by more than the jump.
    HC_REQUIRE_DATA(path, "lidar1m_minnesota_utm15.tif");
    Grid g = ingestFile(path, 0.25);
    InfluenceLists lists = hc::influence::buildInfluenceLists(g, KernelParams{});
    SurfaceEvaluator eval(g, lists);
    std::mt19937_64 rng(16);
    double x0, y0, x1, y1;
    g.boundsLocal(x0, y0, x1, y1);
    std::uniform_real_distribution<double> ux(x0, x1), uy(y0, y1);
    size_t checked = 0, offKink = 0;
    for (int t = 0; t < 2000; ++t) {
        const double x = ux(rng), y = uy(rng), h = 1e-4;
        auto c = eval.valueGradient(x, y, Layer{});
        auto px = eval.value(x + h, y, Layer{}), mx = eval.value(x - h, y, Layer{});
        auto py = eval.value(x, y + h, Layer{}), my = eval.value(x, y - h, Layer{});
        if (!c || !px || !mx || !py || !my) continue;
        ++checked;
        // Central differences: O(h^2) truncation plus rounding of ~1e-13 m / 1e-4 m.
        const double ex = std::abs(c->dx - (*px - *mx) / (2 * h)), ey = std::abs(c->dy - (*py - *my) / (2 * h));
        const double tol = 1e-6 + 1e-5 * std::hypot(c->dx, c->dy);
        if (ex > tol || ey > tol) ++offKink;
        ASSERT_LT(std::max(ex, ey), 2e-3) << "at " << x << "," << y;
    }
    EXPECT_GT(checked, 1500u);
    EXPECT_LE(offKink, checked / 50) << offKink << " of " << checked << " points off";
}

// ---- the water level field (docs/design.md section 6, surface.h) ----

// A river whose surface is not level, over the real LiDAR tile: the cells of the bathtub grid keep their
// elevation, and the depth becomes max(0, level(x) - z) for a surface rising 4 m from west to east (1 %: a
// steep river), so wet cells carry different levels and the wet-only weighting is visible in the result.
Grid slopingRiver(const std::string& lidar) {
    Grid g = ingestFile(lidar, 0.25, 397.0);
    const int depth = g.findLayer("water_depth");
    double x0, y0, x1, y1;
    g.boundsLocal(x0, y0, x1, y1);
    for (size_t i = 0; i < g.cellCount(); ++i) {
        double cx, cy;
        g.cellCenterLocal(i, cx, cy);
        const double level = 395.0 + 4.0 * (cx - x0) / (x1 - x0);
        g.values[size_t(depth)][i] = static_cast<float>(std::max(0.0, level - double(g.values[0][i])));
    }
    return g;
}

// Issue 11, "The water surface is not level": the old water surface (smoothed elevation + smoothed depth,
// where the depth is positive) rose metres above a bathtub flood's level near shores, because dry neighbours
// bring terrain but no depth into the average. A bathtub flood's wet cells all hold z + d = L (up to float
// rounding of their stored means: about 3e-5 m at 400 m), so wherever water is drawn it must be L within
// 1 cm (the figure); the depth is level - terrain there and 0 on dry land.
TEST(Surface, BathtubFloodIsLevelWhereverWaterIsDrawn) {
    HC_REQUIRE_DATA(path, "lidar1m_minnesota_utm15.tif");
    const double level = 397.0;  // inside the tile's range, 379.7 - 410.8 m: a floodplain with shores
    Grid g = ingestFile(path, 0.25, level);
    InfluenceLists lists = hc::influence::buildInfluenceLists(g, KernelParams{});
    SurfaceEvaluator eval(g, lists);
    const Layer depth = Layer::byName(g, "water_depth"), surface = Layer::byName(g, "water_surface");
    const Layer oldDepth{Layer::Cells, size_t(g.findLayer("water_depth"))};  // the smoothed depth cells
    std::vector<std::array<double, 2>> pts;
    for (auto [x, y] : probePoints(g, 20000, 17)) pts.push_back({x, y});
    const auto s = eval.values(pts, surface, 2);
    const auto d = eval.values(pts, depth, 2);
    const auto z = eval.values(pts, Layer{}, 2);
    size_t drawn = 0, dry = 0;
    double worst = 0, oldWorst = 0;
    for (size_t i = 0; i < pts.size(); ++i) {
        if (!z[i]) {
            ASSERT_FALSE(s[i] || d[i]) << "water in a hole";
            continue;
        }
        ASSERT_TRUE(d[i]) << "the depth is defined wherever the terrain is";
        if (!s[i]) {
            ++dry;
            ASSERT_EQ(*d[i], 0.0) << "dry land has depth 0";
            continue;
        }
        ++drawn;
        worst = std::max(worst, std::abs(*s[i] - level));
        ASSERT_GT(*d[i], 0.0) << "water is drawn only above the terrain";
        ASSERT_NEAR(*d[i], *s[i] - *z[i], 1e-9) << "depth = level - terrain";
        // The old definition at the same point, for the regression figure below.
        const auto od = eval.value(pts[i][0], pts[i][1], oldDepth);
        if (*od > 0) oldWorst = std::max(oldWorst, std::abs(*z[i] + *od - level));
    }
    std::printf(
        "%zu points with water, %zu dry: level field within %.2e m of %.0f m; old surface off by up to %.2f m\n", drawn,
        dry, worst, level, oldWorst);
    EXPECT_GT(drawn, 3000u);
    EXPECT_GT(dry, 3000u);
    EXPECT_LE(worst, 0.01);
    // The check above would have caught the old definition: it misses the level by far more than 1 cm
    // (0.29 m measured here; this tile has no buildings, where the issue measured 7 m).
    EXPECT_GT(oldWorst, 0.1);
    EXPECT_THROW(Layer::byName(g, "velocity"), hc::Error);
}

// The rule of surface.h, recomputed here from the kernel's definition over every cell: water is drawn where
// the wet cells hold at least half the weight and their level lies above the smooth terrain; its surface is the
// wet-weighted level, its depth level - terrain (0 elsewhere). Points whose wet share lies within 1e-9 of 1/2
// or whose depth lies within 1e-9 m of 0 are left out: there rounding may decide either way. Tolerance 1e-9 m:
// both sums are double precision over the same terms (errors ~1e-13 m at 400 m).
TEST(Surface, WaterRuleAgainstEveryCell) {
    HC_REQUIRE_DATA(path, "lidar1m_minnesota_utm15.tif");
    Grid g = slopingRiver(path);
    const KernelParams params;
    InfluenceLists lists = hc::influence::buildInfluenceLists(g, params);
    SurfaceEvaluator eval(g, lists);
    const Layer depth = Layer::byName(g, "water_depth"), surface = Layer::byName(g, "water_surface");
    const auto& dl = g.values[size_t(g.findLayer("water_depth"))];
    const double tail = params.tail();
    size_t drawn = 0, dry = 0, byShare = 0, byLevel = 0, ambiguous = 0;
    for (auto [x, y] : probePoints(g, 400, 21)) {
        const auto zEval = eval.value(x, y, Layer{});
        if (!zEval) continue;
        double wAll = 0, wWet = 0, zNum = 0, lNum = 0;
        for (size_t i = 0; i < g.cellCount(); ++i) {
            double cx, cy;
            g.cellCenterLocal(i, cx, cy);
            const double c = g.cellSizeM(i), r2 = (cx - x) * (cx - x) + (cy - y) * (cy - y);
            const double w = std::max(0.0, std::exp(-r2 / (c * c) / (2 * params.sigma * params.sigma)) - tail);
            wAll += w;
            zNum += w * g.values[0][i];
            if (dl[i] > 0) wWet += w, lNum += w * (double(g.values[0][i]) + dl[i]);
        }
        const double z = zNum / wAll, level = wWet > 0 ? lNum / wWet : 0.0, share = wWet / wAll;
        if (std::abs(share - 0.5) < 1e-9 || (wWet > 0 && std::abs(level - z) < 1e-9)) {
            ++ambiguous;
            continue;
        }
        const bool want = share >= 0.5 && level > z;
        const auto s = eval.value(x, y, surface), d = eval.value(x, y, depth);
        const auto sb = eval.valueBruteForce(x, y, surface), db = eval.valueBruteForce(x, y, depth);
        ASSERT_EQ(s.has_value(), want) << x << "," << y << " share " << share << " level " << level << " terrain " << z;
        ASSERT_EQ(sb.has_value(), want) << x << "," << y;
        ASSERT_TRUE(d && db);
        if (want) {
            ++drawn;
            ASSERT_NEAR(*s, level, 1e-9);
            ASSERT_NEAR(*sb, level, 1e-9);
            ASSERT_NEAR(*d, level - z, 1e-9);
            ASSERT_NEAR(*db, level - z, 1e-9);
        } else {
            ++dry;
            byShare += share < 0.5;
            byLevel += share >= 0.5;
            ASSERT_EQ(*d, 0.0);
            ASSERT_EQ(*db, 0.0);
        }
    }
    std::printf("%zu drawn, %zu dry (%zu by the wet share, %zu with the level below the terrain), %zu ambiguous\n",
                drawn, dry, byShare, byLevel, ambiguous);
    EXPECT_GT(drawn, 50u);
    EXPECT_GT(byShare, 50u);
    EXPECT_GT(byLevel, 0u) << "no point tested the level-above-terrain half of the rule";
    EXPECT_LE(ambiguous, 2u);
}

// The gradients of the water surface and depth (hc-export --gradients) against central differences, on the
// sloping river (its level field has a slope of its own). Points whose stencil crosses the edge of the drawn
// water are left out (the depth jumps there); the tolerances are those of GradientMatchesFiniteDifferences,
// except that up to 10 % of the points may straddle a crease (measured: 4 % for the surface, 7 % for the
// depth): the level field is normalised over the wet weights only, so near a shore fewer, smaller weights share
// the denominator and each truncation circle's crease is larger and more of them are in play.
TEST(Surface, WaterGradientsMatchFiniteDifferences) {
    HC_REQUIRE_DATA(path, "lidar1m_minnesota_utm15.tif");
    Grid g = slopingRiver(path);
    InfluenceLists lists = hc::influence::buildInfluenceLists(g, KernelParams{});
    SurfaceEvaluator eval(g, lists);
    for (const char* name : {"water_surface", "water_depth"}) {
        SCOPED_TRACE(name);
        const Layer layer = Layer::byName(g, name);
        size_t checked = 0, offKink = 0;
        for (auto [x, y] : probePoints(g, 3000, 18)) {
            const double h = 1e-4;
            auto c = eval.valueGradient(x, y, layer);
            auto px = eval.value(x + h, y, layer), mx = eval.value(x - h, y, layer);
            auto py = eval.value(x, y + h, layer), my = eval.value(x, y - h, layer);
            if (!c || !px || !mx || !py || !my || !(*px > 0 && *mx > 0 && *py > 0 && *my > 0 && c->value > 0)) continue;
            ++checked;
            const double ex = std::abs(c->dx - (*px - *mx) / (2 * h)), ey = std::abs(c->dy - (*py - *my) / (2 * h));
            const double tol = 1e-6 + 1e-5 * std::hypot(c->dx, c->dy);
            if (ex > tol || ey > tol) ++offKink;
            ASSERT_LT(std::max(ex, ey), 2e-3) << "at " << x << "," << y;
        }
        EXPECT_GT(checked, 300u);
        EXPECT_LE(offKink, checked / 10) << offKink << " of " << checked << " points off";
    }
}

// The batch path (hc-probe's) is a separate, vectorised implementation with its own exponential: it
// must give the reference evaluator's values, and undefined exactly where the reference does, for
// every layer kind (plain layers, and the water surface and depth of the level field).
TEST(Surface, BatchEqualsPointByPointOnEveryLayer) {
    HC_REQUIRE_DATA(lidar, "lidar1m_minnesota_utm15.tif");
    std::vector<Case> cases = grids();
    cases.push_back({"lidar flooded", ingestFile(lidar, 0.25, 397.0)});
    cases.push_back({"lidar sloping river", slopingRiver(lidar)});
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        InfluenceLists lists = hc::influence::buildInfluenceLists(c.grid, KernelParams{});
        SurfaceEvaluator eval(c.grid, lists);
        std::vector<std::array<double, 2>> pts;
        for (auto [x, y] : probePoints(c.grid, 4000, 23)) pts.push_back({x, y});
        pts.push_back({-1e6, -1e6});  // outside the domain
        std::vector<std::string> layers{"elevation"};
        if (c.grid.findLayer("water_depth") >= 0) layers = {"elevation", "water_depth", "water_surface"};
        for (const std::string& name : layers) {
            SCOPED_TRACE(name);
            const Layer layer = Layer::byName(c.grid, name);
            const auto batch = eval.values(pts, layer, 2);
            ASSERT_EQ(batch.size(), pts.size());
            size_t defined = 0;
            for (size_t i = 0; i < pts.size(); ++i) {
                const auto ref = eval.value(pts[i][0], pts[i][1], layer);
                ASSERT_EQ(batch[i].has_value(), ref.has_value()) << pts[i][0] << "," << pts[i][1];
                if (!ref) continue;
                ++defined;
                // 1e-12 relative, as against brute force: both sum the same terms relative to the same
                // base; the exponentials differ by a few ulp.
                ASSERT_NEAR(*batch[i], *ref, 1e-12 * std::max(1.0, std::abs(*ref))) << pts[i][0] << "," << pts[i][1];
            }
            EXPECT_GT(defined, 100u);
        }
    }
}

}  // namespace
