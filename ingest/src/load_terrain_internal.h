// ingest/src/load_terrain_internal.h: what the files of the terrain reading share (private to ingest/):
// load_terrain.cpp (the options, the source's georeferencing settled and the route to the working raster decided, the
// geometry of a source kept as is or resampled affinely, and the whole raster read), terrain_reproject.cpp (geographic
// sources projected to UTM, --t_srs warped by GDAL) and terrain_windows.cpp (the working raster read window by
// window: openTerrainWindows).
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <gdal_alg.h>
#include <gdalwarper.h>

#include "gdal_util.h"
#include "heightcast/ingest/ingest.h"
#include "resample.h"
#include "warp_seam.h"

namespace hc::ingest::detail {

constexpr double kSquareTolerance = 1e-3;  // pixels within 0.1 % of square are taken as square
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Geotransform of the source in metres (or in degrees for geographic sources).
struct GeoTransform {
    double g[6] = {0, 1, 0, 0, 0, -1};
    bool rotated() const { return g[2] != 0 || g[4] != 0; }
    // The position (x, y) [source CRS units] of fractional pixel coordinates (col, row).
    void apply(double col, double row, double& x, double& y) const {
        x = g[0] + col * g[1] + row * g[2];
        y = g[3] + col * g[4] + row * g[5];
    }
    // Source pixel coordinates of world (x, y), via the inverse affine map.
    bool invert(double inv[6]) const { return GDALInvGeoTransform(const_cast<double*>(g), inv) != 0; }
};

// ---- load_terrain.cpp: the working raster's geometry from a source on an affine geotransform ----

void checkWorkingSize(double width, double height, double pixelM, const Options& opt);
bool keptAsIs(const GeoTransform& gt, const Options& opt);
void keptGeometry(const GeoTransform& gt, size_t width, size_t height, Raster& r, bool& flipX, bool& flipY,
                  LoadReport& report);

// How the working raster comes from a source that is resampled (not kept as is, nor warped by GDAL): its geometry
// and CRS, and the map from target pixel centres to source pixel coordinates (no pixel read). resample() (whole)
// or latticeStep and resampleWindow (window by window) then fill it.
struct Resampling {
    Raster shape;  // geometry and CRS; values empty
    detail::TargetToSource map;
    int lattice = 16;
    double maxErrorPx = 1e-9;
    bool sayLattice = false;  // UTM: the method names the lattice step (", map exact every N px") and then methodTail
    std::string methodTail;
    std::function<void(size_t row, std::vector<double>& x, std::vector<double>& y, std::vector<int>& ok)>
        rowToWorld;                    // SourceTrace's
    bool rowToWorldThreadSafe = true;  // false for PROJ's transformations (--t_srs)
};

Resampling planAffine(const GeoTransform& gt, size_t width, size_t height, double pixelM, const std::string& wkt,
                      const Options& opt, LoadReport& report, bool whole);
Raster fromSourceAffine(SourceBand&& src, const GeoTransform& gt, double pixelM, const std::string& wkt,
                        const Options& opt, LoadReport& report, detail::SourceTrace* trace);

// ---- terrain_reproject.cpp: geographic sources projected to UTM, and --t_srs ----

Resampling planUtm(const GeoTransform& gt, size_t width, size_t height, const OGRSpatialReference& geo,
                   const Options& opt, LoadReport& report, bool whole);
Raster projectToUtm(SourceBand&& src, const GeoTransform& gt, const OGRSpatialReference& geo, const Options& opt,
                    LoadReport& report, detail::SourceTrace* trace);

// A source band as a GDAL dataset for the warper, of the whole source's size and georeferencing, whose blocks come
// from `fill` (our reading: every kind of nodata as NaN, metres, Terrain-RGB decoded) when the warper asks for them:
// a rank warping its windows reads only the source pixels they reach, and the one-process warp reads the band it holds.
// Columns [c0, c0 + width) of the source: one piece of a source split at 180 degrees.
class SourceDataset final : public GDALDataset {
public:
    using Fill =
        std::function<void(size_t col0, size_t row0, size_t w, size_t h, float* out)>;  // source columns, row-major
    SourceDataset(size_t c0, size_t width, size_t height, const GeoTransform& gt, const OGRSpatialReference* srs,
                  Fill fill)
        : gt_(gt), fill_(std::move(fill)) {
        nRasterXSize = int(width);
        nRasterYSize = int(height);
        if (srs) srs_ = *srs;
        SetBand(1, new Band(this, c0));
    }
    CPLErr GetGeoTransform(double* g) override {
        std::copy(gt_.g, gt_.g + 6, g);
        return CE_None;
    }
    const OGRSpatialReference* GetSpatialRef() const override { return srs_.IsEmpty() ? nullptr : &srs_; }

private:
    class Band final : public GDALRasterBand {
    public:
        Band(SourceDataset* ds, size_t c0) : c0_(c0) {
            poDS = ds;
            nBand = 1;
            eDataType = GDT_Float32;
            nRasterXSize = ds->nRasterXSize;
            nRasterYSize = ds->nRasterYSize;
            nBlockXSize = std::min(nRasterXSize, 512);
            nBlockYSize = std::min(nRasterYSize, 128);
        }
        double GetNoDataValue(int* has) override {
            if (has) *has = 1;
            return std::numeric_limits<double>::quiet_NaN();
        }
        CPLErr IReadBlock(int bx, int by, void* image) override {
            const size_t x0 = size_t(bx) * size_t(nBlockXSize), y0 = size_t(by) * size_t(nBlockYSize);
            const size_t w = std::min(size_t(nBlockXSize), size_t(nRasterXSize) - x0),
                         h = std::min(size_t(nBlockYSize), size_t(nRasterYSize) - y0);
            auto* out = static_cast<float*>(image);
            std::fill(out, out + size_t(nBlockXSize) * size_t(nBlockYSize), kNaN);
            try {
                std::vector<float> part(w * h);
                static_cast<SourceDataset*>(poDS)->fill_(c0_ + x0, y0, w, h, part.data());
                for (size_t r = 0; r < h; ++r) std::copy_n(part.data() + r * w, w, out + r * size_t(nBlockXSize));
            } catch (const std::exception& e) {
                CPLError(CE_Failure, CPLE_AppDefined, "%s", e.what());
                return CE_Failure;
            }
            return CE_None;
        }

    private:
        size_t c0_;
    };
    GeoTransform gt_;
    OGRSpatialReference srs_;
    Fill fill_;
};

// --t_srs with GDAL's warper and the exact transformer (-et 0): GDAL's default approximates the map
// linearly to within 0.125 source pixel: 10.9 m of elevation error on hef_srtm spread over 4 x 2
// degrees (test Issue11.TargetSrsUsesTheExactTransformer; 0.12 mm exact), up to 55 m in issue 11.
// A geographic source is first moved to start in -180..180; if it then runs past 180, it is split
// there and its east part shifted by -360 (both parts warped into the one output): PROJ's inverse
// gives longitudes in -180..180 only, so without the split every pixel past 180 would be lost.
// Columns that repeat the first ones (a global grid's closing column at west + 360) are left out.
//
// The output lattice is planned from the source's georeferencing alone (planWarp: no pixel read), and any window of it
// is warped on its own (WarpPlan::warp): one process warps the whole output in strips of rows, a rank its windows. A
// window is warped into the whole output's lattice (WarpRegionToBuffer on a virtual raster of the whole output: the
// same pixel coordinates, hence the same source positions), with the kernel's scale fixed (GDAL's XSCALE, YSCALE: its
// own estimate changes from chunk to chunk), so it holds the same bits as the whole output there
// (tests/ingest_windows_test.cpp).
struct WarpPlan {
    std::vector<std::unique_ptr<SourceDataset>> sources;  // one per piece of the source (two when split at 180 degrees)
    std::unique_ptr<detail::WarpSeams> seams;  // pixels between the pieces' columns, interpolated across (or null)
    std::string note;                          // for the report's method
    std::shared_ptr<OGRCoordinateTransformation> ct;  // source CRS -> target CRS (PROJ, exact)
    OGRSpatialReference target;
    std::string targetText, targetWkt, input;  // the target as given (--t_srs) and as WKT
    double ext[4] = {0, 0, 0, 0};              // west, south, east, north [target units]
    double cell = 1, scale = 1;    // output pixel [target units]; output pixels per source pixel (the kernel's)
    size_t width = 0, height = 0;  // output pixels
    unsigned threads = 0;

    // The warped raster's valid pixels, counted over all of it (every window): an error where none is valid, or where
    // the halves of a source split at 180 degrees do not meet (in a map whose own edge is at 180, EPSG:3857 say, they
    // land at its opposite edges, a world apart, with nothing between).
    void checkValid(uint64_t valid) const {
        const double all = double(width) * double(height);
        if (valid == 0)
            throw Error(input + ": projected to " + targetText + " on " + std::to_string(width) + " x " +
                        std::to_string(height) + " pixels of " + fmt(cell, 6) +
                        " (CRS units), no pixel centre falls inside the data: " +
                        "the footprint is too thin for that resolution; give a finer one with --min-cell");
        if (sources.size() == 2 && double(valid) < 0.1 * all)
            throw Error(input + ": crosses 180 degrees of longitude, which is an edge of " + targetText +
                        ": its two halves would lie at " + "the map's opposite edges (" +
                        fmt(100.0 * double(valid) / all, 3) + " % of a " + std::to_string(width) +
                        " px wide raster); choose a --t_srs whose central meridian is near the data (e.g. " +
                        "EPSG:3832, PDC Mercator, or '+proj=laea +lon_0=180 +lat_0=...') or leave --t_srs out for its "
                        "UTM zone");
    }

    GeoTransform outputGt() const {
        GeoTransform g;
        const double gg[6] = {ext[0], cell, 0, ext[3], 0, -cell};
        std::copy(gg, gg + 6, g.g);
        return g;
    }

    // Output pixels [col0, col0 + w) x [row0, row0 + h) into out (w h, row-major, NaN where no source reaches).
    void warp(size_t col0, size_t row0, size_t w, size_t h, float* out) const {
        std::fill(out, out + w * h, kNaN);
        const GeoTransform g = outputGt();  // each piece into the window, on the whole output's pixel coordinates
        for (const auto& source : sources) {
            detail::WindowWarp ww;
            ww.src = source.get();
            ww.hasSrcNoData = true, ww.srcNoData = std::numeric_limits<double>::quiet_NaN();
            std::copy(g.g, g.g + 6, ww.gt);
            ww.width = width, ww.height = height;
            ww.dstSrs = targetText, ww.dstWkt = targetWkt;
            ww.scale = scale, ww.threads = threads;
            ww.setupError = "--t_srs " + targetText + ": cannot transform " + input;
            ww.warpError = input + ": projecting to " + targetText;
            ww.into(col0, row0, w, h, out);
            source->FlushCache(false);  // drops its blocks from GDAL's cache: the next window reads what it reaches
        }
        if (seams) seams->apply(col0, row0, w, h, out);
    }
};

WarpPlan planWarp(const GeoTransform& gtIn, size_t width, size_t height, const OGRSpatialReference& srs,
                  const OGRSpatialReference& target, const Options& opt, LoadReport& report,
                  const SourceDataset::Fill& fill);

// The working raster of a warp in metres: the target CRS with its linear unit made metres, the output lattice scaled
// to match (unit: metres per target unit); the report names that CRS and the method.
struct WarpedFrame {
    OGRSpatialReference crs;
    GeoTransform gt;
    double unit = 1;
};
WarpedFrame warpedFrame(const WarpPlan& plan, LoadReport& report);
std::function<void(size_t, std::vector<double>&, std::vector<double>&, std::vector<int>&)> warpRowToWorld(
    const WarpPlan& plan, const GeoTransform& gtIn, double unit);
Raster warpToTarget(SourceBand&& src, const GeoTransform& gtIn, const OGRSpatialReference& srs,
                    const OGRSpatialReference& target, const Options& opt, LoadReport& report,
                    detail::SourceTrace* trace);

// ---- load_terrain.cpp: the terrain file opened ----

// The terrain file opened and its georeferencing settled, no pixel read: loadTerrain's first half, shared with the
// window-by-window reading (TerrainWindows).
struct Opened {
    DatasetPtr ds;
    std::unique_ptr<detail::BandReader> band;  // reads ds's band; its constructor checked the bands and units
    OGRSpatialReference srs;
    bool hasSrs = false, hasGt = false, localFrame = false;
    GeoTransform gt;
    // How the working raster comes from the source.
    enum class Route { Warp, Utm, Affine } route = Route::Affine;
    OGRSpatialReference target;  // Route::Warp: --t_srs
    double pixelM = 1;           // Route::Affine: the source's pixel size [m]
    std::string wkt;             // Route::Affine: the grid CRS ("" for none)
};

Opened openTerrain(const Options& opt, LoadReport& report);

}  // namespace hc::ingest::detail
