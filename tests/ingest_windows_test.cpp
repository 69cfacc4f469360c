// The terrain read window by window (what each rank of `mpirun hc-ingest` reads, docs/design.md section 7) against the
// same raster read whole by loadTerrain, the reference: the same geometry, the same bits in every pixel of every
// window, and the same reading counts. Sources that are kept as is, resampled (a geographic raster projected to UTM, a
// rotated geotransform, --min-cell) and warped by GDAL (--t_srs), on real rasters, with holes.
//
// "The same bits" is the right tolerance: the ranks' files must be byte-identical to one process's, so a window's
// pixel must not differ from the whole raster's by even one float ulp.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <memory>
#include <random>

#include <gdal_priv.h>
#include <gdal_utils.h>
#include <ogr_spatialref.h>

#include "heightcast/core/error.h"
#include "heightcast/ingest/ingest.h"
#include "heightcast/ingest/detail/windows.h"
#include "temp_dir.h"
#include "test_data.h"

namespace {

namespace fs = std::filesystem;
using hc::ingest::LoadReport;
using hc::ingest::Options;
using hc::ingest::Raster;
namespace detail = hc::ingest::detail;

class IngestWindows : public hc::test::TempDirTest {
protected:
    IngestWindows() : TempDirTest("hc_ingest_windows_") {}
};

bool sameBits(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// One process reading the working raster in pieces (Options::rasterMemoryMB at a tenth of its float32 size: about ten
// runs of share nodes, each read for its tiles' roots and again for its cells) writes the same bytes as `wholeGrid`,
// which ingestToFile wrote holding it whole (`wholeReport`), and reports the same: the same reading counts (each
// window's second read not counted again), warnings and check against the source (its RMS to 1e-12: the sum of squares
// is added in another order).
void compareInPieces(const fs::path& dir, const Options& o, const std::string& wholeGrid,
                     const LoadReport& wholeReport) {
    EXPECT_FALSE(wholeReport.heldInPieces);
    LoadReport rep;
    std::unique_ptr<detail::TerrainWindows> windows = detail::openTerrainWindows(o, rep);
    const Raster& s = windows->shape();
    Options small = o;
    small.rasterMemoryMB = double(s.width * s.height) * sizeof(float) / 10 / 1e6;
    LoadReport pieces;
    const std::string grid = (dir / "windows_pieces.hcg").string();
    hc::ingest::ingestToFile(small, grid, pieces);
    EXPECT_TRUE(pieces.heldInPieces);
    EXPECT_TRUE(hc::test::readBytes(grid) == hc::test::readBytes(wholeGrid)) << "in pieces: " << grid;
    EXPECT_EQ(pieces.method, wholeReport.method);
    EXPECT_EQ(pieces.warnings, wholeReport.warnings);
    EXPECT_EQ(pieces.sourceValidPixels, wholeReport.sourceValidPixels);
    EXPECT_EQ(pieces.infPixels, wholeReport.infPixels);
    EXPECT_EQ(pieces.sourcePrecisionDouble, wholeReport.sourcePrecisionDouble);
    const auto &a = pieces.sourceCheck, &b = wholeReport.sourceCheck;
    EXPECT_EQ(a.done, b.done);
    EXPECT_EQ(a.checked, b.checked);
    EXPECT_EQ(a.missed, b.missed);
    EXPECT_EQ(a.maxDevM, b.maxDevM);
    EXPECT_NEAR(a.rmsDevM, b.rmsDevM, 1e-12 * (1 + b.rmsDevM));
}

// Reads `o` whole and window by window: windows of awkward sizes tiling the working raster (so every pixel is read
// once, its edges included) plus random ones overlapping them; every pixel compared bit for bit. Returns the number
// of valid pixels compared (so a caller can see the comparison was not vacuous). The grid it writes goes into `dir`.
size_t compareWindows(const fs::path& dir, const Options& o, const std::string& expectMethod, size_t tileW,
                      size_t tileH) {
    LoadReport wholeReport;
    const Raster whole = hc::ingest::loadTerrain(o, wholeReport);
    EXPECT_NE(wholeReport.method.find(expectMethod), std::string::npos) << wholeReport.method;

    LoadReport rep;
    std::unique_ptr<detail::TerrainWindows> windows = detail::openTerrainWindows(o, rep);
    EXPECT_TRUE(windows);
    if (!windows) return 0;
    const Raster& s = windows->shape();
    EXPECT_EQ(s.width, whole.width);
    EXPECT_EQ(s.height, whole.height);
    EXPECT_EQ(s.pixelSizeM, whole.pixelSizeM);
    EXPECT_EQ(s.westWorld, whole.westWorld);
    EXPECT_EQ(s.northWorld, whole.northWorld);
    EXPECT_EQ(s.crsWkt, whole.crsWkt);
    EXPECT_EQ(rep.method, wholeReport.method);
    if (s.width != whole.width || s.height != whole.height) return 0;

    size_t valid = 0, mismatches = 0;
    std::vector<float> values, rounding;
    auto check = [&](size_t c0, size_t r0, size_t w, size_t h, bool count) {
        windows->read(c0, r0, w, h, values, rounding, true);
        ASSERT_EQ(values.size(), w * h);
        for (size_t r = 0; r < h; ++r)
            for (size_t c = 0; c < w; ++c) {
                const float a = values[r * w + c], b = whole.at(c0 + c, r0 + r);
                if (!sameBits(a, b) && mismatches++ < 5)
                    ADD_FAILURE() << "pixel " << c0 + c << "," << r0 + r << " of window " << c0 << "," << r0 << " " << w
                                  << "x" << h << ": " << a << " read by window, " << b << " read whole";
                if (count && !std::isnan(b)) ++valid;
            }
    };
    for (size_t r0 = 0; r0 < s.height; r0 += tileH)
        for (size_t c0 = 0; c0 < s.width; c0 += tileW)
            check(c0, r0, std::min(tileW, s.width - c0), std::min(tileH, s.height - r0), true);
    // What the tiling's reads counted (a source kept as is counts what its windows read; a resampled one counts every
    // source pixel once by strips): the whole read's counts.
    windows->finish(windows->tally(), rep);
    EXPECT_EQ(rep.sourceValidPixels, wholeReport.sourceValidPixels);
    EXPECT_EQ(rep.infPixels, wholeReport.infPixels);
    EXPECT_EQ(rep.warnings, wholeReport.warnings);
    std::mt19937 rng(7);
    for (int k = 0; k < 20; ++k) {
        const size_t w = 1 + rng() % std::min<size_t>(s.width, 97), h = 1 + rng() % std::min<size_t>(s.height, 61);
        check(rng() % (s.width - w + 1), rng() % (s.height - h + 1), w, h, false);
    }
    EXPECT_EQ(mismatches, 0u);

    // The check of every source pixel against the cell under its centre, as the ranks make it (strip by strip, against
    // the written file's regions), equals the one-process check (against the painted cells of the whole build): the
    // same counts and largest deviation exactly, the RMS to 1e-12 (its sum of squares is added in another order).
    const std::string grid = (dir / "windows_check.hcg").string();
    LoadReport fileReport;
    hc::ingest::ingestToFile(o, grid, fileReport);
    const std::optional<detail::SourceCheckSums> sums = windows->checkAgainst(grid);
    EXPECT_EQ(sums.has_value(), fileReport.sourceCheck.done);
    if (sums && fileReport.sourceCheck.done) {
        const auto& one = fileReport.sourceCheck;
        EXPECT_GT(sums->checked, 0u);
        EXPECT_EQ(sums->checked, one.checked);
        EXPECT_EQ(sums->missed, one.missed);
        EXPECT_EQ(sums->maxDev, one.maxDevM);
        EXPECT_NEAR(std::sqrt(sums->sumSq / double(sums->checked)), one.rmsDevM, 1e-12 * (1 + one.rmsDevM));
        // And the tally of that pass is still every source pixel once.
        EXPECT_EQ(windows->tally().validPixels, wholeReport.sourceValidPixels);
    }
    EXPECT_NO_FATAL_FAILURE(compareInPieces(dir, o, grid, fileReport));
    return valid;
}

// A GeoTIFF copy of `src` at `path` whose geotransform `change` rewrites.
void copyWithGeoTransform(const std::string& src, const std::string& path, const std::function<void(double*)>& change) {
    GDALDatasetUniquePtr in(GDALDataset::Open(src.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
    ASSERT_TRUE(in);
    double gt[6];
    ASSERT_EQ(in->GetGeoTransform(gt), CE_None);
    GDALDatasetUniquePtr ds(GetGDALDriverManager()->GetDriverByName("GTiff")->CreateCopy(path.c_str(), in.get(), FALSE,
                                                                                         nullptr, nullptr, nullptr));
    ASSERT_TRUE(ds);
    change(gt);
    ASSERT_EQ(ds->SetGeoTransform(gt), CE_None);
}

// A copy of the bundled WGS 84 SRTM tile at `path` with a 40 x 30 px box burnt to its declared nodata (-32768).
void copyWithHole(const std::string& src, const std::string& path) {
    GDALDatasetUniquePtr in(GDALDataset::Open(src.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
    ASSERT_TRUE(in);
    GDALDatasetUniquePtr ds(GetGDALDriverManager()->GetDriverByName("GTiff")->CreateCopy(path.c_str(), in.get(), FALSE,
                                                                                         nullptr, nullptr, nullptr));
    ASSERT_TRUE(ds);
    GDALRasterBand* b = ds->GetRasterBand(1);
    ASSERT_EQ(b->SetNoDataValue(-32768), CE_None);
    std::vector<int16_t> hole(40 * 30, -32768);
    ASSERT_EQ(b->RasterIO(GF_Write, 100, 120, 40, 30, hole.data(), 40, 30, GDT_Int16, 0, 0, nullptr), CE_None);
}

// The bundled WGS 84 SRTM tile (384 x 284 px of 1"), a box of it burnt to its declared nodata: projected to UTM 32N.
TEST_F(IngestWindows, GeographicSourceProjectedToUtmReadsTheSameBitsByWindow) {
    HC_REQUIRE_DATA(src, "hef_srtm.tif");
    GDALAllRegister();
    const std::string path = (dir_ / "hef_holes.tif").string();
    ASSERT_NO_FATAL_FAILURE(copyWithHole(src, path));
    Options o;
    o.input = path;
    const size_t valid = compareWindows(dir_, o, "projected to UTM zone 32N", 37, 23);
    EXPECT_GT(valid, 50000u);  // most of the ~60 k working pixels, the hole and the skewed footprint's corners aside
}

// The bundled 1 m LiDAR tile under a geotransform turned by 20 degrees: resampled north-up.
TEST_F(IngestWindows, RotatedGeotransformReadsTheSameBitsByWindow) {
    HC_REQUIRE_DATA(src, "lidar1m_minnesota_utm15.tif");
    GDALAllRegister();
    const std::string path = (dir_ / "lidar_rotated.tif").string();
    ASSERT_NO_FATAL_FAILURE(copyWithGeoTransform(src, path, [](double* gt) {
        const double a = 20 * M_PI / 180, px = gt[1];
        const double rot[6] = {gt[0], px * std::cos(a), px * std::sin(a), gt[3], px * std::sin(a), -px * std::cos(a)};
        std::copy(rot, rot + 6, gt);
    }));
    Options o;
    o.input = path;
    EXPECT_GT(compareWindows(dir_, o, "rotated geotransform", 64, 41), 10000u);
}

// The same LiDAR tile, kept north-up but resampled to --min-cell 3 (coarser than its 1 m pixels), and to 0.7 m (finer).
TEST_F(IngestWindows, MinCellReadsTheSameBitsByWindow) {
    HC_REQUIRE_DATA(src, "lidar1m_minnesota_utm15.tif");
    GDALAllRegister();
    for (double cell : {3.0, 0.7}) {
        SCOPED_TRACE(cell);
        Options o;
        o.input = src;
        o.minCellM = cell;
        EXPECT_GT(compareWindows(dir_, o, "--min-cell", 50, 29), 1000u);
    }
}

// A source kept as is (a projected GeoTIFF): the windows are its own pixels.
TEST_F(IngestWindows, KeptSourceReadsTheSameBitsByWindow) {
    HC_REQUIRE_DATA(src, "south_glacier_utm7.tif");
    GDALAllRegister();
    Options o;
    o.input = src;
    EXPECT_GT(compareWindows(dir_, o, "kept as is", 45, 33), 1000u);
}

// A kept source whose rows run south-up and whose values float32 cannot hold (Float64: each window keeps the rounding
// too), read in strips of a few rows (GDAL's default blocks for a GeoTIFF it writes): the windows are its own pixels,
// mirrored.
TEST_F(IngestWindows, KeptSouthUpFloat64SourceReadsTheSameBitsByWindow) {
    HC_REQUIRE_DATA(src, "south_glacier_utm7.tif");
    GDALAllRegister();
    const std::string path = (dir_ / "glacier_south_up.tif").string();
    size_t height = 0;
    {
        GDALDatasetUniquePtr in(GDALDataset::Open(src.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
        ASSERT_TRUE(in);
        ASSERT_EQ(in->GetRasterBand(1)->GetRasterDataType(), GDT_Float64);
        height = size_t(in->GetRasterYSize());
    }
    ASSERT_NO_FATAL_FAILURE(copyWithGeoTransform(src, path, [&](double* gt) {
        gt[3] += gt[5] * double(height);  // the southern edge, rows running north
        gt[5] = -gt[5];
    }));
    Options o;
    o.input = path;
    EXPECT_GT(compareWindows(dir_, o, "south-up rows flipped north-up", 31, 47), 1000u);
}

// --t_srs (GDAL's warper, exact transformer): each window warped on its own from the source blocks it reaches, on the
// whole output's pixel centres and with the kernel's scale fixed: the same bits as the whole warp. The bundled WGS 84
// tile with a hole to Austria's Gauss-Krueger zone (EPSG:31254), and the same to ETRS89 LAEA (EPSG:3035) at --min-cell
// 200 (coarser than the ~30 m pixels: the kernel widens).
TEST_F(IngestWindows, WarpedSourceReadsTheSameBitsByWindow) {
    HC_REQUIRE_DATA(src, "hef_srtm.tif");
    GDALAllRegister();
    const std::string path = (dir_ / "hef_holes_warp.tif").string();
    ASSERT_NO_FATAL_FAILURE(copyWithHole(src, path));
    Options o;
    o.input = path;
    o.targetSrs = "EPSG:31254";
    EXPECT_GT(compareWindows(dir_, o, "warped to MGI / Austria GK West", 37, 23), 50000u);
    o.targetSrs = "EPSG:3035";
    o.minCellM = 200;
    EXPECT_GT(compareWindows(dir_, o, "warped to ETRS89-extended / LAEA Europe", 19, 13), 2000u);
}

// Issue 40: the output pixels between the last source column west of 180 degrees and the first east of it, where the
// warp reads two pieces of the source (split at 180), or the grid's last column and its first (a grid around the
// globe, read as one piece), interpolate across the seam: each is the bilinear value of both columns (before, it was
// the nearer column alone, up to hundreds of metres off on this 1-degree relief). The global grid to PDC Mercator,
// centred on 150 degrees, at 80 km pixels: as it is (-180 .. 180: its edges meet at 180), and moved 90 degrees east
// (-90 .. 270: split at 180).
TEST_F(IngestWindows, WarpInterpolatesAcrossTheSeams) {
    HC_REQUIRE_DATA(src, "etopo1_1deg.tif");
    GDALAllRegister();
    OGRSpatialReference pdc, geo;
    pdc.importFromEPSG(3832), geo.importFromEPSG(4326);
    pdc.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER), geo.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    std::unique_ptr<OGRCoordinateTransformation> back(OGRCreateCoordinateTransformation(&pdc, &geo));
    // The pixels between source columns i0 and i0 + 1 (around the circle) against their bilinear value; their count.
    auto check = [&](const std::string& path, size_t i0, const char* what) {
        SCOPED_TRACE(what);
        Options o;
        o.input = path;
        o.targetSrs = "EPSG:3832";
        o.minCellM = 80000;  // 0.72 degrees: pixel columns in every degree of longitude
        LoadReport rep;
        const Raster r = hc::ingest::loadTerrain(o, rep);
        GDALDatasetUniquePtr ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
        const size_t w = size_t(ds->GetRasterXSize()), h = size_t(ds->GetRasterYSize()), period = 360;
        double gt[6];
        ds->GetGeoTransform(gt);
        std::vector<float> v(w * h);
        EXPECT_EQ(
            ds->GetRasterBand(1)->RasterIO(GF_Read, 0, 0, int(w), int(h), v.data(), int(w), int(h), GDT_Float32, 0, 0),
            CE_None);
        const double first = gt[0] + gt[1] / 2;  // column 0's centre; columns repeat every 360
        const size_t i1 = (i0 + 1) % period;
        size_t found = 0;
        double worst = 0;
        std::vector<double> xs(r.width), ys(r.width);
        std::vector<int> ok(r.width);
        for (size_t row = 0; row < r.height; ++row) {
            for (size_t col = 0; col < r.width; ++col)
                xs[col] = r.westWorld + (double(col) + 0.5) * r.pixelSizeM,
                ys[col] = r.northWorld - (double(row) + 0.5) * r.pixelSizeM;
            back->Transform(int(r.width), xs.data(), ys.data(), nullptr, ok.data());
            for (size_t col = 0; col < r.width; ++col) {
                const double x = xs[col], y = ys[col];
                if (!ok[col]) continue;
                const double fi = std::fmod(std::fmod(x - first, 360.0) + 360.0, 360.0);  // columns from column 0
                const double fx = fi - double(i0), fy = (y - gt[3]) / gt[5] - 0.5, ry = std::floor(fy), wy = fy - ry;
                if (!(fx > 0 && fx < 1) || ry < 0 || ry + 1 >= double(h)) continue;
                const size_t r0 = size_t(ry);
                const double want = (1 - wy) * ((1 - fx) * v[r0 * w + i0] + fx * v[r0 * w + i1]) +
                                    wy * ((1 - fx) * v[(r0 + 1) * w + i0] + fx * v[(r0 + 1) * w + i1]);
                worst = std::max(worst, std::abs(double(r.at(col, row)) - want));
                ++found;
            }
        }
        // The bilinear value in double against the warped float32 (values to 5855 m: 5e-4 m a rounding): 1 cm.
        EXPECT_LT(worst, 0.01);
        return found;
    };
    EXPECT_GT(check(src, 359, "the grid's last column (179) and its first (-180 = 180)"), 50u);
    const std::string moved = (dir_ / "etopo_east_seams.tif").string();
    ASSERT_NO_FATAL_FAILURE(copyWithGeoTransform(src, moved, [](double* gt) { gt[0] += 90; }));
    EXPECT_GT(check(moved, 269, "179 and 180 degrees, where the two pieces meet"), 50u);
}

// A geographic source past 180 degrees, which --t_srs warps as two pieces (the east one shifted by -360): each window
// warps both pieces, the same bits as the whole. The bundled 1-degree global grid moved 90 degrees east (-90 .. 270),
// to PDC Mercator (EPSG:3832, centred on 150 degrees: the halves meet). Where they would not (the bundled WGS 84 tile
// moved to 178..182 E, into EPSG:3857, whose edge is at 180 degrees), the whole raster's valid pixels, counted over
// every window, refuse it with the whole read's message (checkValid); and a count of none says the footprint misses
// every pixel centre.
TEST_F(IngestWindows, WarpAcross180ReadsTheSameBitsByWindow) {
    HC_REQUIRE_DATA(src, "etopo1_1deg.tif");
    GDALAllRegister();
    const std::string path = (dir_ / "etopo_east.tif").string();
    ASSERT_NO_FATAL_FAILURE(copyWithGeoTransform(src, path, [](double* gt) { gt[0] += 90; }));
    Options o;
    o.input = path;
    o.targetSrs = "EPSG:3832";
    EXPECT_GT(compareWindows(dir_, o, "split at 180 degrees", 41, 17), 10000u);

    HC_REQUIRE_DATA(hef, "hef_srtm.tif");
    const std::string across = (dir_ / "across.tif").string();
    size_t hw = 0, hh = 0;
    {
        GDALDatasetUniquePtr in(GDALDataset::Open(hef.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
        ASSERT_TRUE(in);
        hw = size_t(in->GetRasterXSize()), hh = size_t(in->GetRasterYSize());
    }
    ASSERT_NO_FATAL_FAILURE(copyWithGeoTransform(hef, across, [&](double* gt) {
        const double g[6] = {178, 4.0 / double(hw), 0, 46, 0, -2.0 / double(hh)};
        std::copy(g, g + 6, gt);
    }));
    o.input = across;
    o.targetSrs = "EPSG:3857";
    LoadReport wholeReport;
    std::string wholeError;
    try {
        hc::ingest::loadTerrain(o, wholeReport);
    } catch (const hc::Error& e) {
        wholeError = e.what();
    }
    EXPECT_NE(wholeError.find("its two halves would lie at the map's opposite edges"), std::string::npos) << wholeError;
    LoadReport rep;
    const std::unique_ptr<detail::TerrainWindows> windows = detail::openTerrainWindows(o, rep);
    ASSERT_TRUE(windows);
    const Raster& s = windows->shape();
    std::vector<float> values, rounding;
    uint64_t valid = 0;
    for (size_t r0 = 0; r0 < s.height; r0 += 64) {
        windows->read(0, r0, s.width, std::min<size_t>(64, s.height - r0), values, rounding, true);
        valid += uint64_t(std::count_if(values.begin(), values.end(), [](float v) { return !std::isnan(v); }));
    }
    try {
        windows->checkValid(valid);
        ADD_FAILURE() << "EPSG:3857 across 180 degrees accepted by windows";
    } catch (const hc::Error& e) {
        EXPECT_EQ(std::string(e.what()), wholeError);
    }
    EXPECT_THROW(windows->checkValid(0), hc::Error);
}

}  // namespace
