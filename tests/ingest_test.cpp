// Ingest on real rasters: every format and CRS case, the tolerance guarantee checked pixel by pixel,
// holes where nodata was, our reading compared with GDAL's own (read or warp), water layers, and the
// geometry extremes (south-up, rotated, 1x1, all-nodata).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>

#include <gdal_alg.h>
#include <gdal_priv.h>
#include <gdal_utils.h>
#include <ogr_spatialref.h>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/ingest/build.h"
#include "heightcast/ingest/ingest.h"
#include "temp_dir.h"
#include "test_data.h"
#include "ingest_world.h"

namespace {

namespace fs = std::filesystem;
using hc::Grid;
using hc::ingest::LoadReport;
using hc::ingest::Options;
using hc::ingest::Raster;

// The suites that write files, each test into a directory of its own.
class Ingest : public hc::test::TempDirTest {
protected:
    Ingest() : TempDirTest("hc_ingest_") {}
};
class Water : public hc::test::TempDirTest {
protected:
    Water() : TempDirTest("hc_ingest_water_") {}
};

using namespace hc::test::ingest;

struct RasterCase {
    const char* file;
    double tol;
    const char* sourceSrs;
    bool projectedAsIs;   // check against a plain GDAL read
    bool geographic;      // check against gdalwarp
    double minValidFrac;  // sanity: fraction of valid pixels expected at least
    double maxValidFrac;
};

class IngestRaster : public hc::test::TempDirTestWithParam<RasterCase> {
protected:
    IngestRaster() : TempDirTestWithParam("hc_ingest_raster_") {}
};

TEST_P(IngestRaster, GuaranteeHoldsPixelByPixel) {
    const RasterCase& c = GetParam();
    HC_REQUIRE_DATA(path, c.file);
    Options o;
    o.input = path;
    o.toleranceM = c.tol;
    o.sourceSrs = c.sourceSrs;
    Loaded l = load(o);
    checkGuarantee(l.terrain, nullptr, l.grid, c.tol);
    double frac = double(l.terrain.validCount()) / double(l.terrain.width * l.terrain.height);
    EXPECT_GE(frac, c.minValidFrac);
    EXPECT_LE(frac, c.maxValidFrac);
    if (c.projectedAsIs) checkSameAsGdalRead(path, l.terrain);
    // 2 mm: float32 rounding of our output (2.4e-4 m at 4000 m) plus position differences between
    // GeographicLib and PROJ (nanometres) and our 16-pixel lattice (below 1e-5 pixel) times slopes
    // of up to ~1000 m per pixel.
    if (c.geographic) checkSameAsProj(path, c.sourceSrs, l.terrain, 0.002);
    // Round trip through the file keeps everything.
    fs::path f = dir_ / (std::string(c.file) + ".hcg");
    hc::writeGrid(l.grid, f.string());
    Grid back = hc::readGrid(f.string());
    EXPECT_EQ(back.contentHash(), l.grid.contentHash());
    EXPECT_EQ(back.crsWkt, l.grid.crsWkt);
    // The grid carries its CRS's name as GDAL gave it at ingest (hc-info prints it), and the file keeps it.
    EXPECT_EQ(l.grid.crsName, l.report.gridCrsName);
    EXPECT_EQ(l.grid.crsName.empty(), l.grid.crsWkt.empty()) << l.grid.crsName;
    EXPECT_EQ(back.crsName, l.grid.crsName);
    fs::remove(f);
}

INSTANTIATE_TEST_SUITE_P(
    RealData, IngestRaster,
    ::testing::Values(
        RasterCase{"hef_srtm.tif", 0.25, "", false, true, 0.8, 1.0},              // GTiff Int16, EPSG:4326 -> UTM 32N
        RasterCase{"lidar1m_minnesota_utm15.tif", 0.25, "", true, false, 1, 1},   // 1 m LiDAR, NAD83 / UTM 15N
        RasterCase{"N00E010.hgt", 0.5, "", false, true, 0.95, 1.0},               // SRTMHGT at the equator
        RasterCase{"N00E011.hgt.zip", 0.5, "", false, true, 0.95, 1.0},           // zipped SRTMHGT
        RasterCase{"buscot_50m.asc", 0.05, "", false, false, 1, 1},               // ESRI ASCII, flat floodplain, no CRS
        RasterCase{"buscot_50m.asc", 0.1, "EPSG:27700", true, false, 1, 1},       // same, CRS named by --s_srs
        RasterCase{"west_bijou_gully_3m.asc", 0.25, "", false, false, 0.2, 0.4},  // NODATA_value 0, 72 % holes
        RasterCase{"kilauea_utm.nc", 1.0, "", true, false, 0.9, 1.0},             // NetCDF, UTM 5N, ocean nodata
        // NetCDF with NaN holes and no CRS, but CF units degrees_east: taken as WGS 84 and projected to UTM
        // (issue 11: degree grids were built as metres); the valid share drops from 0.81 to 0.77 with the
        // projected footprint's empty corners.
        RasterCase{"earth_relief_20m_holes.grd", 1.0, "", false, false, 0.7, 0.85},
        RasterCase{"south_glacier_utm7.tif", 0.25, "", true, false, 1, 1},           // Float64 samples
        RasterCase{"olinda_utm25s.tif", 0.25, "", true, false, 1, 1},                // UTM 25S, northing 9.1e6
        RasterCase{"tin_valid_3857.tif", 0.25, "", true, false, 0.85, 0.9},          // Web Mercator, x = -1.36e7
        RasterCase{"lux_elev.tif", 1.0, "", false, true, 0.4, 0.6},                  // geographic, 46 % nodata
        RasterCase{"boulder_srtmgl3.asc", 0.5, "EPSG:4326", false, true, 0.95, 1.0}  // degrees in an .asc, --s_srs
        ),
    [](const ::testing::TestParamInfo<RasterCase>& p) {
        std::string n = p.param.file;
        for (char& ch : n)
            if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
        return n + (p.param.sourceSrs[0] ? "_s_srs" : "");
    });

TEST_F(Ingest, TerrainRgbDecodesLikeTheReference) {
    HC_REQUIRE_DATA(png, "fuji_terrainrgb.png");
    HC_REQUIRE_DATA(ref, "fuji_terrainrgb_decoded.tif");  // decoded independently (Python), Float32
    Options o;
    o.input = png;
    o.terrainRgb = true;
    LoadReport rep;
    Raster r = hc::ingest::loadTerrain(o, rep);
    Options plain;
    plain.input = ref;
    Raster want = hc::ingest::loadTerrain(plain, rep);
    ASSERT_EQ(r.width, want.width);
    ASSERT_EQ(r.height, want.height);
    double maxDiff = 0;
    for (size_t i = 0; i < r.values.size(); ++i)
        maxDiff = std::max(maxDiff, std::abs(double(r.values[i]) - want.values[i]));
    EXPECT_LE(maxDiff, 1e-3);  // both are the 0.1 m steps rounded to float32
    Grid g = hc::ingest::ingest(o, rep);
    checkGuarantee(r, nullptr, g, o.toleranceM);
}

TEST_F(Ingest, SouthUpAndRotatedRastersLandWhereTheyBelong) {
    HC_REQUIRE_DATA(path, "lidar1m_minnesota_utm15.tif");
    Options o;
    o.input = path;
    LoadReport rep;
    Raster ref = hc::ingest::loadTerrain(o, rep);
    GDALAllRegister();
    GDALDriver* gtiff = GetGDALDriverManager()->GetDriverByName("GTiff");
    const double c = ref.pixelSizeM, x0 = ref.westWorld, y0 = ref.northWorld;
    const auto W = ref.width, H = ref.height;
    OGRSpatialReference srs;
    srs.importFromEPSG(26915);
    auto write = [&](const std::string& name, size_t w, size_t h, const double gt[6], auto&& value) {
        std::string p = (dir_ / name).string();
        std::unique_ptr<GDALDataset> ds(gtiff->Create(p.c_str(), int(w), int(h), 1, GDT_Float32, nullptr));
        ds->SetGeoTransform(const_cast<double*>(gt));
        ds->SetSpatialRef(&srs);
        std::vector<float> v(w * h);
        for (size_t j = 0; j < h; ++j)
            for (size_t i = 0; i < w; ++i) v[j * w + i] = value(i, j);
        EXPECT_EQ(ds->GetRasterBand(1)->RasterIO(GF_Write, 0, 0, int(w), int(h), v.data(), int(w), int(h), GDT_Float32,
                                                 0, 0, nullptr),
                  CE_None);
        return p;
    };
    // South-up: row 0 is the southern-most row.
    const double southUp[6] = {x0, c, 0, y0 - c * double(H), 0, c};
    std::string su = write("south_up.tif", W, H, southUp, [&](size_t i, size_t j) { return ref.at(i, H - 1 - j); });
    // Rotated by 90 degrees: stored pixel (i, j) is original (col j, row H-1-i).
    const double rotated[6] = {x0, 0, c, y0 - c * double(H), c, 0};
    std::string ro = write("rotated.tif", H, W, rotated, [&](size_t i, size_t j) { return ref.at(j, H - 1 - i); });
    for (const std::string& p : {su, ro}) {
        SCOPED_TRACE(p);
        Options po;
        po.input = p;
        LoadReport pr;
        Raster r = hc::ingest::loadTerrain(po, pr);
        ASSERT_EQ(r.width, W);
        ASSERT_EQ(r.height, H);
        EXPECT_NEAR(r.westWorld, x0, 1e-6);
        EXPECT_NEAR(r.northWorld, y0, 1e-6);
        EXPECT_EQ(r.pixelSizeM, c);
        double maxDiff = 0;
        for (size_t i = 0; i < r.values.size(); ++i)
            maxDiff = std::max(maxDiff, std::abs(double(r.values[i]) - ref.values[i]));
        EXPECT_LE(maxDiff, 1e-3) << "pixels moved (resampling at exact pixel centres must reproduce them)";
    }
}

// A geotransform rotated by a general angle (30 degrees) holding a tilted plane of world coordinates:
// ingest resamples it north-up (bilinear, which reproduces a plane), so every valid pixel equals the
// plane at its own centre (1 mm: float32 of 100-200 m values) where it lies between source pixel centres,
// pixels well inside the rotated footprint
// are valid and pixels well outside it are holes. A mirrored or shifted placement fails both.
TEST_F(Ingest, RotatedByThirtyDegreesLandsWhereItBelongs) {
    const double angle = 30 * M_PI / 180, c = 10, x0 = 500000, y0 = 5000000;
    const int W = 40, H = 30;
    // Column direction (cos a, sin a) * c, row direction (sin a, -cos a) * c: a north-up raster turned 30 degrees
    // anticlockwise about its north-west corner.
    const double gt[6] = {x0, c * std::cos(angle), c * std::sin(angle), y0, c * std::sin(angle), -c * std::cos(angle)};
    auto plane = [&](double x, double y) { return 150.0 + 0.05 * (x - x0) - 0.03 * (y - y0); };
    GDALAllRegister();
    const std::string path = (dir_ / "rotated30.tif").string();
    {
        std::unique_ptr<GDALDataset> ds(
            GetGDALDriverManager()->GetDriverByName("GTiff")->Create(path.c_str(), W, H, 1, GDT_Float32, nullptr));
        ds->SetGeoTransform(const_cast<double*>(gt));
        OGRSpatialReference srs;
        srs.importFromEPSG(32633);
        ds->SetSpatialRef(&srs);
        std::vector<float> v(size_t(W) * H);
        for (int j = 0; j < H; ++j)
            for (int i = 0; i < W; ++i) {
                const double x = gt[0] + (i + 0.5) * gt[1] + (j + 0.5) * gt[2],
                             y = gt[3] + (i + 0.5) * gt[4] + (j + 0.5) * gt[5];
                v[size_t(j) * W + size_t(i)] = float(plane(x, y));
            }
        ASSERT_EQ(ds->GetRasterBand(1)->RasterIO(GF_Write, 0, 0, W, H, v.data(), W, H, GDT_Float32, 0, 0, nullptr),
                  CE_None);
    }
    Options o;
    o.input = path;
    LoadReport rep;
    const Raster r = hc::ingest::loadTerrain(o, rep);
    EXPECT_NE(rep.method.find("rotated geotransform"), std::string::npos) << rep.method;
    EXPECT_DOUBLE_EQ(r.pixelSizeM, c);
    // Where a world point falls in the source's pixel grid (column, row as fractions of W and H).
    const double det = gt[1] * gt[5] - gt[2] * gt[4];
    size_t valid = 0, inside = 0, outside = 0;
    double worst = 0, worstRim = 0;
    for (size_t j = 0; j < r.height; ++j)
        for (size_t i = 0; i < r.width; ++i) {
            const double x = r.westWorld + (double(i) + 0.5) * c, y = r.northWorld - (double(j) + 0.5) * c;
            const double dx = x - gt[0], dy = y - gt[3];
            const double col = (gt[5] * dx - gt[2] * dy) / det, row = (-gt[4] * dx + gt[1] * dy) / det;
            const bool wellInside = col > 1.5 && col < W - 1.5 && row > 1.5 && row < H - 1.5;
            const bool wellOutside = col < -1.5 || col > W + 1.5 || row < -1.5 || row > H + 1.5;
            const float v = r.at(i, j);
            if (!std::isnan(v)) {
                ++valid;
                const double err = std::abs(double(v) - plane(x, y));
                if (col >= 0.5 && col <= W - 0.5 && row >= 0.5 && row <= H - 0.5)
                    worst = std::max(worst, err);
                else
                    worstRim = std::max(worstRim, err);
            }
            if (wellInside) {
                ++inside;
                EXPECT_FALSE(std::isnan(v)) << "pixel " << i << "," << j << " inside the footprint is a hole";
            }
            if (wellOutside) {
                ++outside;
                EXPECT_TRUE(std::isnan(v)) << "pixel " << i << "," << j << " outside the footprint has a value";
            }
        }
    EXPECT_GT(inside, 800u);
    EXPECT_GT(outside, 300u);
    EXPECT_GT(valid, inside);
    EXPECT_LE(worst, 1e-3) << "valid pixels off the plane: misplaced";
    // Within half a source pixel of the footprint's edge the value is the nearest edge pixel's: off the plane
    // by at most its gradient (0.058 m/m) times half a pixel diagonal (7.1 m), 0.41 m.
    EXPECT_LE(worstRim, 0.41);
    Grid g = hc::ingest::ingest(o, rep);
    checkGuarantee(r, nullptr, g, o.toleranceM);
}

TEST_F(Ingest, NearlySquarePixelsAreKeptOthersResampled) {
    // 50 x 50.001 m pixels (0.002 % apart) are square for ingest; 50 x 60 m are resampled to 50 m.
    fs::path d = dir_;
    GDALAllRegister();
    GDALDriver* gtiff = GetGDALDriverManager()->GetDriverByName("GTiff");
    OGRSpatialReference srs;
    srs.importFromEPSG(32633);
    auto make = [&](const std::string& name, double dy) {
        std::string p = (d / name).string();
        std::unique_ptr<GDALDataset> ds(gtiff->Create(p.c_str(), 20, 10, 1, GDT_Float32, nullptr));
        double gt[6] = {400000, 50, 0, 5000000, 0, -dy};
        ds->SetGeoTransform(gt);
        ds->SetSpatialRef(&srs);
        std::vector<float> v(200);
        for (size_t i = 0; i < v.size(); ++i) v[i] = 100.0f + float(i % 20) + 10.0f * float(i / 20);  // a plane
        EXPECT_EQ(ds->GetRasterBand(1)->RasterIO(GF_Write, 0, 0, 20, 10, v.data(), 20, 10, GDT_Float32, 0, 0, nullptr),
                  CE_None);
        return p;
    };
    Options o;
    LoadReport rep;
    o.input = make("nearly.tif", 50.001);
    Raster r = hc::ingest::loadTerrain(o, rep);
    EXPECT_EQ(r.width, 20u);
    EXPECT_EQ(r.height, 10u);
    EXPECT_EQ(r.pixelSizeM, 50.0);
    EXPECT_EQ(r.at(3, 2), 123.0f) << "kept as is: no resampling";
    ASSERT_FALSE(rep.warnings.empty()) << "the 1 cm shift of the south edge is reported";
    LoadReport rep2;
    o.input = make("oblong.tif", 60);
    Raster q = hc::ingest::loadTerrain(o, rep2);
    EXPECT_EQ(q.pixelSizeM, 50.0);
    EXPECT_EQ(q.height, 12u);  // 600 m of extent in 50 m rows
    EXPECT_NE(rep2.method.find("resampled"), std::string::npos) << rep2.method;
    // A plane is reproduced exactly by bilinear interpolation, away from the clamped edges.
    EXPECT_NEAR(q.at(5, 6), 100.0 + (5.5 * 50 / 50 - 0.5) + 10.0 * ((6.5 * 50) / 60 - 0.5), 1e-3);
}

TEST_F(Ingest, SinglePixelAndAllNodata) {
    fs::path d = dir_;
    {
        std::ofstream one(d / "one.asc");
        one << "ncols 1\nnrows 1\nxllcorner 500\nyllcorner 700\ncellsize 10\nNODATA_value -9999\n42.5\n";
        std::ofstream none(d / "none.asc");
        none << "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 10\nNODATA_value -9999\n-9999 -9999\n-9999 "
                "-9999\n";
    }
    Options o;
    o.input = (d / "one.asc").string();
    LoadReport rep;
    Grid g = hc::ingest::ingest(o, rep);
    ASSERT_EQ(g.cellCount(), 1u);
    EXPECT_EQ(g.values[0][0], 42.5f);
    EXPECT_EQ(g.rootLevel, 0);
    EXPECT_EQ(g.originWorldX, 500.0);
    EXPECT_EQ(g.originWorldY, 700.0);
    o.input = (d / "none.asc").string();
    try {
        hc::ingest::ingest(o, rep);
        FAIL() << "an all-nodata raster was accepted";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("none.asc"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("nodata"), std::string::npos) << e.what();
    }
}

TEST_F(Ingest, RefusesWhatNoUtmZoneHolds) {
    HC_REQUIRE_DATA(path, "etopo1_1deg.tif");
    Options o;
    o.input = path;
    LoadReport rep;
    try {
        hc::ingest::ingest(o, rep);
        FAIL();
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("--t_srs"), std::string::npos) << e.what();
    }
}

TEST_F(Ingest, TargetSrsWarpsWithGdal) {
    HC_REQUIRE_DATA(path, "hef_srtm.tif");
    Options o;
    o.input = path;
    o.targetSrs = "EPSG:31254";  // MGI / Austria GK West: a national CRS for the Oetztal
    o.toleranceM = 0.5;
    Loaded l = load(o);
    EXPECT_NE(l.report.gridCrsName.find("31254"), std::string::npos) << l.report.gridCrsName;
    checkGuarantee(l.terrain, nullptr, l.grid, o.toleranceM);
    o.targetSrs = "EPSG:4326";
    LoadReport rep;
    EXPECT_THROW(hc::ingest::loadTerrain(o, rep), hc::Error) << "a geographic target is not metric";
}

TEST_F(Ingest, FeetAreConvertedToMetres) {
    HC_REQUIRE_DATA(path, "lidar1m_minnesota_utm15.tif");
    // The same raster declared in US survey feet (a State Plane CRS): coordinates are scaled to metres.
    GDALAllRegister();
    fs::path p = dir_ / "feet.tif";
    std::unique_ptr<GDALDataset> src(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER));
    std::unique_ptr<GDALDataset> dst(GetGDALDriverManager()->GetDriverByName("GTiff")->CreateCopy(
        p.string().c_str(), src.get(), false, nullptr, nullptr, nullptr));
    OGRSpatialReference ft;
    ft.importFromEPSG(2243);  // NAD83 / Idaho West (ftUS)
    dst->SetSpatialRef(&ft);
    double gt[6] = {1000000, 3, 0, 2000000, 0, -3};  // 3 ftUS pixels
    dst->SetGeoTransform(gt);
    dst.reset();
    Options o;
    o.input = p.string();
    LoadReport rep;
    Raster r = hc::ingest::loadTerrain(o, rep);
    const double ftUS = 1200.0 / 3937.0;
    EXPECT_NEAR(r.pixelSizeM, 3 * ftUS, 1e-12);
    EXPECT_NEAR(r.westWorld, 1000000 * ftUS, 1e-6);
    EXPECT_NE(r.crsWkt.find("metre"), std::string::npos);
}

TEST_F(Water, BathtubFillsFromTheBoundaryOnly) {
    // A basin open to the west edge, and a closed pit ringed by a wall above the water level.
    Raster t;
    t.width = 40;
    t.height = 30;
    t.pixelSizeM = 2;
    t.northWorld = 100;
    t.values.assign(t.width * t.height, 20.0f);
    for (size_t r = 5; r < 25; ++r)
        for (size_t c = 0; c < 15; ++c) t.at(c, r) = 5.0f + 0.1f * float(c);  // open basin
    for (size_t r = 10; r < 20; ++r)
        for (size_t c = 25; c < 35; ++c) t.at(c, r) = 2.0f;  // closed pit
    Options o;
    o.water = hc::ingest::WaterSource::Level;
    o.waterLevelM = 10;
    LoadReport rep;
    Raster d = hc::ingest::loadWater(o, t, rep);
    EXPECT_FLOAT_EQ(d.at(0, 10), 5.0f);
    EXPECT_FLOAT_EQ(d.at(10, 10), 10.0f - (5.0f + 1.0f));
    EXPECT_EQ(d.at(30, 15), 0.0f) << "a closed pit below the level stays dry";
    EXPECT_EQ(d.at(20, 2), 0.0f) << "ground above the level stays dry";
    hc::ingest::BuildOptions b;
    b.maxLevel = 4;
    Grid g = hc::ingest::buildGrid(t, &d, b);
    ASSERT_EQ(g.layers.size(), 2u);
    EXPECT_EQ(g.layers[1].name, "water_depth");
    checkGuarantee(t, &d, g, b.toleranceM);
}

TEST_F(Water, DepthAndSurfaceRastersMatchTheBathtub) {
    HC_REQUIRE_DATA(path, "lidar1m_minnesota_utm15.tif");
    // Water rasters made from the DEM itself: a surface at 395 m everywhere, and its depth.
    GDALAllRegister();
    std::unique_ptr<GDALDataset> src(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER));
    GDALDriver* gtiff = GetGDALDriverManager()->GetDriverByName("GTiff");
    const int w = src->GetRasterXSize(), h = src->GetRasterYSize();
    std::vector<float> z(size_t(w) * h);
    ASSERT_EQ(src->GetRasterBand(1)->RasterIO(GF_Read, 0, 0, w, h, z.data(), w, h, GDT_Float32, 0, 0, nullptr),
              CE_None);
    auto make = [&](const std::string& name, auto&& f) {
        std::string p = (dir_ / name).string();
        std::unique_ptr<GDALDataset> ds(gtiff->CreateCopy(p.c_str(), src.get(), false, nullptr, nullptr, nullptr));
        std::vector<float> v(z.size());
        for (size_t i = 0; i < v.size(); ++i) v[i] = f(z[i]);
        EXPECT_EQ(ds->GetRasterBand(1)->RasterIO(GF_Write, 0, 0, w, h, v.data(), w, h, GDT_Float32, 0, 0, nullptr),
                  CE_None);
        return p;
    };
    std::string depth = make("depth.tif", [](float zz) { return std::max(0.0f, 395.0f - zz); });
    std::string surface = make("surface.tif", [](float) { return 395.0f; });
    for (auto [mode, file] :
         {std::pair{hc::ingest::WaterSource::Depth, depth}, {hc::ingest::WaterSource::Surface, surface}}) {
        Options o;
        o.input = path;
        o.water = mode;
        o.waterPath = file;
        LoadReport rep;
        Raster t = hc::ingest::loadTerrain(o, rep);
        Raster d = hc::ingest::loadWater(o, t, rep);
        size_t wet = 0;
        for (size_t i = 0; i < d.values.size(); ++i) {
            // Same grid, so the bilinear warp samples exactly at pixel centres: float rounding only.
            ASSERT_NEAR(d.values[i], std::max(0.0f, 395.0f - t.values[i]), 1e-3) << "pixel " << i;
            wet += d.values[i] > 0;
        }
        EXPECT_GT(wet, d.values.size() / 10);
        Grid g = hc::ingest::ingest(o, rep);
        checkGuarantee(t, &d, g, o.toleranceM);
    }
}

TEST(Options, AbsurdValuesAreRefused) {
    auto refused = [](auto&& edit) {
        Options o;
        o.input = "x.tif";
        edit(o);
        EXPECT_THROW(hc::ingest::validateOptions(o), hc::Error);
    };
    refused([](Options& o) { o.toleranceM = -1; });
    refused([](Options& o) { o.toleranceM = NAN; });
    refused([](Options& o) {
        o.minCellM = 10;
        o.maxCellM = 5;
    });
    refused([](Options& o) { o.minCellM = 0; });
    refused([](Options& o) { o.band = 0; });
    refused([](Options& o) { o.zScale = 0; });
    refused([](Options& o) {
        o.terrainRgb = true;
        o.band = 2;
    });
    refused([](Options& o) { o.water = hc::ingest::WaterSource::Depth; });
    HC_REQUIRE_DATA(path, "hef_srtm.tif");
    Options o;
    o.input = path;
    o.band = 2;
    LoadReport rep;
    EXPECT_THROW(hc::ingest::loadTerrain(o, rep), hc::Error);
}

}  // namespace

namespace {

TEST_F(Ingest, StreamedFileEqualsInMemoryGrid) {
    HC_REQUIRE_DATA(path, "lidar1m_minnesota_utm15.tif");
    for (bool water : {false, true}) {
        Options o;
        o.input = path;
        if (water) o.water = hc::ingest::WaterSource::Level, o.waterLevelM = 397;
        LoadReport rep;
        Grid mem = hc::ingest::ingest(o, rep);
        fs::path f = dir_ / "streamed.hcg";
        hc::ingest::BuildSummary s = hc::ingest::ingestToFile(o, f.string(), rep);
        Grid back = hc::readGrid(f.string());
        EXPECT_EQ(back.contentHash(), mem.contentHash());
        EXPECT_EQ(s.cellCount, mem.cellCount());
        EXPECT_EQ(s.cellsPerLevel, mem.cellsPerLevel());
        EXPECT_EQ(back.stats.maxDevM, mem.stats.maxDevM);
        EXPECT_EQ(back.stats.validPixels, mem.stats.validPixels);
        EXPECT_EQ(back.crsName, "NAD83 / UTM zone 15N (EPSG:26915)") << "the streamed file stores the CRS name too";
        EXPECT_EQ(back.crsName, mem.crsName);
        size_t wet = 0;
        if (water)
            for (float d : mem.values[1]) wet += d > 0;
        EXPECT_EQ(s.wetCells, wet);
        if (water) {
            EXPECT_GT(wet, 1000u) << "the flood must reach something for this test to mean anything";
        }
        fs::remove(f);
    }
}

}  // namespace
