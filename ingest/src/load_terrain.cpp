// loadTerrain: raster file -> metric, north-up, square-pixel working raster (ingest.h). Here: the options checked, the
// terrain file opened and its georeferencing settled (which CRS, which route to the working raster: kept as is,
// resampled affinely, projected to UTM or warped to --t_srs), the geometry of a source on an affine geotransform, and
// the whole raster read (loadTerrainTraced). Reprojection is terrain_reproject.cpp's, the window-by-window reading
// terrain_windows.cpp's; what they share is in load_terrain_internal.h.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <functional>
#include <limits>

#include <unistd.h>

#include "gdal_util.h"
#include "heightcast/core/error.h"
#include "heightcast/core/heap.h"
#include "heightcast/core/progress.h"
#include "heightcast/ingest/ingest.h"
#include "load_terrain_internal.h"
#include "resample.h"

namespace hc::ingest {

using detail::DatasetPtr;
using detail::SourceBand;

namespace {

using detail::fmt;
using detail::GeoTransform;
using detail::lower;

// Whether a raster without CRS has degrees for coordinates: NetCDF's CF units say so, or the extent
// fits the globe and either the pixels are finer than 0.01 (1 km in degrees, 1 cm in metres) or it
// covers the whole globe (a 360 x 180 m local terrain of 1 m pixels is far less likely than a
// global grid of 1 degree pixels).
bool looksLikeDegrees(const GeoTransform& gt, size_t width, size_t height, bool unitsSayDegrees) {
    if (gt.rotated()) return false;
    const double* g = gt.g;
    const double px = std::abs(g[1]), py = std::abs(g[5]);
    const double x0 = std::min(g[0], g[0] + g[1] * double(width)), x1 = std::max(g[0], g[0] + g[1] * double(width));
    const double y0 = std::min(g[3], g[3] + g[5] * double(height)), y1 = std::max(g[3], g[3] + g[5] * double(height));
    if (x0 < -180.0 - px || x1 > 540.0 + px || y0 < -90.0 - py || y1 > 90.0 + py) return false;
    if (unitsSayDegrees) return true;
    return std::max(px, py) < 0.01 || (x1 - x0 >= 350.0 && y1 - y0 >= 170.0);
}

// CF conventions (NetCDF): a coordinate variable with units "degrees_east" (GDAL shows it as
// metadata "lon#units=degrees_east").
bool metadataSaysDegrees(GDALDataset& ds) {
    for (char** md = ds.GetMetadata(); md && *md; ++md) {
        std::string item = lower(*md);
        size_t eq = item.find('=');
        if (eq == std::string::npos || item.rfind("#units", eq) == std::string::npos) continue;
        std::string v = item.substr(eq + 1);
        if (v.rfind("degrees_east", 0) == 0 || v.rfind("degree_east", 0) == 0 || v.rfind("degrees_e", 0) == 0)
            return true;
    }
    return false;
}

}  // namespace

namespace detail {

// Refuses a working raster this machine cannot hold (a --min-cell far below the pixel size, say)
// before allocating it: the raster takes 4 bytes per pixel and the grid up to 12 more.
void checkWorkingSize(double width, double height, double pixelM, const Options& opt) {
    double bytes = 16.0 * width * height;
    double ram = static_cast<double>(sysconf(_SC_PHYS_PAGES)) * static_cast<double>(sysconf(_SC_PAGESIZE));
    if (width > double(size_t{1} << 29) || height > double(size_t{1} << 29) || bytes > ram)
        throw Error(opt.input + ": the working raster would be " + fmt(width, 4) + " x " + fmt(height, 4) + " px of " +
                    fmt(pixelM, 4) + " m" + (opt.minCellM ? " (--min-cell)" : "") + ", about " + fmt(bytes / 1e9, 3) +
                    " GB with its grid, more than this machine's " + fmt(ram / 1e9, 3) + " GB");
}

// Whether the working raster is the source's pixels as they are (at most flipped): not rotated, square pixels, no
// --min-cell other than the pixel size.
bool keptAsIs(const GeoTransform& gt, const Options& opt) {
    const double* g = gt.g;
    const bool square =
        std::abs(std::abs(g[1]) - std::abs(g[5])) <= kSquareTolerance * std::max(std::abs(g[1]), std::abs(g[5]));
    const bool sameSize = !opt.minCellM || std::abs(*opt.minCellM - std::abs(g[1])) <= 1e-9 * std::abs(g[1]);
    return !gt.rotated() && square && sameSize;
}

// The geometry of a source kept as is (keptAsIs), flipped so that row 0 is north and column 0 west: r's size,
// pixel and corner, the report's method and the warning of snapped pixels. Values are not touched.
void keptGeometry(const GeoTransform& gt, size_t width, size_t height, Raster& r, bool& flipX, bool& flipY,
                  LoadReport& report) {
    const double* g = gt.g;
    r.width = width;
    r.height = height;
    r.pixelSizeM = std::abs(g[1]);
    flipX = g[1]<0, flipY = g[5]> 0;
    r.westWorld = flipX ? g[0] + g[1] * static_cast<double>(width) : g[0];
    r.northWorld = flipY ? g[3] + g[5] * static_cast<double>(height) : g[3];
    if (std::abs(g[1]) != std::abs(g[5])) {
        double shift = std::abs(std::abs(g[5]) - std::abs(g[1])) * static_cast<double>(height);
        report.warnings.push_back("pixels of " + fmt(std::abs(g[1])) + " x " + fmt(std::abs(g[5])) +
                                  " m are within 0.1 % of square: snapped (not resampled) to " + fmt(r.pixelSizeM) +
                                  " m squares, which moves the south edge by " + fmt(shift, 3) + " m");
    }
    if (flipX || flipY)
        report.method += std::string(report.method.empty() ? "" : "; ") +
                         (flipY ? "south-up rows flipped north-up" : "") + (flipX && flipY ? ", " : "") +
                         (flipX ? "east-to-west columns flipped" : "");
    if (report.method.empty()) report.method = "kept as is";
}

// A source on an affine geotransform that is rotated, has non-square pixels or is resampled to --min-cell.
// `whole`: the working raster will be held whole (its size is checked against this machine's memory).
Resampling planAffine(const GeoTransform& gt, size_t width, size_t height, double pixelM, const std::string& wkt,
                      const Options& opt, LoadReport& report, bool whole) {
    Resampling p;
    Raster& r = p.shape;
    r.crsWkt = wkt;
    r.crsName = report.gridCrsName;  // each caller names the grid CRS in the report before it comes here
    const double* g = gt.g;
    const bool square =
        std::abs(std::abs(g[1]) - std::abs(g[5])) <= kSquareTolerance * std::max(std::abs(g[1]), std::abs(g[5]));
    double inv[6];
    if (!gt.invert(inv)) throw Error(opt.input + ": geotransform cannot be inverted (degenerate pixel size)");
    double xs[4], ys[4];
    double cw = static_cast<double>(width), ch = static_cast<double>(height);
    const double corners[4][2] = {{0, 0}, {cw, 0}, {0, ch}, {cw, ch}};
    for (int k = 0; k < 4; ++k) gt.apply(corners[k][0], corners[k][1], xs[k], ys[k]);
    double xmin = *std::min_element(xs, xs + 4), xmax = *std::max_element(xs, xs + 4);
    double ymin = *std::min_element(ys, ys + 4), ymax = *std::max_element(ys, ys + 4);
    r.pixelSizeM = opt.minCellM ? *opt.minCellM : pixelM;
    if (whole)
        checkWorkingSize(std::ceil((xmax - xmin) / r.pixelSizeM), std::ceil((ymax - ymin) / r.pixelSizeM), r.pixelSizeM,
                         opt);
    r.width = static_cast<size_t>(std::ceil((xmax - xmin) / r.pixelSizeM - 1e-9));
    r.height = static_cast<size_t>(std::ceil((ymax - ymin) / r.pixelSizeM - 1e-9));
    r.westWorld = xmin;
    r.northWorld = ymax;
    std::string why = gt.rotated() ? "rotated geotransform" : (!square ? "non-square pixels" : "--min-cell");
    report.method += std::string(report.method.empty() ? "" : "; ") + "resampled north-up onto " + fmt(r.pixelSizeM) +
                     " m squares (" + why + ", bilinear)";
    p.map = [i0 = inv[0], i1 = inv[1], i2 = inv[2], i3 = inv[3], i4 = inv[4], i5 = inv[5]](double x, double y,
                                                                                           double& col, double& row) {
        col = i0 + x * i1 + y * i2;
        row = i3 + x * i4 + y * i5;
        return true;
    };
    p.lattice = 16, p.maxErrorPx = 1e-9;  // affine: the lattice interpolation is exact (the check confirms it)
    p.rowToWorld = [gt](size_t row, std::vector<double>& x, std::vector<double>& y, std::vector<int>& ok) {
        for (size_t c = 0; c < x.size(); ++c) {
            gt.apply(static_cast<double>(c) + 0.5, static_cast<double>(row) + 0.5, x[c], y[c]);
            ok[c] = 1;
        }
    };
    return p;
}

// `trace`, when given, receives the source and its pixel-to-world map if the source is resampled.
Raster fromSourceAffine(SourceBand&& src, const GeoTransform& gt, double pixelM, const std::string& wkt,
                        const Options& opt, LoadReport& report, detail::SourceTrace* trace) {
    if (keptAsIs(gt, opt)) {
        Raster r;
        r.crsWkt = wkt;
        r.crsName = report.gridCrsName;  // each caller names the grid CRS in the report before it comes here
        bool flipX = false, flipY = false;
        keptGeometry(gt, src.width, src.height, r, flipX, flipY, report);
        if (flipX || flipY) {
            auto flipped = [&](const std::vector<float>& v) {
                std::vector<float> out(v.size());
                for (size_t row = 0; row < src.height; ++row)
                    for (size_t col = 0; col < src.width; ++col)
                        out[row * src.width + col] =
                            v[(flipY ? src.height - 1 - row : row) * src.width + (flipX ? src.width - 1 - col : col)];
                return out;
            };
            r.values = flipped(src.values);
            if (!src.residual.empty()) r.roundingM = flipped(src.residual);
        } else {
            r.values = std::move(src.values);
            r.roundingM = std::move(src.residual);
        }
        return r;
    }
    // Resample: rotated, non-square, or a finest cell other than the pixel size.
    Resampling p = planAffine(gt, src.width, src.height, pixelM, wkt, opt, report, true);
    Raster r = std::move(p.shape);
    resample(src, p.map, r, p.lattice, p.maxErrorPx, opt.threads);
    if (trace) {
        trace->band = std::move(src);
        trace->rowToWorld = std::move(p.rowToWorld);
    }
    return r;
}

}  // namespace detail

void validateOptions(const Options& o) {
    auto bad = [](const std::string& m) { throw Error(m); };
    if (o.input.empty()) bad("no input raster given");
    if (o.band < 1) bad("--band " + std::to_string(o.band) + ": bands are numbered from 1");
    if (o.terrainRgb && o.band != 1) bad("--terrain-rgb reads bands 1-3; --band cannot be combined with it");
    if (!std::isfinite(o.toleranceM) || o.toleranceM < 0)
        bad("--tolerance " + fmt(o.toleranceM) + ": must be a finite number of metres >= 0");
    if (o.minCellM && !(std::isfinite(*o.minCellM) && *o.minCellM > 0))
        bad("--min-cell " + fmt(*o.minCellM) + ": must be a positive number of metres");
    if (o.maxCellM && !(std::isfinite(*o.maxCellM) && *o.maxCellM > 0))
        bad("--max-cell " + fmt(*o.maxCellM) + ": must be a positive number of metres");
    if (!(std::isfinite(o.rasterMemoryMB) && o.rasterMemoryMB >= 0))
        bad("--raster-memory " + fmt(o.rasterMemoryMB) + ": must be a finite number of MB > 0 (0: the default)");
    if (o.minCellM && o.maxCellM && *o.minCellM > *o.maxCellM)
        bad("--min-cell " + fmt(*o.minCellM) + " m is larger than --max-cell " + fmt(*o.maxCellM) + " m");
    if (!std::isfinite(o.zScale) || o.zScale == 0)
        bad("--z-scale " + fmt(o.zScale) + ": must be a finite non-zero factor");
    if (o.nodata && std::isnan(*o.nodata)) bad("--nodata nan: NaN is always nodata already");
    if ((o.water == WaterSource::Depth || o.water == WaterSource::Surface) && o.waterPath.empty() &&
        o.waterPaths.empty())
        bad("no water raster given");
    if (o.water == WaterSource::Level && o.waterLevelsM.empty() && !std::isfinite(o.waterLevelM))
        bad("--water-level must be a finite elevation in metres");
    for (double l : o.waterLevelsM)
        if (!std::isfinite(l)) bad("--water-level " + fmt(l) + ": every level must be a finite elevation in metres");
    const size_t steps = waterStepCount(o);
    if (!o.timesS.empty()) {
        if (steps == 0) bad("--times given without water (--water, --water-surface or --water-level)");
        if (o.timesS.size() != steps)
            bad("--times lists " + std::to_string(o.timesS.size()) + " times for " + std::to_string(steps) +
                " water steps");
        for (size_t k = 0; k < o.timesS.size(); ++k) {
            if (!std::isfinite(o.timesS[k]))
                bad("--times: time " + std::to_string(k) + " is not a finite number of seconds");
            if (k > 0 && !(o.timesS[k] > o.timesS[k - 1]))
                bad("--times must increase strictly: " + fmt(o.timesS[k]) + " s follows " + fmt(o.timesS[k - 1]) +
                    " s (step " + std::to_string(k) + ")");
        }
    }
}

size_t waterStepCount(const Options& o) {
    switch (o.water) {
        case WaterSource::None:
            return 0;
        case WaterSource::Level:
            return o.waterLevelsM.empty() ? 1 : o.waterLevelsM.size();
        default:
            return o.waterPaths.empty() ? 1 : o.waterPaths.size();
    }
}

double waterStepTimeS(const Options& o, size_t k) { return o.timesS.empty() ? static_cast<double>(k) : o.timesS.at(k); }

namespace detail {

Opened openTerrain(const Options& opt, LoadReport& report) {
    validateOptions(opt);
    Opened o;
    o.ds = detail::openRaster(opt.input, "terrain raster");
    report.sourceWidth = static_cast<size_t>(o.ds->GetRasterXSize());
    report.sourceHeight = static_cast<size_t>(o.ds->GetRasterYSize());
    const size_t width = report.sourceWidth, height = report.sourceHeight;

    o.localFrame = lower(opt.sourceSrs) == "local";
    OGRSpatialReference& srs = o.srs;
    srs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    if (o.localFrame) {
        report.warnings.push_back(
            "--s_srs local: coordinates taken as metres in a local frame, the file's own CRS (if any) ignored");
    } else if (!opt.sourceSrs.empty()) {
        if (srs.SetFromUserInput(opt.sourceSrs.c_str()) != OGRERR_NONE)
            throw Error("--s_srs " + opt.sourceSrs +
                        ": not a CRS that GDAL/PROJ knows (or 'local' for metres in a local frame)");
        o.hasSrs = true;
    } else if (const OGRSpatialReference* own = o.ds->GetSpatialRef(); own && !own->IsEmpty()) {
        srs = *own;
        srs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
        o.hasSrs = true;
    }
    report.sourceCrsName = o.hasSrs ? detail::crsName(&srs) : "";

    GeoTransform& gt = o.gt;
    o.hasGt = o.ds->GetGeoTransform(gt.g) == CE_None;
    if (o.hasGt && (gt.g[1] == 0 || gt.g[5] == 0) && !gt.rotated())
        throw Error(opt.input + ": geotransform has a zero pixel size");
    // Elevation units a compound CRS declares (its vertical part), for bands that declare none.
    double zCrs = 1.0;
    std::string zCrsUnit;
    if (o.hasSrs && srs.IsCompound()) {
        const char* name = nullptr;
        double u = srs.GetTargetLinearUnits("VERT_CS", &name);
        if (u > 0 && std::abs(u - 1.0) > 1e-12) zCrs = u, zCrsUnit = name ? name : "?";
    }
    const bool unitsSayDegrees = metadataSaysDegrees(*o.ds);
    o.band = std::make_unique<detail::BandReader>(*o.ds, opt, report, zCrs, zCrsUnit);
    if (!o.hasGt) {
        // No georeferencing: pixel (c, r) -> (c, -r) metres; the file itself can't say more.
        gt = GeoTransform{};
        gt.g[3] = static_cast<double>(height);
        report.warnings.push_back(
            "no georeferencing: pixels taken as 1 m squares in a local frame (assign one with gdal_translate -a_ullr / "
            "-a_srs)");
    }
    if (!o.hasSrs && !o.localFrame && o.hasGt && looksLikeDegrees(gt, width, height, unitsSayDegrees)) {
        srs.SetWellKnownGeogCS("WGS84");
        o.hasSrs = true;
        report.sourceCrsName = "none; taken as WGS 84";
        const double* g = gt.g;
        report.warnings.push_back(
            "no CRS, and the coordinates look like degrees (" +
            std::string(unitsSayDegrees ? "the file's units say degrees_east, " : "") + "x " + fmt(g[0]) + ".." +
            fmt(g[0] + g[1] * double(width)) + ", y " + fmt(g[3] + g[5] * double(height)) + ".." + fmt(g[3]) +
            "): taken as geographic WGS 84; name the CRS with --s_srs, or take them as metres with --s_srs local");
    }

    if (!opt.targetSrs.empty()) {
        if (o.target.SetFromUserInput(opt.targetSrs.c_str()) != OGRERR_NONE)
            throw Error("--t_srs " + opt.targetSrs + ": not a CRS that GDAL/PROJ knows");
        if (!o.target.IsProjected())
            throw Error("--t_srs " + opt.targetSrs + ": not a projected CRS (the grid needs metres)");
        if (!o.hasSrs) throw Error(opt.input + ": has no CRS to project from; name it with --s_srs");
        o.route = Opened::Route::Warp;
        return o;
    }
    if (!o.hasSrs) {
        if (o.hasGt && !o.localFrame) {
            // Degrees by their range, but neither fine nor global enough to say so with confidence.
            const bool couldBeDegrees = looksLikeDegrees(gt, width, height, true);
            report.warnings.push_back(
                std::string("no CRS: coordinates taken as metres in a local frame (name the CRS with --s_srs") +
                (couldBeDegrees ? "; they would fit degrees too: if they are, --s_srs EPSG:4326)" : ")"));
        }
        report.gridCrsName = "";
        o.pixelM = std::min(std::abs(gt.g[1]), std::abs(gt.g[5]));
        return o;
    }
    if (srs.IsGeographic()) {
        if (gt.rotated())
            throw Error(opt.input +
                        ": rotated geotransform on a geographic CRS is not supported; warp it with gdalwarp first");
        o.route = Opened::Route::Utm;
        return o;
    }
    if (!srs.IsProjected()) {
        const std::string name = "'" + report.sourceCrsName + "'";
        const std::string way =
            ": name the real CRS with --s_srs (e.g. --s_srs EPSG:25832), or take the coordinates as metres in "
            "a local frame with --s_srs local";
        if (srs.IsLocal())
            throw Error(opt.input + ": CRS " + name +
                        " is a local (engineering) CRS, tied to no place on Earth (often the sign of "
                        "incomplete GeoTIFF GeoKeys)" +
                        way);
        if (srs.IsGeocentric())
            throw Error(opt.input + ": CRS " + name +
                        " is geocentric (x, y, z from the Earth's centre), not a map CRS" + way);
        if (srs.IsVertical())
            throw Error(opt.input + ": CRS " + name + " is only a vertical CRS (heights, no horizontal position)" +
                        way);
        throw Error(opt.input + ": CRS " + name + " is neither projected nor geographic" + way);
    }
    const char* unitNamePtr = nullptr;
    const double unit = srs.GetLinearUnits(&unitNamePtr);
    const std::string unitName = unitNamePtr ? unitNamePtr : "?";  // copied: the update below changes it
    if (unit != 1.0) {
        for (double& v : gt.g) v *= unit;
        srs.SetLinearUnitsAndUpdateParameters(SRS_UL_METER, 1.0);
        report.warnings.push_back("horizontal units are " + unitName + ": converted to metres (x" + fmt(unit, 10) +
                                  ")");
        if (zCrs == 1.0 && !opt.terrainRgb && opt.zScale == 1.0 &&
            report.warnings.end() ==
                std::find_if(report.warnings.begin(), report.warnings.end(),
                             [](const std::string& w) { return w.rfind("elevations are in", 0) == 0; }))
            report.warnings.push_back(
                "elevations taken as metres (neither the band nor the CRS names their unit); in a CRS in " + unitName +
                " they are often in the same unit: if so, add --z-scale " + fmt(unit, 10));
    }
    report.gridCrsName = detail::crsName(&srs);
    o.pixelM = std::min(std::abs(gt.g[1]), std::abs(gt.g[5]));
    if (gt.rotated()) o.pixelM = std::min(std::hypot(gt.g[1], gt.g[4]), std::hypot(gt.g[2], gt.g[5]));
    o.wkt = detail::toWkt(srs);
    return o;
}

}  // namespace detail

Raster loadTerrain(const Options& opt, LoadReport& report) { return detail::loadTerrainTraced(opt, report, nullptr); }

Raster detail::loadTerrainTraced(const Options& opt, LoadReport& report, SourceTrace* trace) {
    Opened o = openTerrain(opt, report);
    SourceBand src;
    {
        src.width = o.band->width();
        src.height = o.band->height();
        src.values.reserve(src.width * src.height);
        adviseHugePages(src.values.data(), src.width * src.height * sizeof(float));
        src.values.assign(src.width * src.height, kNaN);
        const size_t strip = o.band->stripRows(size_t{1} << 20);  // ~1 MB buffers, whole rows of blocks
        SourceTally tally;
        Progress progress("reading " + opt.input, src.height, opt.progress);
        for (size_t r0 = 0; r0 < src.height; r0 += strip) {
            const size_t rows = std::min(strip, src.height - r0);
            o.band->read(0, r0, src.width, rows, src.values.data() + r0 * src.width, src.residual, r0 * src.width,
                         src.values.size(), tally);
            o.band->dropCache();
            progress.advance(rows);
        }
        progress.finish();
        o.band->finish(tally, report);
    }
    o.band.reset();
    o.ds.reset();  // releases GDAL's cached blocks of the file before the working raster is made
    switch (o.route) {
        case Opened::Route::Warp:
            return warpToTarget(std::move(src), o.gt, o.srs, o.target, opt, report, trace);
        case Opened::Route::Utm:
            return projectToUtm(std::move(src), o.gt, o.srs, opt, report, trace);
        case Opened::Route::Affine:
            break;
    }
    return fromSourceAffine(std::move(src), o.gt, o.pixelM, o.wkt, opt, report, trace);
}

}  // namespace hc::ingest
