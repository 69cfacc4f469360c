// Exports read back with each format's own library: GeoTIFF through GDAL, EXR through OpenEXR, VDB
// through OpenVDB; each compared with the exact evaluator.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>

#include <ImfChannelList.h>
#include <ImfDoubleAttribute.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfStringAttribute.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>
#if HC_WITH_VDB
#include <openvdb/openvdb.h>
#endif

#include "heightcast/export/export.h"
#include "heightcast/core/error.h"
#include "heightcast/ingest/ingest.h"
#include "temp_dir.h"
#include "test_data.h"

namespace {

namespace fs = std::filesystem;
using hc::exporting::SampledRaster;

struct Scene {
    hc::Grid grid;
    hc::influence::InfluenceLists lists;
    std::unique_ptr<hc::influence::SurfaceEvaluator> eval;
};

// The bundled demo DEM with a bathtub flood: geographic input projected to UTM, holes at the corners.
Scene& scene() {
    static Scene s = [] {
        Scene sc;
        hc::ingest::Options o;
        o.input = hc::test::dataFile("hef_srtm.tif");
        o.water = hc::ingest::WaterSource::Level;
        o.waterLevelM = 2600;
        hc::ingest::LoadReport r;
        sc.grid = hc::ingest::ingest(o, r);
        sc.lists = hc::influence::buildInfluenceLists(sc.grid, {});
        sc.eval = std::make_unique<hc::influence::SurfaceEvaluator>(sc.grid, sc.lists);
        return sc;
    }();
    return s;
}

class Export : public hc::test::TempDirTest {
protected:
    Export() : TempDirTest("hc_export_") {}
};
class ExportWater : public hc::test::TempDirTest {
protected:
    ExportWater() : TempDirTest("hc_export_water_") {}
};

SampledRaster sample(const std::string& layer, double res, bool gradients = false) {
    Scene& s = scene();
    return hc::exporting::sampleSurface(*s.eval, hc::influence::Layer::byName(s.grid, layer), layer, res, std::nullopt,
                                        gradients, 0, false);
}

TEST_F(Export, SamplesAreTheExactSurfaceAtPixelCentres) {
    Scene& s = scene();
    SampledRaster r = sample("elevation", 250);
    ASSERT_GT(r.definedCount(), r.values.size() / 2);
    ASSERT_LT(r.definedCount(), r.values.size()) << "the projected footprint leaves holes at the corners";
    for (size_t row = 0; row < r.height; row += 7)
        for (size_t col = 0; col < r.width; col += 5) {
            double x = r.westWorld + (double(col) + 0.5) * r.pixelSizeM - s.grid.originWorldX;
            double y = r.northWorld - (double(row) + 0.5) * r.pixelSizeM - s.grid.originWorldY;
            auto v = s.eval->value(x, y, hc::influence::Layer{});
            float got = r.values[row * r.width + col];
            if (!v) {
                EXPECT_TRUE(std::isnan(got));
                continue;
            }
            EXPECT_EQ(got, static_cast<float>(*v));  // rounded once, to float32
        }
}

TEST_F(Export, RefusesAbsurdRequests) {
    Scene& s = scene();
    auto layer = hc::influence::Layer{};
    EXPECT_THROW(hc::exporting::sampleSurface(*s.eval, layer, "elevation", 0, std::nullopt, false, 0, false),
                 hc::Error);
    EXPECT_THROW(hc::exporting::sampleSurface(*s.eval, layer, "elevation", 0.001, std::nullopt, false, 0, false),
                 hc::Error)
        << "a raster of 6e14 pixels must be refused before any allocation";
    EXPECT_THROW(hc::exporting::sampleSurface(*s.eval, layer, "elevation", 10, hc::exporting::BoxWorld{5, 5, 1, 1},
                                              false, 0, false),
                 hc::Error);
}

TEST_F(Export, GeoTiffReadsBackThroughGdal) {
    Scene& s = scene();
    SampledRaster r = sample("elevation", 200);
    const std::string path = (dir_ / "e.tif").string();
    hc::exporting::writeGeoTiff(r, path);
    GDALAllRegister();
    std::unique_ptr<GDALDataset> ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
    ASSERT_TRUE(ds);
    ASSERT_EQ(ds->GetRasterXSize(), int(r.width));
    ASSERT_EQ(ds->GetRasterYSize(), int(r.height));
    double gt[6];
    ASSERT_EQ(ds->GetGeoTransform(gt), CE_None);
    EXPECT_EQ(gt[0], r.westWorld);
    EXPECT_EQ(gt[3], r.northWorld);
    EXPECT_EQ(gt[1], 200.0);
    EXPECT_EQ(gt[5], -200.0);
    OGRSpatialReference want;
    want.importFromWkt(s.grid.crsWkt.c_str());
    ASSERT_TRUE(ds->GetSpatialRef());
    EXPECT_TRUE(ds->GetSpatialRef()->IsSame(&want)) << "CRS lost";
    GDALRasterBand* b = ds->GetRasterBand(1);
    int has = 0;
    const double nd = b->GetNoDataValue(&has);
    ASSERT_TRUE(has);
    std::vector<float> v(r.values.size());
    ASSERT_EQ(b->RasterIO(GF_Read, 0, 0, int(r.width), int(r.height), v.data(), int(r.width), int(r.height),
                          GDT_Float32, 0, 0, nullptr),
              CE_None);
    for (size_t i = 0; i < v.size(); ++i) {
        if (std::isnan(r.values[i])) {
            ASSERT_EQ(v[i], static_cast<float>(nd)) << "a hole must be nodata, pixel " << i;
        } else {
            ASSERT_EQ(v[i], r.values[i]) << "pixel " << i;
        }
    }
}

TEST_F(Export, ExrReadsBackThroughOpenExr) {
    SampledRaster r = sample("water_depth", 200);
    const std::string path = (dir_ / "d.exr").string();
    hc::exporting::writeExr(r, path);
    Imf::InputFile in(path.c_str());
    const Imf::Header& h = in.header();
    ASSERT_TRUE(h.channels().findChannel("water_depth"));
    ASSERT_TRUE(h.channels().findChannel("A"));
    EXPECT_EQ(h.typedAttribute<Imf::DoubleAttribute>("heightcast.gridOriginX").value(), r.originWorldX);
    EXPECT_EQ(h.typedAttribute<Imf::DoubleAttribute>("heightcast.gridOriginY").value(), r.originWorldY);
    EXPECT_EQ(h.typedAttribute<Imf::DoubleAttribute>("heightcast.rasterNorthWestX").value(), r.westWorld);
    EXPECT_EQ(h.typedAttribute<Imf::DoubleAttribute>("heightcast.rasterNorthWestY").value(), r.northWorld);
    EXPECT_EQ(h.typedAttribute<Imf::DoubleAttribute>("heightcast.pixelSizeM").value(), 200.0);
    EXPECT_EQ(h.typedAttribute<Imf::StringAttribute>("heightcast.crsWkt").value(), r.crsWkt);
    auto dw = h.dataWindow();
    ASSERT_EQ(size_t(dw.max.x - dw.min.x + 1), r.width);
    ASSERT_EQ(size_t(dw.max.y - dw.min.y + 1), r.height);
    std::vector<float> v(r.values.size()), a(r.values.size());
    Imf::FrameBuffer fb;
    fb.insert("water_depth", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(v.data()), 4, 4 * r.width));
    fb.insert("A", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(a.data()), 4, 4 * r.width));
    in.setFrameBuffer(fb);
    in.readPixels(dw.min.y, dw.max.y);
    size_t wet = 0;
    for (size_t i = 0; i < v.size(); ++i) {
        if (std::isnan(r.values[i])) {
            ASSERT_TRUE(std::isnan(v[i]));
            ASSERT_EQ(a[i], 0.0f);
        } else {
            ASSERT_EQ(v[i], r.values[i]);
            ASSERT_EQ(a[i], 1.0f);
            wet += v[i] > 0;
        }
    }
    EXPECT_GT(wet, 100u);
}

#if HC_WITH_VDB
TEST_F(Export, VdbLevelSetsCrossZeroOnTheSurface) {
    EXPECT_TRUE(hc::exporting::vdbAvailable());
    SampledRaster terrain = sample("elevation", 100, true);
    SampledRaster water = sample("water_surface", 100, true);
    ASSERT_GT(water.definedCount(), 100u);
    const std::string path = (dir_ / "s.vdb").string();
    hc::exporting::writeVdb(terrain, &water, path);
    openvdb::initialize();
    openvdb::io::File file(path);
    file.open();
    auto grids = file.getGrids();
    file.close();
    ASSERT_EQ(grids->size(), 2u);
    for (const auto& base : *grids) {
        auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
        ASSERT_TRUE(grid);
        EXPECT_EQ(grid->getGridClass(), openvdb::GRID_LEVEL_SET);
        const SampledRaster& r = grid->getName() == "terrain" ? terrain : water;
        ASSERT_TRUE(grid->getName() == "terrain" || grid->getName() == "water_surface") << grid->getName();
        EXPECT_EQ(grid->metaValue<double>("heightcast.gridOriginX"), r.originWorldX);
        EXPECT_EQ(grid->metaValue<double>("heightcast.gridOriginY"), r.originWorldY);
        EXPECT_EQ(grid->metaValue<double>("heightcast.rasterSouthWestX"), r.westWorld);
        EXPECT_NEAR(grid->metaValue<double>("heightcast.rasterSouthWestY"), r.northWorld - double(r.height) * 100.0,
                    1e-6);
        EXPECT_NEAR(grid->voxelSize()[0], 100.0, 1e-12);
        auto acc = grid->getConstAccessor();
        size_t checked = 0;
        for (size_t row = 0; row < r.height; row += 3)
            for (size_t col = 0; col < r.width; col += 3) {
                const float h = r.values[row * r.width + col];
                if (std::isnan(h)) continue;
                const int i = int(col), j = int(r.height - 1 - row);
                const int k = int(std::floor(h / 100.0));
                const float below = acc.getValue(openvdb::Coord(i, j, k)),
                            above = acc.getValue(openvdb::Coord(i, j, k + 1));
                ASSERT_LE(below, 0.0f) << grid->getName() << " col " << col << " row " << row;
                ASSERT_GT(above, 0.0f);
                // The zero crossing, interpolated between the two voxels, lies at the surface height,
                // within what the slope projection changes (both scale by the same cosine).
                const double zCross = k * 100.0 + 100.0 * (-below) / (above - below);
                ASSERT_NEAR(zCross, h, 1e-3 * 100.0);
                // The voxel centre's world position is the pixel centre's.
                const auto world = grid->transform().indexToWorld(openvdb::Coord(i, j, 0));
                ASSERT_NEAR(world.x() + r.westWorld, r.westWorld + (double(col) + 0.5) * 100.0, 1e-6);
                ++checked;
            }
        EXPECT_GT(checked, 50u);
    }
}
#else
// A build without OpenVDB (-DHC_WITH_VDB=OFF) refuses .vdb, naming the file and the option, and writes nothing.
TEST_F(Export, VdbBuiltOutIsRefused) {
    EXPECT_FALSE(hc::exporting::vdbAvailable());
    SampledRaster terrain = sample("elevation", 100, true);
    const std::string path = (dir_ / "s.vdb").string();
    try {
        hc::exporting::writeVdb(terrain, nullptr, path);
        FAIL() << "writeVdb wrote in a build without OpenVDB";
    } catch (const hc::Error& e) {
        EXPECT_NE(std::string(e.what()).find("s.vdb"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("HC_WITH_VDB"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(std::filesystem::exists(path));
}
#endif

// The two georeference frames apart (export.h): on a raster whose corner lies away from the grid's origin,
// gridOrigin stays the grid's origin and the raster corners are the origin plus the corner's local offset.
// A writer that stored one for the other (as heightcast.originX once meant the origin in .exr and the raster
// corner in .vdb) fails here. 1e-6 m: world y is summed from offsets near 5e6 m (a double's step there is 1e-9 m).
TEST_F(Export, GridOriginAndRasterCornersAreDistinctAttributes) {
    Scene& s = scene();
    const double res = 100, offX = 1200, offY = 700;  // the raster's south-west corner, local [m]
    const size_t cols = 20, rows = 15;
    const hc::exporting::BoxWorld box{s.grid.originWorldX + offX, s.grid.originWorldY + offY,
                                      s.grid.originWorldX + offX + double(cols) * res,
                                      s.grid.originWorldY + offY + double(rows) * res};
    SampledRaster r =
        hc::exporting::sampleSurface(*s.eval, hc::influence::Layer{}, "elevation", res, box, true, 0, false);
    ASSERT_EQ(r.width, cols);
    ASSERT_EQ(r.height, rows);

    const std::string exrPath = (dir_ / "corner.exr").string();
    hc::exporting::writeExr(r, exrPath);
    Imf::InputFile in(exrPath.c_str());
    const Imf::Header& h = in.header();
    auto exrDouble = [&](const char* name) { return h.typedAttribute<Imf::DoubleAttribute>(name).value(); };
    EXPECT_EQ(exrDouble("heightcast.gridOriginX"), s.grid.originWorldX);
    EXPECT_EQ(exrDouble("heightcast.gridOriginY"), s.grid.originWorldY);
    EXPECT_NEAR(exrDouble("heightcast.rasterNorthWestX"), s.grid.originWorldX + offX, 1e-6);
    EXPECT_NEAR(exrDouble("heightcast.rasterNorthWestY"), s.grid.originWorldY + offY + double(rows) * res, 1e-6);
#if HC_WITH_VDB
    const std::string vdbPath = (dir_ / "corner.vdb").string();
    hc::exporting::writeVdb(r, nullptr, vdbPath);
    openvdb::initialize();
    openvdb::io::File file(vdbPath);
    file.open();
    auto grids = file.getGrids();
    file.close();
    ASSERT_EQ(grids->size(), 1u);
    const auto& grid = (*grids)[0];
    EXPECT_EQ(grid->metaValue<double>("heightcast.gridOriginX"), s.grid.originWorldX);
    EXPECT_EQ(grid->metaValue<double>("heightcast.gridOriginY"), s.grid.originWorldY);
    EXPECT_NEAR(grid->metaValue<double>("heightcast.rasterSouthWestX"), s.grid.originWorldX + offX, 1e-6);
    EXPECT_NEAR(grid->metaValue<double>("heightcast.rasterSouthWestY"), s.grid.originWorldY + offY, 1e-6);
#endif
}

TEST_F(Export, FailedWritesLeaveNothing) {
    SampledRaster r = sample("elevation", 500);
    fs::path d = dir_ / "nothing";
    fs::create_directories(d);
    EXPECT_THROW(hc::exporting::writeGeoTiff(r, (d / "missing_dir" / "x.tif").string()), hc::Error);
    EXPECT_THROW(hc::exporting::writeExr(r, (d / "missing_dir" / "x.exr").string()), hc::Error);
    EXPECT_THROW(hc::exporting::writeVdb(r, nullptr, (d / "missing_dir" / "x.vdb").string()), hc::Error);
    EXPECT_TRUE(fs::is_empty(d));
}

// ---------------------------------------------------------------------------------------------------------
// The water level field (docs/design.md section 6; issue 11, "The water surface is not level"): the exports
// carry what hc-probe and the renderers show. The demo flood is a bathtub at 2600 m, so the exported water
// surface is flat at 2600 m (1 cm, the figure; float32 storage rounds to 2.4e-4 m there), the
// exported depth is that surface minus the exported elevation where there is water (1 mm: three float32
// roundings of values near 2600 m) and 0 on dry land, and the VDB's water level set crosses zero at 2600 m.

// Band 1 of a GeoTIFF written by writeGeoTiff, nodata as NaN.
std::vector<float> readGeoTiff(const std::string& path, const SampledRaster& r) {
    GDALAllRegister();
    std::unique_ptr<GDALDataset> ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
    EXPECT_TRUE(ds);
    if (!ds) return {};
    GDALRasterBand* b = ds->GetRasterBand(1);
    int has = 0;
    const float nd = static_cast<float>(b->GetNoDataValue(&has));
    EXPECT_TRUE(has);
    std::vector<float> v(r.width * r.height);
    EXPECT_EQ(b->RasterIO(GF_Read, 0, 0, int(r.width), int(r.height), v.data(), int(r.width), int(r.height),
                          GDT_Float32, 0, 0, nullptr),
              CE_None);
    for (float& x : v)
        if (x == nd) x = std::numeric_limits<float>::quiet_NaN();
    return v;
}

TEST_F(ExportWater, BathtubFloodExportsFlatWithDepthToTheTerrain) {
    const double level = 2600;
    const double res = 100;
    SampledRaster zr = sample("elevation", res), sr = sample("water_surface", res), dr = sample("water_depth", res);
    hc::exporting::writeGeoTiff(sr, (dir_ / "ws.tif").string());
    hc::exporting::writeGeoTiff(dr, (dir_ / "wd.tif").string());
    const std::vector<float> surface = readGeoTiff((dir_ / "ws.tif").string(), sr),
                             depth = readGeoTiff((dir_ / "wd.tif").string(), dr);
    ASSERT_EQ(surface.size(), zr.values.size());
    ASSERT_EQ(depth.size(), zr.values.size());
    size_t wet = 0, dry = 0;
    double worst = 0;
    for (size_t i = 0; i < zr.values.size(); ++i) {
        const float z = zr.values[i];
        if (std::isnan(z)) {
            ASSERT_TRUE(std::isnan(surface[i]) && std::isnan(depth[i])) << "pixel " << i << ": water in a hole";
            continue;
        }
        ASSERT_FALSE(std::isnan(depth[i])) << "pixel " << i << ": the depth is defined wherever the terrain is";
        if (std::isnan(surface[i])) {
            ++dry;
            ASSERT_EQ(depth[i], 0.0f) << "pixel " << i << ": dry land has depth 0";
            continue;
        }
        ++wet;
        worst = std::max(worst, std::abs(double(surface[i]) - level));
        ASSERT_GT(depth[i], 0.0f) << "pixel " << i;
        ASSERT_NEAR(double(depth[i]), double(surface[i]) - double(z), 1e-3) << "pixel " << i;
    }
    std::printf("%zu water pixels, %zu dry: water surface within %.2e m of %.0f m\n", wet, dry, worst, level);
    EXPECT_GT(wet, 500u);
    EXPECT_GT(dry, 500u);
    EXPECT_LE(worst, 0.01);

#if HC_WITH_VDB
    // The VDB: the water level set crosses zero at the level, between the two voxels around it (the existing
    // VdbLevelSetsCrossZeroOnTheSurface test's interpolation, within 1e-3 voxel).
    SampledRaster terrain = sample("elevation", res, true), water = sample("water_surface", res, true);
    const std::string path = (dir_ / "w.vdb").string();
    hc::exporting::writeVdb(terrain, &water, path);
    openvdb::initialize();
    openvdb::io::File file(path);
    file.open();
    auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("water_surface"));
    file.close();
    ASSERT_TRUE(grid);
    auto acc = grid->getConstAccessor();
    size_t checked = 0;
    for (size_t row = 0; row < water.height; row += 2)
        for (size_t col = 0; col < water.width; col += 2) {
            if (std::isnan(water.values[row * water.width + col])) continue;
            const int i = int(col), j = int(water.height - 1 - row), k = int(std::floor(level / res));
            const float below = acc.getValue(openvdb::Coord(i, j, k)),
                        above = acc.getValue(openvdb::Coord(i, j, k + 1));
            ASSERT_LE(below, 0.0f);
            ASSERT_GT(above, 0.0f);
            ASSERT_NEAR(k * res + res * (-below) / (above - below), level, 1e-3 * res)
                << "col " << col << " row " << row;
            ++checked;
        }
    EXPECT_GT(checked, 100u);
#endif
}

}  // namespace
