// tests/ingest_world.h: what the ingest tests on real rasters share (ingest_test.cpp, ingest_checks_test.cpp): pixel
// centres in a grid's frame, the tolerance guarantee checked pixel by pixel, a raster loaded as ingest reads it, and
// our reading compared with GDAL's own read and with PROJ.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include <gdal_alg.h>
#include <gdal_priv.h>
#include <gdal_utils.h>
#include <ogr_spatialref.h>

#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/ingest/build.h"
#include "heightcast/ingest/ingest.h"

namespace hc::test::ingest {

using hc::Grid;
using hc::ingest::LoadReport;
using hc::ingest::Options;
using hc::ingest::Raster;

// Pixel (col, row) centre in the grid's local frame (the origin is the raster's south-west corner).
inline void pixelCentreLocal(const Raster& r, size_t col, size_t row, double& x, double& y) {
    x = (static_cast<double>(col) + 0.5) * r.pixelSizeM;
    y = (static_cast<double>(r.height - row) - 0.5) * r.pixelSizeM;
}

// The guarantee of docs/design.md section 2, pixel by pixel: every valid pixel lies within the tolerance
// of the cell covering it (no slack: the build checks against the stored float value); every
// nodata pixel is a hole.
inline void checkGuarantee(const Raster& terrain, const Raster* water, const Grid& g, double tol) {
    ASSERT_EQ(g.validate(), "");
    ASSERT_EQ(g.finestCellM, terrain.pixelSizeM);
    ASSERT_EQ(g.originWorldX, terrain.westWorld);
    ASSERT_NEAR(g.originWorldY, terrain.southWorld(), 1e-9 * std::abs(terrain.southWorld()) + 1e-9);
    size_t valid = 0;
    double maxDev = 0;
    for (size_t row = 0; row < terrain.height; ++row)
        for (size_t col = 0; col < terrain.width; ++col) {
            double x, y;
            pixelCentreLocal(terrain, col, row, x, y);
            auto cell = g.locate(x, y);
            float z = terrain.at(col, row);
            if (std::isnan(z)) {
                ASSERT_FALSE(cell) << "nodata pixel " << col << "," << row << " became a cell";
                continue;
            }
            ++valid;
            ASSERT_TRUE(cell) << "valid pixel " << col << "," << row << " has no cell";
            double dev = std::abs(static_cast<double>(z) - g.values[0][*cell]);
            maxDev = std::max(maxDev, dev);
            ASSERT_LE(dev, tol) << "pixel " << col << "," << row;
            if (water) {
                double d = water->at(col, row);
                ASSERT_LE(std::abs(d - g.values[1][*cell]), tol);
                ASSERT_EQ(d > 0, g.values[1][*cell] > 0) << "a wet/dry edge was blurred at " << col << "," << row;
            }
        }
    EXPECT_EQ(valid, g.stats.validPixels);
    EXPECT_LE(g.stats.maxDevM, tol);
    EXPECT_GE(g.stats.maxDevM, maxDev);
    EXPECT_LE(g.cellCount(), valid);
}

struct Loaded {
    Raster terrain;
    Grid grid;
    LoadReport report;
};

inline Loaded load(const Options& o) {
    Loaded l;
    l.terrain = hc::ingest::loadTerrain(o, l.report);
    LoadReport again;
    l.grid = hc::ingest::ingest(o, again);
    return l;
}

// Reads band 1 straight through GDAL (not through our loader) and checks our working raster holds
// the same numbers in the same places: for projected rasters with square pixels, kept as is.
inline void checkSameAsGdalRead(const std::string& path, const Raster& r) {
    GDALAllRegister();
    std::unique_ptr<GDALDataset> ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
    ASSERT_TRUE(ds);
    double gt[6];
    ASSERT_EQ(ds->GetGeoTransform(gt), CE_None);
    ASSERT_EQ(r.width, static_cast<size_t>(ds->GetRasterXSize()));
    ASSERT_EQ(r.height, static_cast<size_t>(ds->GetRasterYSize()));
    EXPECT_EQ(r.westWorld, gt[0]);
    EXPECT_EQ(r.northWorld, gt[3]);
    EXPECT_EQ(r.pixelSizeM, gt[1]);
    std::vector<double> v(r.width * r.height);
    GDALRasterBand* b = ds->GetRasterBand(1);
    ASSERT_EQ(b->RasterIO(GF_Read, 0, 0, int(r.width), int(r.height), v.data(), int(r.width), int(r.height),
                          GDT_Float64, 0, 0, nullptr),
              CE_None);
    int has = 0;
    double nd = b->GetNoDataValue(&has);
    size_t holes = 0;
    for (size_t i = 0; i < v.size(); ++i) {
        bool nodata = std::isnan(v[i]) || (has && static_cast<float>(v[i]) == static_cast<float>(nd));
        holes += nodata;
        if (nodata)
            ASSERT_TRUE(std::isnan(r.values[i])) << "pixel " << i;
        else
            ASSERT_EQ(r.values[i], static_cast<float>(v[i])) << "pixel " << i;
    }
    EXPECT_EQ(r.validCount(), v.size() - holes);
}

// Independent check of the projection and resampling: for every working pixel, GDAL's own
// transformer (PROJ) gives the source pixel position, and a plain bilinear interpolation of the
// source as GDAL reads it gives the value. Our GeographicLib path must agree. (GDAL's warper is not
// the reference here: where it downsamples it widens its bilinear kernel into an area average.)
inline void checkSameAsProj(const std::string& path, const std::string& sourceSrs, const Raster& r, double tolM) {
    GDALAllRegister();
    std::unique_ptr<GDALDataset> ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
    ASSERT_TRUE(ds);
    const int sw = ds->GetRasterXSize(), sh = ds->GetRasterYSize();
    std::vector<double> src(size_t(sw) * sh);
    GDALRasterBand* band = ds->GetRasterBand(1);
    ASSERT_EQ(band->RasterIO(GF_Read, 0, 0, sw, sh, src.data(), sw, sh, GDT_Float64, 0, 0, nullptr), CE_None);
    int has = 0;
    double nd = band->GetNoDataValue(&has);
    for (double& v : src)
        if (has && v == nd) v = NAN;
    char** opts = CSLSetNameValue(nullptr, "DST_SRS", r.crsWkt.c_str());
    if (!sourceSrs.empty()) opts = CSLSetNameValue(opts, "SRC_SRS", sourceSrs.c_str());
    void* tr = GDALCreateGenImgProjTransformer2(GDALDataset::ToHandle(ds.get()), nullptr, opts);
    CSLDestroy(opts);
    ASSERT_TRUE(tr);
    size_t compared = 0, validityDiffers = 0;
    double maxDiff = 0;
    for (size_t row = 0; row < r.height; ++row)
        for (size_t col = 0; col < r.width; ++col) {
            double x = r.westWorld + (double(col) + 0.5) * r.pixelSizeM,
                   y = r.northWorld - (double(row) + 0.5) * r.pixelSizeM, z = 0;
            int ok = 0;
            GDALGenImgProjTransform(tr, TRUE, 1, &x, &y, &z, &ok);  // -> source pixel coordinates
            double u = x - 0.5, v = y - 0.5;
            bool inside = ok && x >= 0 && y >= 0 && x < sw && y < sh;
            float ours = r.at(col, row);
            if (!inside) {
                validityDiffers += !std::isnan(ours);
                continue;
            }
            auto at = [&](long i, long j) {
                return src[size_t(std::clamp<long>(j, 0, sh - 1)) * size_t(sw) +
                           size_t(std::clamp<long>(i, 0, sw - 1))];
            };
            long i0 = long(std::floor(u)), j0 = long(std::floor(v));
            double fx = u - double(i0), fy = v - double(j0);
            double a = at(i0, j0), b = at(i0 + 1, j0), c = at(i0, j0 + 1), d = at(i0 + 1, j0 + 1);
            if (std::isnan(a) || std::isnan(b) || std::isnan(c) || std::isnan(d)) continue;  // next to a hole
            double want = (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy;
            ASSERT_FALSE(std::isnan(ours)) << "pixel " << col << "," << row << " lost";
            maxDiff = std::max(maxDiff, std::abs(want - ours));
            ++compared;
        }
    GDALDestroyGenImgProjTransformer(tr);
    EXPECT_GT(compared, r.validCount() / 2);
    EXPECT_EQ(validityDiffers, 0u) << "pixels outside the source carry values";
    EXPECT_LE(maxDiff, tolM);
    std::printf("vs PROJ + plain bilinear: max diff %.3g m over %zu pixels\n", maxDiff, compared);
}

}  // namespace hc::test::ingest
