// Flood scenarios over time (docs/design.md section 6): ingest of water steps into one structure, and reading them
// back.
//
// The structure a scenario shares must keep every step's wet/dry edges and depth tolerance; the build reaches it
// through per-step merge masks (ingest/src/build.cpp). These tests compare it with the rule written out directly
// (a recursive build over all layers at once), check each step's depths pixel by pixel, and refuse series that
// disagree.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <optional>
#include <random>

#include <gdal_priv.h>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/ingest/build.h"
#include "heightcast/ingest/ingest.h"
#include "temp_dir.h"
#include "test_data.h"

namespace {

namespace fs = std::filesystem;
using hc::Grid;
using hc::ingest::Raster;

class Steps : public hc::test::TempDirTest {
protected:
    Steps() : TempDirTest("hc_steps_") {}
};

// A valley with a hole, sloping so that merges depend on the tolerance: 37 x 29 pixels of 2 m (not a power of two).
Raster valley() {
    Raster t;
    t.width = 37;
    t.height = 29;
    t.pixelSizeM = 2;
    t.westWorld = 500000;
    t.northWorld = 5200000;
    t.values.resize(t.width * t.height);
    for (size_t r = 0; r < t.height; ++r)
        for (size_t c = 0; c < t.width; ++c) {
            const double x = double(c) - 18, y = double(r);
            t.at(c, r) = float(100 + 0.02 * x * x + 0.05 * y + (c % 7 == 0 ? 0.1 : 0.0));
        }
    for (size_t r = 10; r < 13; ++r)
        for (size_t c = 30; c < 34; ++c) t.at(c, r) = NAN;  // a hole
    return t;
}

// Depth of a bathtub at `level` over the whole valley (every pixel below it, no connectivity: a test raster).
Raster tub(const Raster& t, double level) {
    Raster d = t;
    for (size_t i = 0; i < d.values.size(); ++i)
        d.values[i] = std::isnan(t.values[i]) ? NAN : float(std::max(0.0, level - double(t.values[i])));
    return d;
}

// The merge rule of build.h written out directly: a node is one cell when its four children are, it is no coarser
// than maxLevel, and for the terrain and for every step the float mean of the children's means holds every pixel
// within the tolerance; for every step the four are all wet or all dry. Returns the cell codes in Morton order.
std::vector<uint64_t> referenceCells(const Raster& t, const std::vector<Raster>& steps, double tol, int maxLevel,
                                     int rootLevel) {
    struct Node {
        bool leaf = false;
        std::vector<float> mean, lo, hi;  // terrain, then each step
    };
    std::vector<uint64_t> codes;
    const size_t layers = 1 + steps.size();
    std::function<Node(uint32_t, uint32_t, int)> build = [&](uint32_t ix, uint32_t iy, int level) -> Node {
        Node n;
        if (level == 0) {
            if (ix >= t.width || iy >= t.height) return n;
            const size_t idx = (t.height - 1 - iy) * t.width + ix;
            if (std::isnan(t.values[idx])) return n;
            n.leaf = true;
            n.mean.push_back(t.values[idx]);
            for (const Raster& d : steps) n.mean.push_back(d.values[idx]);
            n.lo = n.hi = n.mean;
            return n;
        }
        const uint32_t h = uint32_t{1} << (level - 1);
        const Node c[4] = {build(ix, iy, level - 1), build(ix + h, iy, level - 1), build(ix, iy + h, level - 1),
                           build(ix + h, iy + h, level - 1)};
        if (!(c[0].leaf && c[1].leaf && c[2].leaf && c[3].leaf) || level > maxLevel) return n;
        for (size_t l = 1; l < layers; ++l) {
            const bool wet = c[0].mean[l] > 0;
            for (const Node& k : c)
                if ((k.mean[l] > 0) != wet) return n;
        }
        for (size_t l = 0; l < layers; ++l) {
            const double sum = double(c[0].mean[l]) + c[1].mean[l] + c[2].mean[l] + c[3].mean[l];
            const float m = float(sum * 0.25);
            const float lo = std::min({c[0].lo[l], c[1].lo[l], c[2].lo[l], c[3].lo[l]});
            const float hi = std::max({c[0].hi[l], c[1].hi[l], c[2].hi[l], c[3].hi[l]});
            if (double(hi) - m > tol || m - double(lo) > tol) return n;
            n.mean.push_back(m), n.lo.push_back(lo), n.hi.push_back(hi);
        }
        n.leaf = true;
        return n;
    };
    std::function<void(uint32_t, uint32_t, int)> emit = [&](uint32_t ix, uint32_t iy, int level) {
        if (build(ix, iy, level).leaf) {
            codes.push_back(hc::makeCellCode(hc::mortonEncode(ix, iy), level));
            return;
        }
        if (level == 0) return;
        const uint32_t h = uint32_t{1} << (level - 1);
        emit(ix, iy, level - 1), emit(ix + h, iy, level - 1), emit(ix, iy + h, level - 1),
            emit(ix + h, iy + h, level - 1);
    };
    emit(0, 0, rootLevel);
    return codes;
}

// Every valid pixel against the cell covering it, for step k's depth: within the tolerance, wet exactly where wet.
void checkStep(const Raster& t, const Raster& d, const Grid& g, double tol) {
    const int depth = g.findLayer("water_depth");
    ASSERT_GE(depth, 0);
    for (size_t r = 0; r < t.height; ++r)
        for (size_t c = 0; c < t.width; ++c) {
            if (std::isnan(t.at(c, r))) continue;
            const double x = (double(c) + 0.5) * t.pixelSizeM, y = (double(t.height - 1 - r) + 0.5) * t.pixelSizeM;
            const auto cell = g.locate(x, y);
            ASSERT_TRUE(cell);
            const float v = g.values[size_t(depth)][*cell];
            ASSERT_LE(std::abs(double(d.at(c, r)) - v), tol) << "pixel " << c << "," << r;
            ASSERT_EQ(d.at(c, r) > 0, v > 0) << "a wet/dry edge of this step was blurred at " << c << "," << r;
        }
}

TEST_F(Steps, OneStructureKeepsEveryStepsEdgesAndIsNoFinerThanTheRule) {
    const Raster t = valley();
    const double levels[3] = {99.5, 101.2, 103.0};  // dry, a channel, most of the valley
    std::vector<Raster> depths;
    for (double l : levels) depths.push_back(tub(t, l));
    hc::ingest::WaterSteps steps;
    steps.count = 3;
    steps.timesS = {0, 3600, 7200};
    int loads = 0;
    steps.load = [&](size_t k) {
        ++loads;
        return depths[k];
    };
    hc::ingest::BuildOptions b;
    b.toleranceM = 0.2;
    b.maxLevel = 3;
    const hc::ingest::BuildSummary s = hc::ingest::buildGridFile(t, &steps, b, path("flood.hcg"), {});
    EXPECT_EQ(loads, 6) << "each step read twice: for the structure, then for its values";
    ASSERT_EQ(s.steps.size(), 3u);
    EXPECT_EQ(s.steps[0].wetCells, 0u);
    EXPECT_GT(s.steps[1].wetCells, 0u);
    EXPECT_GT(s.steps[2].wetCells, s.steps[1].wetCells);
    const Grid first = hc::readGrid(path("flood.hcg"), nullptr, 0);
    EXPECT_EQ(first.codes, referenceCells(t, depths, b.toleranceM, b.maxLevel, first.rootLevel))
        << "the structure is exactly the one the rule gives over all steps at once";
    for (size_t k = 0; k < 3; ++k) {
        SCOPED_TRACE("step " + std::to_string(k));
        const Grid g = hc::readGrid(path("flood.hcg"), nullptr, k);
        EXPECT_EQ(g.codes, first.codes);
        EXPECT_EQ(g.stepTimeS(), steps.timesS[k]);
        checkStep(t, depths[k], g, b.toleranceM);
    }
    // One step alone gives the grid a single-water build gives (the same cells and depths, so the same hash).
    const Grid alone = hc::ingest::buildGrid(t, &depths[1], b);
    EXPECT_EQ(alone.codes, referenceCells(t, {depths[1]}, b.toleranceM, b.maxLevel, alone.rootLevel));
    hc::ingest::WaterSteps one;
    one.count = 1;
    one.timesS = {0};
    one.load = [&](size_t) { return depths[1]; };
    hc::ingest::buildGridFile(t, &one, b, path("one.hcg"), {});
    EXPECT_EQ(hc::readGrid(path("one.hcg")).contentHash(), alone.contentHash());
    // A scenario is coarser than the union of nothing: fewer cells than pixels, more than the dry terrain alone.
    const Grid dry = hc::ingest::buildGrid(t, nullptr, b);
    EXPECT_GT(first.cellCount(), dry.cellCount())
        << "the wet/dry edges of step 1 and 2 split cells the terrain alone merges";
}

TEST_F(Steps, UnsortedTimesAndMismatchedStepsAreRefusedAndNothingIsWritten) {
    const Raster t = valley();
    hc::ingest::WaterSteps steps;
    steps.count = 2;
    steps.timesS = {60, 60};
    steps.load = [&](size_t) { return tub(t, 101); };
    hc::ingest::BuildOptions b;
    EXPECT_THROW(hc::ingest::buildGridFile(t, &steps, b, path("a.hcg"), {}), hc::Error);
    steps.timesS = {60, 30};
    EXPECT_THROW(hc::ingest::buildGridFile(t, &steps, b, path("a.hcg"), {}), hc::Error);
    steps.timesS = {0, 30};
    steps.load = [&](size_t k) {
        Raster d = tub(t, 101);
        if (k == 1) d.width -= 1, d.values.resize(d.width * d.height);
        return d;
    };
    try {
        hc::ingest::buildGridFile(t, &steps, b, path("a.hcg"), {});
        FAIL() << "a step of another size was accepted";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("water step 1"), std::string::npos) << e.what();
    }
    EXPECT_TRUE(fs::is_empty(dir_)) << "a refused scenario left a file";
    // The options: times that do not increase, or do not match the steps.
    hc::ingest::Options o;
    o.input = "x.tif";
    o.water = hc::ingest::WaterSource::Level;
    o.waterLevelsM = {100, 101, 102};
    o.timesS = {0, 20, 10};
    EXPECT_THROW(hc::ingest::validateOptions(o), hc::Error);
    o.timesS = {0, 10};
    EXPECT_THROW(hc::ingest::validateOptions(o), hc::Error);
    o.timesS = {0, 10, 20};
    EXPECT_NO_THROW(hc::ingest::validateOptions(o));
    o.waterLevelsM = {100, NAN};
    o.timesS.clear();
    EXPECT_THROW(hc::ingest::validateOptions(o), hc::Error);
}

// A series of real rasters: depth GeoTIFFs made from a real LiDAR DEM at three levels, ingested as three steps; a
// fourth on another grid (shifted by one pixel) is refused naming both files.
TEST_F(Steps, RasterSeriesFromRealData) {
    HC_REQUIRE_DATA(dem, "lidar1m_minnesota_utm15.tif");
    GDALAllRegister();
    std::unique_ptr<GDALDataset> src(GDALDataset::Open(dem.c_str(), GDAL_OF_RASTER));
    ASSERT_TRUE(src);
    const int w = src->GetRasterXSize(), h = src->GetRasterYSize();
    std::vector<float> z(size_t(w) * h);
    ASSERT_EQ(src->GetRasterBand(1)->RasterIO(GF_Read, 0, 0, w, h, z.data(), w, h, GDT_Float32, 0, 0, nullptr),
              CE_None);
    GDALDriver* gtiff = GetGDALDriverManager()->GetDriverByName("GTiff");
    auto make = [&](const std::string& name, double level, double shiftX) {
        const std::string p = path(name);
        std::unique_ptr<GDALDataset> ds(gtiff->CreateCopy(p.c_str(), src.get(), false, nullptr, nullptr, nullptr));
        std::vector<float> v(z.size());
        for (size_t i = 0; i < v.size(); ++i) v[i] = std::max(0.0f, float(level) - z[i]);
        EXPECT_EQ(ds->GetRasterBand(1)->RasterIO(GF_Write, 0, 0, w, h, v.data(), w, h, GDT_Float32, 0, 0, nullptr),
                  CE_None);
        if (shiftX != 0) {
            double gt[6];
            ds->GetGeoTransform(gt);
            gt[0] += shiftX;
            ds->SetGeoTransform(gt);
        }
        return p;
    };
    hc::ingest::Options o;
    o.input = dem;
    o.water = hc::ingest::WaterSource::Depth;
    o.waterPaths = {make("depth_1.tif", 394.5, 0), make("depth_2.tif", 395.5, 0), make("depth_10.tif", 396.5, 0)};
    o.timesS = {0, 1800, 3600};
    hc::ingest::LoadReport rep;
    const hc::ingest::BuildSummary s = hc::ingest::ingestToFile(o, path("series.hcg"), rep);
    ASSERT_EQ(s.steps.size(), 3u);
    EXPECT_LT(s.steps[0].wetCells, s.steps[1].wetCells);
    EXPECT_LT(s.steps[1].wetCells, s.steps[2].wetCells);
    EXPECT_GT(s.steps[0].wetCells, 100u) << "the lowest level must wet something for this test to mean anything";
    const Raster terrain = hc::ingest::loadTerrain(o, rep);
    for (size_t k = 0; k < 3; ++k) {
        SCOPED_TRACE("step " + std::to_string(k));
        const Grid g = hc::readGrid(path("series.hcg"), nullptr, k);
        EXPECT_EQ(g.stepTimeS(), o.timesS[k]);
        checkStep(terrain, hc::ingest::loadWater(o, terrain, rep, k), g, o.toleranceM);
    }
    o.waterPaths.push_back(make("depth_shifted.tif", 397, 1.0));
    o.timesS.push_back(5400);
    try {
        hc::ingest::ingestToFile(o, path("bad.hcg"), rep);
        FAIL() << "a step on another grid was accepted";
    } catch (const hc::Error& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("depth_shifted.tif"), std::string::npos) << m;
        EXPECT_NE(m.find("depth_1.tif"), std::string::npos) << m;
        EXPECT_NE(m.find("georeferencing"), std::string::npos) << m;
    }
    EXPECT_FALSE(fs::exists(path("bad.hcg")));
}

}  // namespace
