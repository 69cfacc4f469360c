// loadTerrain: raster file -> metric, north-up, square-pixel working raster (ingest.h).
#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <sstream>

#include <unistd.h>

#include <GeographicLib/Math.hpp>
#include <GeographicLib/TransverseMercator.hpp>
#include <GeographicLib/UTMUPS.hpp>
#include <gdal_alg.h>
#include <gdalwarper.h>

#include "gdal_util.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/ranks.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/ingest/ingest.h"
#include "resample.h"
#include "warp_seam.h"

namespace hc::ingest {

using detail::DatasetPtr;
using detail::SourceBand;

namespace {

constexpr double kSquareTolerance = 1e-3;  // pixels within 0.1 % of square are taken as square
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

using detail::fmt;
using detail::lower;

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
    const bool square = std::abs(std::abs(g[1]) - std::abs(g[5])) <= kSquareTolerance * std::max(std::abs(g[1]), std::abs(g[5]));
    const bool sameSize = !opt.minCellM || std::abs(*opt.minCellM - std::abs(g[1])) <= 1e-9 * std::abs(g[1]);
    return !gt.rotated() && square && sameSize;
}

// The geometry of a source kept as is (keptAsIs), flipped so that row 0 is north and column 0 west: r's size,
// pixel and corner, the report's method and the warning of snapped pixels. Values are not touched.
void keptGeometry(const GeoTransform& gt, size_t width, size_t height, Raster& r, bool& flipX, bool& flipY, LoadReport& report) {
    const double* g = gt.g;
    r.width = width;
    r.height = height;
    r.pixelSizeM = std::abs(g[1]);
    flipX = g[1] < 0, flipY = g[5] > 0;
    r.westWorld = flipX ? g[0] + g[1] * static_cast<double>(width) : g[0];
    r.northWorld = flipY ? g[3] + g[5] * static_cast<double>(height) : g[3];
    if (std::abs(g[1]) != std::abs(g[5])) {
        double shift = std::abs(std::abs(g[5]) - std::abs(g[1])) * static_cast<double>(height);
        report.warnings.push_back("pixels of " + fmt(std::abs(g[1])) + " x " + fmt(std::abs(g[5])) +
                                  " m are within 0.1 % of square: snapped (not resampled) to " + fmt(r.pixelSizeM) +
                                  " m squares, which moves the south edge by " + fmt(shift, 3) + " m");
    }
    if (flipX || flipY)
        report.method += std::string(report.method.empty() ? "" : "; ") + (flipY ? "south-up rows flipped north-up" : "") +
                         (flipX && flipY ? ", " : "") + (flipX ? "east-to-west columns flipped" : "");
    if (report.method.empty()) report.method = "kept as is";
}

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
    std::function<void(size_t row, std::vector<double>& x, std::vector<double>& y, std::vector<int>& ok)> rowToWorld;  // SourceTrace's
    bool rowToWorldThreadSafe = true;  // false for PROJ's transformations (--t_srs)
};

// A source on an affine geotransform that is rotated, has non-square pixels or is resampled to --min-cell.
// `whole`: the working raster will be held whole (its size is checked against this machine's memory).
Resampling planAffine(const GeoTransform& gt, size_t width, size_t height, double pixelM, const std::string& wkt, const Options& opt,
                      LoadReport& report, bool whole) {
    Resampling p;
    Raster& r = p.shape;
    r.crsWkt = wkt;
    r.crsName = report.gridCrsName;  // each caller names the grid CRS in the report before it comes here
    const double* g = gt.g;
    const bool square = std::abs(std::abs(g[1]) - std::abs(g[5])) <= kSquareTolerance * std::max(std::abs(g[1]), std::abs(g[5]));
    double inv[6];
    if (!gt.invert(inv)) throw Error(opt.input + ": geotransform cannot be inverted (degenerate pixel size)");
    double xs[4], ys[4];
    double cw = static_cast<double>(width), ch = static_cast<double>(height);
    const double corners[4][2] = {{0, 0}, {cw, 0}, {0, ch}, {cw, ch}};
    for (int k = 0; k < 4; ++k) gt.apply(corners[k][0], corners[k][1], xs[k], ys[k]);
    double xmin = *std::min_element(xs, xs + 4), xmax = *std::max_element(xs, xs + 4);
    double ymin = *std::min_element(ys, ys + 4), ymax = *std::max_element(ys, ys + 4);
    r.pixelSizeM = opt.minCellM ? *opt.minCellM : pixelM;
    if (whole) checkWorkingSize(std::ceil((xmax - xmin) / r.pixelSizeM), std::ceil((ymax - ymin) / r.pixelSizeM), r.pixelSizeM, opt);
    r.width = static_cast<size_t>(std::ceil((xmax - xmin) / r.pixelSizeM - 1e-9));
    r.height = static_cast<size_t>(std::ceil((ymax - ymin) / r.pixelSizeM - 1e-9));
    r.westWorld = xmin;
    r.northWorld = ymax;
    std::string why = gt.rotated() ? "rotated geotransform" : (!square ? "non-square pixels" : "--min-cell");
    report.method += std::string(report.method.empty() ? "" : "; ") + "resampled north-up onto " + fmt(r.pixelSizeM) +
                     " m squares (" + why + ", bilinear)";
    p.map = [i0 = inv[0], i1 = inv[1], i2 = inv[2], i3 = inv[3], i4 = inv[4], i5 = inv[5]](double x, double y, double& col, double& row) {
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

// Geographic -> UTM zone of the raster centre, on the source's own ellipsoid (GeographicLib's
// Krueger series: accurate to 5 nm within 3900 km of the central meridian).
// Longitudes may run 0..360 or anywhere past 180: every longitude below is taken on the circle,
// relative to the raster's centre, so 234..238 E is the same as 126..122 W, and a raster across the
// antimeridian stays whole (its UTM zone sits across 180).
Resampling planUtm(const GeoTransform& gt, size_t width, size_t height, const OGRSpatialReference& geo, const Options& opt,
                   LoadReport& report, bool whole) {
    using GeographicLib::Math;
    const double degPerUnit = geo.GetAngularUnits() * 180.0 / M_PI;
    const double pm = geo.GetPrimeMeridian();  // degrees east of Greenwich
    auto lonLat = [&](double col, double row, double& lon, double& lat) {
        gt.apply(col, row, lon, lat);
        lon = lon * degPerUnit + pm;
        lat *= degPerUnit;
    };
    // The outline, sampled along every edge; longitudes as offsets from the centre's.
    const double cw = static_cast<double>(width), ch = static_cast<double>(height);
    double lonC, latC;
    lonLat(cw / 2, ch / 2, lonC, latC);
    double lonMin = HUGE_VAL, lonMax = -HUGE_VAL, latMin = HUGE_VAL, latMax = -HUGE_VAL;
    std::vector<std::pair<double, double>> outline;
    for (int k = 0; k <= 64; ++k) {
        double t = k / 64.0;
        for (auto [c, r] : {std::pair{t * cw, 0.0}, {t * cw, ch}, {0.0, t * ch}, {cw, t * ch}}) {
            double lon, lat;
            lonLat(c, r, lon, lat);
            outline.emplace_back(lon, lat);
            lonMin = std::min(lonMin, lon);
            lonMax = std::max(lonMax, lon);
            latMin = std::min(latMin, lat);
            latMax = std::max(latMax, lat);
        }
    }
    auto hint = std::string("; choose a projection with --t_srs (for example a Lambert azimuthal equal-area CRS centred on the data)");
    if (latMin < -80.0 || latMax > 84.0 || lonMax - lonMin >= 180.0)
        throw Error(opt.input + ": spans longitude " + fmt(lonMin) + ".." + fmt(lonMax) + " and latitude " + fmt(latMin) + ".." +
                    fmt(latMax) + " degrees: no UTM zone holds it (UTM covers 80S..84N, and a zone at most a few degrees either side of its meridian)" + hint);
    int zone = GeographicLib::UTMUPS::StandardZone(latC, Math::AngNormalize(lonC));
    const double lon0 = 6.0 * zone - 183.0;
    double maxOff = 0;
    for (auto [lon, lat] : outline) maxOff = std::max(maxOff, std::abs(Math::AngDiff(lon0, lon)));
    if (maxOff > 12.0)
        throw Error(opt.input + ": spans longitude " + fmt(lonMin) + ".." + fmt(lonMax) + " degrees, up to " + fmt(maxOff, 3) +
                    " degrees from the central meridian of UTM zone " + std::to_string(zone) +
                    " (at most 12 are accepted: distortion grows fast beyond)" + hint);
    const bool north = latC >= 0;
    const double a = geo.GetSemiMajor();
    const double invf = geo.GetInvFlattening();
    const GeographicLib::TransverseMercator tm(a, invf > 0 ? 1.0 / invf : 0.0, GeographicLib::Constants::UTM_k0());
    const double fe = 500000.0, fn = north ? 0.0 : 10000000.0;
    auto forward = [&](double lon, double lat, double& x, double& y) {
        tm.Forward(lon0, lat, lon, x, y);
        x += fe;
        y += fn;
    };

    // Finest size: the smaller side of the centre pixel once projected.
    double x0, y0, x1, y1, x2, y2, lo, la;
    lonLat(cw / 2, ch / 2, lo, la);
    forward(lo, la, x0, y0);
    lonLat(cw / 2 + 1, ch / 2, lo, la);
    forward(lo, la, x1, y1);
    lonLat(cw / 2, ch / 2 + 1, lo, la);
    forward(lo, la, x2, y2);
    double dx = std::hypot(x1 - x0, y1 - y0), dy = std::hypot(x2 - x0, y2 - y0);

    Resampling p;
    Raster& r = p.shape;
    r.pixelSizeM = opt.minCellM ? *opt.minCellM : std::min(dx, dy);
    double xmin = HUGE_VAL, xmax = -HUGE_VAL, ymin = HUGE_VAL, ymax = -HUGE_VAL;
    for (auto [lon, lat] : outline) {
        double x, y;
        forward(lon, lat, x, y);
        xmin = std::min(xmin, x);
        xmax = std::max(xmax, x);
        ymin = std::min(ymin, y);
        ymax = std::max(ymax, y);
    }
    if (whole) checkWorkingSize(std::ceil((xmax - xmin) / r.pixelSizeM), std::ceil((ymax - ymin) / r.pixelSizeM), r.pixelSizeM, opt);
    r.width = static_cast<size_t>(std::ceil((xmax - xmin) / r.pixelSizeM - 1e-9));
    r.height = static_cast<size_t>(std::ceil((ymax - ymin) / r.pixelSizeM - 1e-9));
    r.westWorld = xmin;
    r.northWorld = ymax;

    OGRSpatialReference utm;
    utm.CopyGeogCSFrom(&geo);
    utm.SetUTM(zone, north);
    std::string projName = std::string(geo.GetName() ? geo.GetName() : "unnamed") + " / UTM zone " + std::to_string(zone) + (north ? "N" : "S");
    utm.SetProjCS(projName.c_str());
    utm.SetLinearUnits(SRS_UL_METER, 1.0);
    utm.AutoIdentifyEPSG();
    r.crsWkt = detail::toWkt(utm);
    report.gridCrsName = detail::crsName(&utm);
    r.crsName = report.gridCrsName;
    report.method = "projected to UTM zone " + std::to_string(zone) + (north ? "N" : "S") + " (GeographicLib, " +
                    "pixels " + fmt(dx, 4) + " x " + fmt(dy, 4) + " m) and resampled onto " + fmt(r.pixelSizeM, 4) +
                    " m squares (bilinear)";

    double inv[6];
    if (!gt.invert(inv)) throw Error(opt.input + ": geotransform cannot be inverted (degenerate pixel size)");
    // Everything by value: the map outlives this function (window by window).
    p.map = [tm, lon0, fe, fn, lonC, pm, degPerUnit, i0 = inv[0], i1 = inv[1], i2 = inv[2], i3 = inv[3], i4 = inv[4], i5 = inv[5]](
                double x, double y, double& col, double& row) {
        double lat, lon;
        tm.Reverse(lon0, x - fe, y - fn, lat, lon);
        lon = lonC + Math::AngDiff(lonC, lon);  // back into the source's own longitude range
        double gx = (lon - pm) / degPerUnit, gy = lat / degPerUnit;
        col = i0 + gx * i1 + gy * i2;
        row = i3 + gx * i4 + gy * i5;
        return std::isfinite(col) && std::isfinite(row);
    };
    // 1e-5 pixel: at slopes of 100 m per pixel (alpine SRTM) that is 1 mm of elevation.
    p.lattice = 16, p.maxErrorPx = 1e-5, p.sayLattice = true;
    if (std::abs(lonC - Math::AngNormalize(lonC)) > 1e-9)
        p.methodTail = "; longitudes " + fmt(lonMin) + ".." + fmt(lonMax) + " read as " + fmt(Math::AngNormalize(lonMin)) + ".." +
                       fmt(Math::AngNormalize(lonMin) + (lonMax - lonMin));
    {
        // Outlives this function: everything by value. The projection of every source pixel centre was most of
        // the check's time (geographic SRTM ingest 2.8-3.2x slower, BENCHMARKS.md): along a row the map is
        // smooth, so it is projected exactly at every 8th column and interpolated by the parabola through three
        // such nodes in between, checked against an exact projection in each 16-column span: kept where the
        // check is within 1e-6 m (the residual, cubic between the nodes, peaks at most 1.2x the check point's),
        // else that span is projected exactly, column by column.
        p.rowToWorld = [gt, degPerUnit, pm, tm, lon0, fe, fn](size_t row, std::vector<double>& x, std::vector<double>& y,
                                                              std::vector<int>& ok) {
            const double rc = static_cast<double>(row) + 0.5;
            auto exact = [&](size_t c, double& ox, double& oy) {
                double lon, lat;
                gt.apply(static_cast<double>(c) + 0.5, rc, lon, lat);
                tm.Forward(lon0, lat * degPerUnit, lon * degPerUnit + pm, ox, oy);
                ox += fe;
                oy += fn;
                return std::isfinite(ox) && std::isfinite(oy);
            };
            constexpr size_t kHalf = 8, kSpan = 2 * kHalf;
            constexpr double kMaxErrM = 1e-6;
            const size_t w = x.size();
            size_t c0 = 0;
            // A span's last node is the next span's first: projected once (3 exact projections a span, not 4).
            double lastX = 0, lastY = 0;
            bool lastOk = false, haveLast = false;
            for (; c0 + kSpan < w; c0 += kSpan) {
                // Nodes at c0, c0 + 8, c0 + 16; the check at c0 + 5 (no node, not the span's symmetric point).
                double nx[3], ny[3], qx, qy;
                const bool first = haveLast ? (nx[0] = lastX, ny[0] = lastY, lastOk) : exact(c0, nx[0], ny[0]);
                const bool end = exact(c0 + kSpan, nx[2], ny[2]);
                lastX = nx[2], lastY = ny[2], lastOk = end, haveLast = true;
                bool good = first && exact(c0 + kHalf, nx[1], ny[1]) && end;
                auto para = [&](const double* n, size_t c) {
                    const double s = (static_cast<double>(c - c0) - double(kHalf)) / double(kHalf);  // -1, 0, 1 at the nodes
                    return n[1] + 0.5 * s * (n[2] - n[0]) + 0.5 * s * s * (n[2] - 2 * n[1] + n[0]);
                };
                good = good && exact(c0 + 5, qx, qy) && std::abs(para(nx, c0 + 5) - qx) <= kMaxErrM && std::abs(para(ny, c0 + 5) - qy) <= kMaxErrM;
                for (size_t c = c0; c < c0 + kSpan; ++c) {
                    if (good) {
                        x[c] = para(nx, c), y[c] = para(ny, c), ok[c] = 1;
                    } else {
                        ok[c] = exact(c, x[c], y[c]);
                    }
                }
            }
            for (size_t c = c0; c < w; ++c) ok[c] = exact(c, x[c], y[c]);
        };
    }
    return p;
}

Raster projectToUtm(SourceBand&& src, const GeoTransform& gt, const OGRSpatialReference& geo, const Options& opt,
                    LoadReport& report, detail::SourceTrace* trace) {
    Resampling p = planUtm(gt, src.width, src.height, geo, opt, report, true);
    Raster r = std::move(p.shape);
    const int lattice = resample(src, p.map, r, p.lattice, p.maxErrorPx, opt.threads);
    report.method += ", map exact every " + std::to_string(lattice) + " px" + p.methodTail;
    if (trace) {
        trace->band = std::move(src);
        trace->rowToWorld = std::move(p.rowToWorld);
    }
    return r;
}

}  // namespace

void validateOptions(const Options& o) {
    auto bad = [](const std::string& m) { throw Error(m); };
    if (o.input.empty()) bad("no input raster given");
    if (o.band < 1) bad("--band " + std::to_string(o.band) + ": bands are numbered from 1");
    if (o.terrainRgb && o.band != 1) bad("--terrain-rgb reads bands 1-3; --band cannot be combined with it");
    if (!std::isfinite(o.toleranceM) || o.toleranceM < 0) bad("--tolerance " + fmt(o.toleranceM) + ": must be a finite number of metres >= 0");
    if (o.minCellM && !(std::isfinite(*o.minCellM) && *o.minCellM > 0)) bad("--min-cell " + fmt(*o.minCellM) + ": must be a positive number of metres");
    if (o.maxCellM && !(std::isfinite(*o.maxCellM) && *o.maxCellM > 0)) bad("--max-cell " + fmt(*o.maxCellM) + ": must be a positive number of metres");
    if (o.minCellM && o.maxCellM && *o.minCellM > *o.maxCellM)
        bad("--min-cell " + fmt(*o.minCellM) + " m is larger than --max-cell " + fmt(*o.maxCellM) + " m");
    if (!std::isfinite(o.zScale) || o.zScale == 0) bad("--z-scale " + fmt(o.zScale) + ": must be a finite non-zero factor");
    if (o.nodata && std::isnan(*o.nodata)) bad("--nodata nan: NaN is always nodata already");
    if ((o.water == WaterSource::Depth || o.water == WaterSource::Surface) && o.waterPath.empty() && o.waterPaths.empty())
        bad("no water raster given");
    if (o.water == WaterSource::Level && o.waterLevelsM.empty() && !std::isfinite(o.waterLevelM))
        bad("--water-level must be a finite elevation in metres");
    for (double l : o.waterLevelsM)
        if (!std::isfinite(l)) bad("--water-level " + fmt(l) + ": every level must be a finite elevation in metres");
    const size_t steps = waterStepCount(o);
    if (!o.timesS.empty()) {
        if (steps == 0) bad("--times given without water (--water, --water-surface or --water-level)");
        if (o.timesS.size() != steps)
            bad("--times lists " + std::to_string(o.timesS.size()) + " times for " + std::to_string(steps) + " water steps");
        for (size_t k = 0; k < o.timesS.size(); ++k) {
            if (!std::isfinite(o.timesS[k])) bad("--times: time " + std::to_string(k) + " is not a finite number of seconds");
            if (k > 0 && !(o.timesS[k] > o.timesS[k - 1]))
                bad("--times must increase strictly: " + fmt(o.timesS[k]) + " s follows " + fmt(o.timesS[k - 1]) + " s (step " + std::to_string(k) + ")");
        }
    }
}

size_t waterStepCount(const Options& o) {
    switch (o.water) {
        case WaterSource::None: return 0;
        case WaterSource::Level: return o.waterLevelsM.empty() ? 1 : o.waterLevelsM.size();
        default: return o.waterPaths.empty() ? 1 : o.waterPaths.size();
    }
}

double waterStepTimeS(const Options& o, size_t k) { return o.timesS.empty() ? static_cast<double>(k) : o.timesS.at(k); }

namespace {

// A source band as a GDAL dataset for the warper, of the whole source's size and georeferencing, whose blocks come
// from `fill` (our reading: every kind of nodata as NaN, metres, Terrain-RGB decoded) when the warper asks for them:
// a rank warping its windows reads only the source pixels they reach, and the one-process warp reads the band it holds.
// Columns [c0, c0 + width) of the source: one piece of a source split at 180 degrees.
class SourceDataset final : public GDALDataset {
public:
    using Fill = std::function<void(size_t col0, size_t row0, size_t w, size_t h, float* out)>;  // source columns, row-major
    SourceDataset(size_t c0, size_t width, size_t height, const GeoTransform& gt, const OGRSpatialReference* srs, Fill fill)
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
            const size_t w = std::min(size_t(nBlockXSize), size_t(nRasterXSize) - x0), h = std::min(size_t(nBlockYSize), size_t(nRasterYSize) - y0);
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
    std::unique_ptr<detail::WarpSeams> seams;             // pixels between the pieces' columns, interpolated across (or null)
    std::string note;                                     // for the report's method
    std::shared_ptr<OGRCoordinateTransformation> ct;       // source CRS -> target CRS (PROJ, exact)
    OGRSpatialReference target;
    std::string targetText, targetWkt, input;  // the target as given (--t_srs) and as WKT
    double ext[4] = {0, 0, 0, 0};  // west, south, east, north [target units]
    double cell = 1, scale = 1;    // output pixel [target units]; output pixels per source pixel (the kernel's)
    size_t width = 0, height = 0;  // output pixels
    unsigned threads = 0;

    // The warped raster's valid pixels, counted over all of it (every window): an error where none is valid, or where the
    // halves of a source split at 180 degrees do not meet (in a map whose own edge is at 180, EPSG:3857 say, they land
    // at its opposite edges, a world apart, with nothing between).
    void checkValid(uint64_t valid) const {
        const double all = double(width) * double(height);
        if (valid == 0)
            throw Error(input + ": projected to " + targetText + " on " + std::to_string(width) + " x " + std::to_string(height) +
                        " pixels of " + fmt(cell, 6) + " (CRS units), no pixel centre falls inside the data: " +
                        "the footprint is too thin for that resolution; give a finer one with --min-cell");
        if (sources.size() == 2 && double(valid) < 0.1 * all)
            throw Error(input + ": crosses 180 degrees of longitude, which is an edge of " + targetText + ": its two halves would lie at " +
                        "the map's opposite edges (" + fmt(100.0 * double(valid) / all, 3) + " % of a " + std::to_string(width) +
                        " px wide raster); choose a --t_srs whose central meridian is near the data (e.g. " +
                        "EPSG:3832, PDC Mercator, or '+proj=laea +lon_0=180 +lat_0=...') or leave --t_srs out for its UTM zone");
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

// The output lattice of --t_srs for a source of width x height pixels on gtIn (no pixel read: `fill` gives them when a
// window is warped), the pieces, and the report's method note.
WarpPlan planWarp(const GeoTransform& gtIn, size_t width, size_t height, const OGRSpatialReference& srs, const OGRSpatialReference& target,
                  const Options& opt, LoadReport& report, const SourceDataset::Fill& fill) {
    WarpPlan plan;
    plan.target = target;
    plan.targetText = opt.targetSrs;
    plan.targetWkt = detail::toWkt(target);
    plan.input = opt.input;
    plan.threads = opt.threads;
    struct Piece {
        size_t c0, c1;
        GeoTransform gt;
    };
    std::vector<Piece> pieces{{0, width, gtIn}};
    std::vector<detail::WarpSeams::Seam> seams;  // where the warp reads two columns from different pieces
    GeoTransform moved = gtIn;                   // the source with its west edge in -180..180 (the seams' frame)
    std::string& note = plan.note;
    const double dx = gtIn.g[1];
    if (srs.IsGeographic() && !gtIn.rotated() && dx > 0 && srs.GetPrimeMeridian() == 0 &&
        std::abs(srs.GetAngularUnits() - M_PI / 180) < 1e-12) {
        GeoTransform gt = gtIn;
        // West edge into [-180, 180) give or take half a pixel: a grid whose first pixel centre is at -180
        // (west edge -180.5) stays where it is.
        gt.g[0] -= 360.0 * std::floor((gt.g[0] + dx / 2 + 180.0) / 360.0);
        const double w = static_cast<double>(width);
        // Columns with centres at 180 or beyond go east; those at west + 360 or beyond repeat column 0.
        const auto firstEast = static_cast<size_t>(std::clamp(std::ceil((180.0 - gt.g[0]) / dx - 0.5), 0.0, w));
        const auto end = static_cast<size_t>(std::clamp(std::ceil(360.0 / dx - 1e-6), 0.0, w));
        pieces.assign(1, Piece{0, firstEast, gt});  // not = {{...}}: GCC 12 with ASan detect_stack_use_after_return crashed copying that initializer list
        if (firstEast < end) {
            GeoTransform east = gt;
            east.g[0] = gt.g[0] + static_cast<double>(firstEast) * dx - 360.0;
            pieces.push_back({firstEast, end, east});
            note = "; split at 180 degrees (east part shifted by -360)";
        }
        // Seams: at 180 degrees between the pieces, and around a grid that closes the globe (its last column before its first).
        if (firstEast < end && firstEast > 0) seams.push_back({firstEast - 1, firstEast, gt.g[0] + (double(firstEast) - 0.5) * dx});
        if (end <= width && std::abs(double(end) * dx - 360.0) < 1e-6 * 360.0) seams.push_back({end - 1, 0, gt.g[0] + (double(end) - 0.5) * dx});
        moved = gt;
        if (gt.g[0] != gtIn.g[0]) note += "; longitudes moved by " + fmt(gt.g[0] - gtIn.g[0]) + " degrees";
        if (end < width) note += "; " + std::to_string(width - end) + " closing column(s) repeating the first left out";
        if (pieces[0].c1 == 0) pieces.erase(pieces.begin());
    }
    const std::string& targetText = plan.targetText;
    // Source coordinates -> target CRS, exact (PROJ): for the output extent and the source check.
    OGRSpatialReference from = srs, to = target;
    from.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    to.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    plan.ct.reset(OGRCreateCoordinateTransformation(&from, &to), [](OGRCoordinateTransformation* t) { OGRCoordinateTransformation::DestroyCT(t); });
    if (!plan.ct) throw Error("--t_srs " + targetText + ": cannot transform from " + report.sourceCrsName + ": " + detail::lastGdalError());
    // The output extent: GDAL's suggestion shrinks to what its edge samples reach, and loses every
    // row beyond a failing edge (a global grid's poles at +-90.5 cut it to +-81 degrees). So: the
    // bounding box of the pixel corners and centres that do transform: all along the outline, and on a
    // lattice of every k-th one inside (at most about 1024 x 1024 points; whatever an extreme between
    // lattice points leaves out is counted by the source check as lost).
    double* ext = plan.ext;
    ext[0] = ext[1] = HUGE_VAL, ext[2] = ext[3] = -HUGE_VAL;
    {
        const size_t k = std::max<size_t>(1, std::max(width, height) / 1024);
        std::vector<double> xs, ys;
        auto take = [&](double half) {  // half = 0: corners; 0.5: centres (the last ones clamped to the edge)
            const size_t n = width + 1, m = height + 1;
            for (size_t j = 0; j < m; ++j) {
                const bool edgeRow = j == 0 || j + 2 >= m;
                for (size_t i = 0; i < n; ++i) {
                    if (!(edgeRow || i == 0 || i + 2 >= n || (i % k == 0 && j % k == 0))) continue;
                    const double c = std::min(double(i) + half, double(width)), r = std::min(double(j) + half, double(height));
                    double x, y;
                    gtIn.apply(c, r, x, y);
                    xs.push_back(x);
                    ys.push_back(y);
                }
            }
        };
        take(0.0);
        take(0.5);
        std::vector<int> ok(xs.size());
        CPLErrorReset();
        plan.ct->Transform(static_cast<int>(xs.size()), xs.data(), ys.data(), nullptr, ok.data());
        for (size_t i = 0; i < xs.size(); ++i)
            if (ok[i] && std::isfinite(xs[i]) && std::isfinite(ys[i]))
                ext[0] = std::min(ext[0], xs[i]), ext[1] = std::min(ext[1], ys[i]), ext[2] = std::max(ext[2], xs[i]),
                ext[3] = std::max(ext[3], ys[i]);
        if (!(ext[0] < ext[2] && ext[1] < ext[3]))
            throw Error(opt.input + ": no part of it has a position in " + targetText + " (PROJ: " + detail::lastGdalError() + ")");
    }
    double suggested = HUGE_VAL;
    for (const Piece& pc : pieces) {
        plan.sources.push_back(std::make_unique<SourceDataset>(pc.c0, pc.c1 - pc.c0, height, pc.gt, &srs, fill));
        // GDAL's suggested output, made square with the smaller side (the finest over the pieces).
        char** dst = CSLSetNameValue(nullptr, "DST_SRS", targetText.c_str());
        void* tr = GDALCreateGenImgProjTransformer2(GDALDataset::ToHandle(plan.sources.back().get()), nullptr, dst);
        CSLDestroy(dst);
        if (!tr) throw Error("--t_srs " + targetText + ": cannot transform from " + report.sourceCrsName + ": " + detail::lastGdalError());
        double sg[6];
        int pw = 0, ph = 0;
        CPLErr e = GDALSuggestedWarpOutput(GDALDataset::ToHandle(plan.sources.back().get()), GDALGenImgProjTransform, tr, sg, &pw, &ph);
        GDALDestroyGenImgProjTransformer(tr);
        if (e != CE_None) throw Error("--t_srs " + targetText + ": cannot project " + opt.input + ": " + detail::lastGdalError());
        suggested = std::min({suggested, std::abs(sg[1]), std::abs(sg[5])});
    }
    plan.cell = opt.minCellM ? *opt.minCellM / target.GetLinearUnits() : suggested;
    plan.scale = std::min(1.0, suggested / plan.cell);  // coarser than the source: the kernel widens (GDAL's downsampling)
    // Half a pixel more on every side: source pixel centres on the extent's edge (a pole, the
    // antimeridian) then fall inside the output rather than on its closing edge.
    const double cell = plan.cell;
    ext[0] -= cell / 2, ext[1] -= cell / 2, ext[2] += cell / 2, ext[3] += cell / 2;
    // gdalwarp's size for -te and -tr.
    plan.width = size_t((ext[2] - ext[0] + cell / 2) / cell);
    plan.height = size_t((ext[3] - ext[1] + cell / 2) / cell);
    if (plan.width == 0 || plan.height == 0) throw Error(opt.input + ": projected to " + targetText + ": an empty raster");
    checkWorkingSize(double(plan.width), double(plan.height), cell * target.GetLinearUnits(), opt);
    // Across the seams, pixels as fine as the source or finer (a coarser output widens GDAL's kernel: not done here).
    if (!seams.empty() && plan.scale == 1.0)
        plan.seams = std::make_unique<detail::WarpSeams>(seams, moved.g, height, srs, target, plan.ct, plan.ext, plan.cell, plan.width,
                                                         plan.height, fill);
    return plan;
}

// The working raster of a warp in metres: the target CRS with its linear unit made metres, the output lattice scaled
// to match (unit: metres per target unit); the report names that CRS and the method.
struct WarpedFrame {
    OGRSpatialReference crs;
    GeoTransform gt;
    double unit = 1;
};
WarpedFrame warpedFrame(const WarpPlan& plan, LoadReport& report) {
    WarpedFrame f;
    f.crs = plan.target;
    f.crs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    f.unit = f.crs.GetLinearUnits();
    if (f.unit != 1.0) f.crs.SetLinearUnitsAndUpdateParameters(SRS_UL_METER, 1.0);
    f.gt = plan.outputGt();
    for (double& v : f.gt.g) v *= f.unit;
    report.gridCrsName = detail::crsName(&f.crs);
    report.method = "warped to " + report.gridCrsName + " by GDAL (bilinear, exact transformer)" + plan.note;
    return f;
}

// Where each source pixel centre lands in the working raster's CRS [m]: PROJ, exact, from the source's own coordinates.
std::function<void(size_t, std::vector<double>&, std::vector<double>&, std::vector<int>&)> warpRowToWorld(const WarpPlan& plan,
                                                                                                        const GeoTransform& gtIn, double unit) {
    return [ct = plan.ct, gt = gtIn, unit](size_t row, std::vector<double>& x, std::vector<double>& y, std::vector<int>& ok) {
        for (size_t c = 0; c < x.size(); ++c) gt.apply(static_cast<double>(c) + 0.5, static_cast<double>(row) + 0.5, x[c], y[c]);
        CPLErrorReset();
        ct->Transform(static_cast<int>(x.size()), x.data(), y.data(), nullptr, ok.data());
        for (size_t c = 0; c < x.size(); ++c) {
            ok[c] = ok[c] && std::isfinite(x[c]) && std::isfinite(y[c]);
            x[c] *= unit;
            y[c] *= unit;
        }
    };
}

Raster warpToTarget(SourceBand&& src, const GeoTransform& gtIn, const OGRSpatialReference& srs, const OGRSpatialReference& target,
                    const Options& opt, LoadReport& report, detail::SourceTrace* trace) {
    auto fill = [&src](size_t c0, size_t r0, size_t w, size_t h, float* out) {
        for (size_t r = 0; r < h; ++r) std::copy_n(src.values.data() + (r0 + r) * src.width + c0, w, out + r * w);
    };
    WarpPlan plan = planWarp(gtIn, src.width, src.height, srs, target, opt, report, fill);
    SourceBand ws;
    ws.width = plan.width, ws.height = plan.height;
    ws.values.resize(ws.width * ws.height);
    {
        // In strips of rows (each its own window), so the warper's buffers stay small.
        const size_t strip = std::max<size_t>(1, (size_t{1} << 22) / ws.width);
        Progress progress("projecting to " + plan.targetText, ws.height, opt.progress);
        for (size_t r0 = 0; r0 < ws.height; r0 += strip) {
            const size_t rows = std::min(strip, ws.height - r0);
            plan.warp(0, r0, ws.width, rows, ws.values.data() + r0 * ws.width);
            progress.advance(rows);
        }
        progress.finish();
    }
    plan.checkValid(uint64_t(std::count_if(ws.values.begin(), ws.values.end(), [](float v) { return !std::isnan(v); })));
    const WarpedFrame frame = warpedFrame(plan, report);
    Options keep = opt;
    keep.minCellM.reset();  // -tr already applied it
    Raster r = fromSourceAffine(std::move(ws), frame.gt, std::abs(frame.gt.g[1]), detail::toWkt(frame.crs), keep, report, nullptr);
    if (trace) {
        trace->band = std::move(src);
        trace->rowToWorldThreadSafe = false;  // PROJ's transformations
        trace->rowToWorld = warpRowToWorld(plan, gtIn, frame.unit);
    }
    return r;
}

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
        if (v.rfind("degrees_east", 0) == 0 || v.rfind("degree_east", 0) == 0 || v.rfind("degrees_e", 0) == 0) return true;
    }
    return false;
}

}  // namespace

namespace {

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
        report.warnings.push_back("--s_srs local: coordinates taken as metres in a local frame, the file's own CRS (if any) ignored");
    } else if (!opt.sourceSrs.empty()) {
        if (srs.SetFromUserInput(opt.sourceSrs.c_str()) != OGRERR_NONE)
            throw Error("--s_srs " + opt.sourceSrs + ": not a CRS that GDAL/PROJ knows (or 'local' for metres in a local frame)");
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
        report.warnings.push_back("no georeferencing: pixels taken as 1 m squares in a local frame (assign one with gdal_translate -a_ullr / -a_srs)");
    }
    if (!o.hasSrs && !o.localFrame && o.hasGt && looksLikeDegrees(gt, width, height, unitsSayDegrees)) {
        srs.SetWellKnownGeogCS("WGS84");
        o.hasSrs = true;
        report.sourceCrsName = "none; taken as WGS 84";
        const double* g = gt.g;
        report.warnings.push_back("no CRS, and the coordinates look like degrees (" +
                                  std::string(unitsSayDegrees ? "the file's units say degrees_east, " : "") + "x " + fmt(g[0]) + ".." +
                                  fmt(g[0] + g[1] * double(width)) + ", y " + fmt(g[3] + g[5] * double(height)) + ".." + fmt(g[3]) +
                                  "): taken as geographic WGS 84; name the CRS with --s_srs, or take them as metres with --s_srs local");
    }

    if (!opt.targetSrs.empty()) {
        if (o.target.SetFromUserInput(opt.targetSrs.c_str()) != OGRERR_NONE)
            throw Error("--t_srs " + opt.targetSrs + ": not a CRS that GDAL/PROJ knows");
        if (!o.target.IsProjected()) throw Error("--t_srs " + opt.targetSrs + ": not a projected CRS (the grid needs metres)");
        if (!o.hasSrs) throw Error(opt.input + ": has no CRS to project from; name it with --s_srs");
        o.route = Opened::Route::Warp;
        return o;
    }
    if (!o.hasSrs) {
        if (o.hasGt && !o.localFrame) {
            // Degrees by their range, but neither fine nor global enough to say so with confidence.
            const bool couldBeDegrees = looksLikeDegrees(gt, width, height, true);
            report.warnings.push_back(std::string("no CRS: coordinates taken as metres in a local frame (name the CRS with --s_srs") +
                                      (couldBeDegrees ? "; they would fit degrees too: if they are, --s_srs EPSG:4326)" : ")"));
        }
        report.gridCrsName = "";
        o.pixelM = std::min(std::abs(gt.g[1]), std::abs(gt.g[5]));
        return o;
    }
    if (srs.IsGeographic()) {
        if (gt.rotated()) throw Error(opt.input + ": rotated geotransform on a geographic CRS is not supported; warp it with gdalwarp first");
        o.route = Opened::Route::Utm;
        return o;
    }
    if (!srs.IsProjected()) {
        const std::string name = "'" + report.sourceCrsName + "'";
        const std::string way = ": name the real CRS with --s_srs (e.g. --s_srs EPSG:25832), or take the coordinates as metres in "
                                "a local frame with --s_srs local";
        if (srs.IsLocal())
            throw Error(opt.input + ": CRS " + name + " is a local (engineering) CRS, tied to no place on Earth (often the sign of "
                        "incomplete GeoTIFF GeoKeys)" + way);
        if (srs.IsGeocentric()) throw Error(opt.input + ": CRS " + name + " is geocentric (x, y, z from the Earth's centre), not a map CRS" + way);
        if (srs.IsVertical()) throw Error(opt.input + ": CRS " + name + " is only a vertical CRS (heights, no horizontal position)" + way);
        throw Error(opt.input + ": CRS " + name + " is neither projected nor geographic" + way);
    }
    const char* unitNamePtr = nullptr;
    const double unit = srs.GetLinearUnits(&unitNamePtr);
    const std::string unitName = unitNamePtr ? unitNamePtr : "?";  // copied: the update below changes it
    if (unit != 1.0) {
        for (double& v : gt.g) v *= unit;
        srs.SetLinearUnitsAndUpdateParameters(SRS_UL_METER, 1.0);
        report.warnings.push_back("horizontal units are " + unitName + ": converted to metres (x" + fmt(unit, 10) + ")");
        if (zCrs == 1.0 && !opt.terrainRgb && opt.zScale == 1.0 && report.warnings.end() ==
            std::find_if(report.warnings.begin(), report.warnings.end(), [](const std::string& w) { return w.rfind("elevations are in", 0) == 0; }))
            report.warnings.push_back("elevations taken as metres (neither the band nor the CRS names their unit); in a CRS in " + unitName +
                                      " they are often in the same unit: if so, add --z-scale " + fmt(unit, 10));
    }
    report.gridCrsName = detail::crsName(&srs);
    o.pixelM = std::min(std::abs(gt.g[1]), std::abs(gt.g[5]));
    if (gt.rotated()) o.pixelM = std::min(std::hypot(gt.g[1], gt.g[4]), std::hypot(gt.g[2], gt.g[5]));
    o.wkt = detail::toWkt(srs);
    return o;
}

// TerrainWindows over a source kept as is: a working window is the same window of the source, mirrored where the
// source runs south-up or east-to-west.
class KeptWindows final : public detail::TerrainWindows {
public:
    KeptWindows(Opened&& o, LoadReport& report) : o_(std::move(o)) {
        shape_.crsWkt = o_.wkt;
        shape_.crsName = report.gridCrsName;
        keptGeometry(o_.gt, o_.band->width(), o_.band->height(), shape_, flipX_, flipY_, report);
    }
    const Raster& shape() const override { return shape_; }
    void read(size_t col0, size_t row0, size_t w, size_t h, std::vector<float>& values, std::vector<float>& rounding) override {
        if (col0 + w > shape_.width || row0 + h > shape_.height) throw Error("window outside the working raster");
        const size_t c0 = flipX_ ? shape_.width - col0 - w : col0, r0 = flipY_ ? shape_.height - row0 - h : row0;
        values.assign(w * h, kNaN);
        rounding.clear();
        o_.band->read(c0, r0, w, h, values.data(), rounding, 0, w * h, tally_);
        if (flipX_ || flipY_) {
            auto mirror = [&](std::vector<float>& v) {
                if (v.empty()) return;
                std::vector<float> m(v.size());
                for (size_t r = 0; r < h; ++r)
                    for (size_t c = 0; c < w; ++c) m[r * w + c] = v[(flipY_ ? h - 1 - r : r) * w + (flipX_ ? w - 1 - c : c)];
                v.swap(m);
            };
            mirror(values);
            mirror(rounding);
        }
    }
    const detail::SourceTally& tally() const override { return tally_; }
    void finish(const detail::SourceTally& all, LoadReport& report) const override { o_.band->finish(all, report); }

private:
    Opened o_;
    Raster shape_;
    bool flipX_ = false, flipY_ = false;
    detail::SourceTally tally_;
};

// TerrainWindows over a source that is resampled (projected to UTM, rotated, non-square pixels or --min-cell): a working
// window reads the source pixels its map reaches (resampleWindow asks for them) and resamples them on the whole target's lattice, so
// its pixels are the same bits as the whole raster's (resample.h). The reading tally counts every source pixel once:
// each rank reads its share of the source's row strips for it (one more pass over the source, spread over the ranks),
// and in the same pass, once the grid file is written, checks those pixels against the cells under their centres
// (LoadReport::sourceCheck), each strip against the file's region under it.
class ResampledWindows final : public detail::TerrainWindows {
public:
    ResampledWindows(Opened&& o, Resampling&& plan, const Options& opt, LoadReport& report)
        : o_(std::move(o)), plan_(std::move(plan)), threads_(opt.threads), progress_(opt.progress) {
        step_ = detail::latticeStep(plan_.shape, plan_.map, plan_.lattice, plan_.maxErrorPx, threads_);
        if (plan_.sayLattice) report.method += ", map exact every " + std::to_string(step_) + " px" + plan_.methodTail;
    }
    // --t_srs: the windows warped by GDAL (WarpPlan::warp), the source's blocks read as the warper asks for them.
    ResampledWindows(Opened&& o, const Options& opt, LoadReport& report) : o_(std::move(o)), threads_(opt.threads), progress_(opt.progress) {
        const size_t width = o_.band->width(), height = o_.band->height();
        auto fill = [this](size_t c0, size_t r0, size_t w, size_t h, float* out) {
            std::vector<float> residual;  // the warper takes float32 values (as read whole)
            detail::SourceTally uncounted;  // counted once by tally()
            o_.band->read(c0, r0, w, h, out, residual, 0, w * h, uncounted);
        };
        warp_ = std::make_unique<WarpPlan>(planWarp(o_.gt, width, height, o_.srs, o_.target, opt, report, fill));
        const WarpedFrame frame = warpedFrame(*warp_, report);
        Raster& r = plan_.shape;  // as fromSourceAffine keeps the warped raster (north-up, square: as is)
        r.crsWkt = detail::toWkt(frame.crs);
        r.crsName = report.gridCrsName;
        bool flipX = false, flipY = false;
        keptGeometry(frame.gt, warp_->width, warp_->height, r, flipX, flipY, report);
        plan_.rowToWorld = warpRowToWorld(*warp_, o_.gt, frame.unit);
        plan_.rowToWorldThreadSafe = false;
    }
    const Raster& shape() const override { return plan_.shape; }
    void checkValid(uint64_t validPixels) const override {
        if (warp_) warp_->checkValid(validPixels);
    }
    void read(size_t col0, size_t row0, size_t w, size_t h, std::vector<float>& values, std::vector<float>& rounding) override {
        if (col0 + w > plan_.shape.width || row0 + h > plan_.shape.height) throw Error("window outside the working raster");
        values.assign(w * h, kNaN);
        rounding.clear();  // a resampled raster keeps float32 values only (as read whole)
        if (warp_) {
            warp_->warp(col0, row0, w, h, values.data());
            o_.band->dropCache();
            return;
        }
        const size_t width = o_.band->width(), height = o_.band->height();
        auto readSource = [&](size_t c0, size_t r0, size_t c1, size_t r1) {
            const size_t sw = c1 - c0 + 1, sh = r1 - r0 + 1;
            source_.assign(sw * sh, kNaN);
            residual_.clear();
            detail::SourceTally uncounted;  // counted once by tally()
            o_.band->read(c0, r0, sw, sh, source_.data(), residual_, 0, sw * sh, uncounted);
            o_.band->dropCache();
            return detail::SourceView{source_.data(), c0, r0, sw, width, height};
        };
        detail::resampleWindow(plan_.map, plan_.shape, step_, col0, row0, w, h, width, height, readSource, values.data(), threads_);
    }
    const detail::SourceTally& tally() const override {
        if (!counted_) stripPass(nullptr, nullptr);
        return tally_;
    }
    std::optional<detail::SourceCheckSums> checkAgainst(const std::string& gridPath) override {
        const GridRegionReader grid(gridPath);
        detail::SourceCheckSums sums;
        stripPass(&grid, &sums);
        return sums;
    }
    void finish(const detail::SourceTally& all, LoadReport& report) const override { o_.band->finish(all, report); }

private:
    // One pass over this rank's share of the source's row strips (every source pixel once over the ranks): the tally,
    // and with `grid` the check of each valid pixel against the cell under its centre, as checkAgainstSource
    // (ingest.cpp) makes it in one process: the pixel's centre mapped to the working raster's pixel, whose cell is
    // read from the file (the region under the strip, painted onto that strip's pixels).
    void stripPass(const GridRegionReader* grid, detail::SourceCheckSums* sums) const {
        const size_t width = o_.band->width(), height = o_.band->height();
        const size_t strip = std::max<size_t>(1, (size_t{1} << 20) / (width * 8 + 1));  // ~1 MB buffers, as read whole
        // A rank takes a run of strips: its rows' footprint is then one band of the working raster, and the file's
        // regions under them about its share of the file (every rank's strips spread over the height would each touch
        // nearly every page of the file, the cells of a band being spread over it in Morton order).
        const uint64_t strips = (height + strip - 1) / strip;
        const uint64_t s0 = ranks::shareBegin(strips, ranks::rank(), ranks::count()), s1 = ranks::shareBegin(strips, ranks::rank() + 1, ranks::count());
        Progress progress(grid ? "checking the source's pixels against their cells" : "counting the source's pixels", s1 - s0,
                          progress_ && ranks::rank() == 0);
        std::vector<float> values, residual, painted;
        std::vector<int64_t> at;  // per strip pixel: its working pixel (row * width + col), or -1 where none
        tally_ = {};
        for (uint64_t s = s0; s < s1; ++s) {
            const size_t r0 = size_t(s) * strip, rows = std::min(strip, height - r0);
            values.assign(width * rows, kNaN);
            residual.clear();
            o_.band->read(0, r0, width, rows, values.data(), residual, 0, values.size(), tally_);
            o_.band->dropCache();
            if (grid) checkStrip(*grid, r0, rows, values, residual, at, painted, *sums);
            progress.advance(1);
        }
        progress.finish();
        counted_ = true;
    }

    // Rows [r0, r0 + rows) of the source (values, residual as read) against the file's cells, on every worker.
    void checkStrip(const GridRegionReader& grid, size_t r0, size_t rows, const std::vector<float>& values, const std::vector<float>& residual,
                    std::vector<int64_t>& at, std::vector<float>& painted, detail::SourceCheckSums& sums) const {
        const Raster& t = plan_.shape;
        const size_t width = o_.band->width(), workers = resolveThreads(threads_);
        at.assign(width * rows, -1);
        struct Box {
            size_t c0 = SIZE_MAX, c1 = 0, w0 = SIZE_MAX, w1 = 0;  // the working pixels the centres reach
        };
        std::vector<Box> boxes(workers);
        parallelFor(rows, 4, plan_.rowToWorldThreadSafe ? threads_ : 1, [&](size_t b, size_t e, unsigned worker) {
            std::vector<double> x(width), y(width);
            std::vector<int> ok(width);
            Box& box = boxes[worker];
            for (size_t j = b; j < e; ++j) {
                plan_.rowToWorld(r0 + j, x, y, ok);
                for (size_t c = 0; c < width; ++c) {
                    if (std::isnan(values[j * width + c])) continue;
                    const int64_t p = detail::workingPixelAt(t, x[c], y[c], ok[c]);
                    if (p < 0) continue;
                    const size_t ic = size_t(p) % t.width, ir = size_t(p) / t.width;
                    at[j * width + c] = p;
                    box.c0 = std::min(box.c0, ic), box.c1 = std::max(box.c1, ic), box.w0 = std::min(box.w0, ir), box.w1 = std::max(box.w1, ir);
                }
            }
        });
        Box all;
        for (const Box& box : boxes)
            all.c0 = std::min(all.c0, box.c0), all.c1 = std::max(all.c1, box.c1), all.w0 = std::min(all.w0, box.w0), all.w1 = std::max(all.w1, box.w1);
        const size_t c0 = all.c0, c1 = all.c1, w0 = all.w0, w1 = all.w1;
        const size_t bw = c0 <= c1 ? c1 - c0 + 1 : 0, bh = w0 <= w1 ? w1 - w0 + 1 : 0;
        painted.assign(bw * bh, kNaN);
        if (bw > 0) {
            // The cells under working pixels [c0, c1] x [w0, w1] (the grid's local frame: origin at the working raster's
            // south-west corner, y north, one finest cell a pixel), painted onto them.
            const double px = t.pixelSizeM;
            const Grid cells = grid.region({double(c0) * px, double(t.height - 1 - w1) * px, double(c1 + 1) * px, double(t.height - w0) * px});
            for (size_t i = 0; i < cells.cellCount(); ++i) {
                const uint64_t key = codeKey(cells.codes[i]);
                const size_t span = size_t{1} << codeLevel(cells.codes[i]), ix0 = mortonX(key), iy0 = mortonY(key);
                for (size_t iy = iy0; iy < iy0 + span; ++iy) {
                    if (iy >= t.height) break;
                    const size_t row = t.height - 1 - iy;
                    if (row < w0 || row > w1) continue;
                    for (size_t ix = std::max(ix0, c0); ix < std::min(ix0 + span, c1 + 1); ++ix) painted[(row - w0) * bw + (ix - c0)] = cells.values[0][i];
                }
            }
        }
        std::vector<detail::SourceCheckSums> parts(workers);
        parallelFor(rows, 4, threads_, [&](size_t b, size_t e, unsigned worker) {
            detail::SourceCheckSums& p = parts[worker];
            for (size_t i = b * width; i < e * width; ++i) {
                if (std::isnan(values[i])) continue;
                const float z = at[i] < 0 ? kNaN : painted[(size_t(at[i]) / t.width - w0) * bw + (size_t(at[i]) % t.width - c0)];
                p.addPixel(double(values[i]) + (residual.empty() ? 0.0 : double(residual[i])), z);
            }
        });
        for (const auto& p : parts) sums.add(p);
    }

    Opened o_;
    Resampling plan_;
    std::unique_ptr<WarpPlan> warp_;  // --t_srs
    unsigned threads_;
    bool progress_;
    int step_ = 1;
    std::vector<float> source_, residual_;
    mutable detail::SourceTally tally_;
    mutable bool counted_ = false;
};

}  // namespace

Raster loadTerrain(const Options& opt, LoadReport& report) { return detail::loadTerrainTraced(opt, report, nullptr); }

Raster detail::loadTerrainTraced(const Options& opt, LoadReport& report, SourceTrace* trace) {
    Opened o = openTerrain(opt, report);
    SourceBand src;
    {
        src.width = o.band->width();
        src.height = o.band->height();
        src.values.assign(src.width * src.height, kNaN);
        const size_t strip = std::max<size_t>(1, (size_t{1} << 20) / (src.width * 8 + 1));  // ~1 MB buffers
        SourceTally tally;
        Progress progress("reading " + opt.input, src.height, opt.progress);
        for (size_t r0 = 0; r0 < src.height; r0 += strip) {
            const size_t rows = std::min(strip, src.height - r0);
            o.band->read(0, r0, src.width, rows, src.values.data() + r0 * src.width, src.residual, r0 * src.width, src.values.size(), tally);
            o.band->dropCache();
            progress.advance(rows);
        }
        progress.finish();
        o.band->finish(tally, report);
    }
    o.band.reset();
    o.ds.reset();  // releases GDAL's cached blocks of the file before the working raster is made
    switch (o.route) {
    case Opened::Route::Warp: return warpToTarget(std::move(src), o.gt, o.srs, o.target, opt, report, trace);
    case Opened::Route::Utm: return projectToUtm(std::move(src), o.gt, o.srs, opt, report, trace);
    case Opened::Route::Affine: break;
    }
    return fromSourceAffine(std::move(src), o.gt, o.pixelM, o.wkt, opt, report, trace);
}

std::unique_ptr<detail::TerrainWindows> detail::openTerrainWindows(const Options& opt, LoadReport& report) {
    Opened o = openTerrain(opt, report);
    const size_t width = o.band->width(), height = o.band->height();
    switch (o.route) {
    case Opened::Route::Warp: {
        return std::make_unique<ResampledWindows>(std::move(o), opt, report);
    }
    case Opened::Route::Utm: {
        Resampling plan = planUtm(o.gt, width, height, o.srs, opt, report, false);
        return std::make_unique<ResampledWindows>(std::move(o), std::move(plan), opt, report);
    }
    case Opened::Route::Affine: break;
    }
    if (!keptAsIs(o.gt, opt)) {
        Resampling plan = planAffine(o.gt, width, height, o.pixelM, o.wkt, opt, report, false);
        return std::make_unique<ResampledWindows>(std::move(o), std::move(plan), opt, report);
    }
    return std::make_unique<KeptWindows>(std::move(o), report);
}

}  // namespace hc::ingest
