// ingest/src/terrain_reproject.cpp: the terrain's reprojection onto a metric working raster: a geographic source
// projected to its UTM zone (GeographicLib: planUtm, projectToUtm), and --t_srs warped by GDAL's warper with the exact
// transformer (planWarp, warpToTarget). Which route a source takes is load_terrain.cpp's decision; the window-by-window
// reading of these routes is terrain_windows.cpp's.
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>

#include <GeographicLib/Math.hpp>
#include <GeographicLib/TransverseMercator.hpp>
#include <GeographicLib/UTMUPS.hpp>
#include <gdal_alg.h>
#include <gdalwarper.h>

#include "gdal_util.h"
#include "heightcast/core/error.h"
#include "heightcast/core/progress.h"
#include "load_terrain_internal.h"
#include "resample.h"
#include "warp_seam.h"

namespace hc::ingest::detail {

// Geographic -> UTM zone of the raster centre, on the source's own ellipsoid (GeographicLib's
// Krueger series: accurate to 5 nm within 3900 km of the central meridian).
// Longitudes may run 0..360 or anywhere past 180: every longitude below is taken on the circle,
// relative to the raster's centre, so 234..238 E is the same as 126..122 W, and a raster across the
// antimeridian stays whole (its UTM zone sits across 180).
Resampling planUtm(const GeoTransform& gt, size_t width, size_t height, const OGRSpatialReference& geo,
                   const Options& opt, LoadReport& report, bool whole) {
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
    auto hint = std::string(
        "; choose a projection with --t_srs (for example a Lambert azimuthal equal-area CRS centred on the data)");
    if (latMin < -80.0 || latMax > 84.0 || lonMax - lonMin >= 180.0)
        throw Error(opt.input + ": spans longitude " + fmt(lonMin) + ".." + fmt(lonMax) + " and latitude " +
                    fmt(latMin) + ".." + fmt(latMax) +
                    " degrees: no UTM zone holds it (UTM covers 80S..84N, and a zone at most a few degrees either side "
                    "of its meridian)" +
                    hint);
    int zone = GeographicLib::UTMUPS::StandardZone(latC, Math::AngNormalize(lonC));
    const double lon0 = 6.0 * zone - 183.0;
    double maxOff = 0;
    for (auto [lon, lat] : outline) maxOff = std::max(maxOff, std::abs(Math::AngDiff(lon0, lon)));
    if (maxOff > 12.0)
        throw Error(opt.input + ": spans longitude " + fmt(lonMin) + ".." + fmt(lonMax) + " degrees, up to " +
                    fmt(maxOff, 3) + " degrees from the central meridian of UTM zone " + std::to_string(zone) +
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
    if (whole)
        checkWorkingSize(std::ceil((xmax - xmin) / r.pixelSizeM), std::ceil((ymax - ymin) / r.pixelSizeM), r.pixelSizeM,
                         opt);
    r.width = static_cast<size_t>(std::ceil((xmax - xmin) / r.pixelSizeM - 1e-9));
    r.height = static_cast<size_t>(std::ceil((ymax - ymin) / r.pixelSizeM - 1e-9));
    r.westWorld = xmin;
    r.northWorld = ymax;

    OGRSpatialReference utm;
    utm.CopyGeogCSFrom(&geo);
    utm.SetUTM(zone, north);
    std::string projName = std::string(geo.GetName() ? geo.GetName() : "unnamed") + " / UTM zone " +
                           std::to_string(zone) + (north ? "N" : "S");
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
    p.map = [tm, lon0, fe, fn, lonC, pm, degPerUnit, i0 = inv[0], i1 = inv[1], i2 = inv[2], i3 = inv[3], i4 = inv[4],
             i5 = inv[5]](double x, double y, double& col, double& row) {
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
        p.methodTail = "; longitudes " + fmt(lonMin) + ".." + fmt(lonMax) + " read as " +
                       fmt(Math::AngNormalize(lonMin)) + ".." + fmt(Math::AngNormalize(lonMin) + (lonMax - lonMin));
    {
        // Outlives this function: everything by value. The projection of every source pixel centre was most of
        // the check's time (geographic SRTM ingest 2.8-3.2x slower, docs/benchmarks.md): along a row the map is
        // smooth, so it is projected exactly at every 8th column and interpolated by the parabola through three
        // such nodes in between, checked against an exact projection in each 16-column span: kept where the
        // check is within 1e-6 m (the residual, cubic between the nodes, peaks at most 1.2x the check point's),
        // else that span is projected exactly, column by column.
        p.rowToWorld = [gt, degPerUnit, pm, tm, lon0, fe, fn](size_t row, std::vector<double>& x,
                                                              std::vector<double>& y, std::vector<int>& ok) {
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
                    const double s =
                        (static_cast<double>(c - c0) - double(kHalf)) / double(kHalf);  // -1, 0, 1 at the nodes
                    return n[1] + 0.5 * s * (n[2] - n[0]) + 0.5 * s * s * (n[2] - 2 * n[1] + n[0]);
                };
                good = good && exact(c0 + 5, qx, qy) && std::abs(para(nx, c0 + 5) - qx) <= kMaxErrM &&
                       std::abs(para(ny, c0 + 5) - qy) <= kMaxErrM;
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

// The output lattice of --t_srs for a source of width x height pixels on gtIn (no pixel read: `fill` gives them when a
// window is warped), the pieces, and the report's method note.
WarpPlan planWarp(const GeoTransform& gtIn, size_t width, size_t height, const OGRSpatialReference& srs,
                  const OGRSpatialReference& target, const Options& opt, LoadReport& report,
                  const SourceDataset::Fill& fill) {
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
        pieces.assign(1, Piece{0, firstEast, gt});  // not = {{...}}: GCC 12 with ASan detect_stack_use_after_return
                                                    // crashed copying that initializer list
        if (firstEast < end) {
            GeoTransform east = gt;
            east.g[0] = gt.g[0] + static_cast<double>(firstEast) * dx - 360.0;
            pieces.push_back({firstEast, end, east});
            note = "; split at 180 degrees (east part shifted by -360)";
        }
        // Seams: at 180 degrees between the pieces, and around a grid that closes the globe (its last column before its
        // first).
        if (firstEast < end && firstEast > 0)
            seams.push_back({firstEast - 1, firstEast, gt.g[0] + (double(firstEast) - 0.5) * dx});
        if (end <= width && std::abs(double(end) * dx - 360.0) < 1e-6 * 360.0)
            seams.push_back({end - 1, 0, gt.g[0] + (double(end) - 0.5) * dx});
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
    plan.ct.reset(OGRCreateCoordinateTransformation(&from, &to),
                  [](OGRCoordinateTransformation* t) { OGRCoordinateTransformation::DestroyCT(t); });
    if (!plan.ct)
        throw Error("--t_srs " + targetText + ": cannot transform from " + report.sourceCrsName + ": " +
                    detail::lastGdalError());
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
                    const double c = std::min(double(i) + half, double(width)),
                                 r = std::min(double(j) + half, double(height));
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
            throw Error(opt.input + ": no part of it has a position in " + targetText +
                        " (PROJ: " + detail::lastGdalError() + ")");
    }
    double suggested = HUGE_VAL;
    for (const Piece& pc : pieces) {
        plan.sources.push_back(std::make_unique<SourceDataset>(pc.c0, pc.c1 - pc.c0, height, pc.gt, &srs, fill));
        // GDAL's suggested output, made square with the smaller side (the finest over the pieces).
        char** dst = CSLSetNameValue(nullptr, "DST_SRS", targetText.c_str());
        void* tr = GDALCreateGenImgProjTransformer2(GDALDataset::ToHandle(plan.sources.back().get()), nullptr, dst);
        CSLDestroy(dst);
        if (!tr)
            throw Error("--t_srs " + targetText + ": cannot transform from " + report.sourceCrsName + ": " +
                        detail::lastGdalError());
        double sg[6];
        int pw = 0, ph = 0;
        CPLErr e = GDALSuggestedWarpOutput(GDALDataset::ToHandle(plan.sources.back().get()), GDALGenImgProjTransform,
                                           tr, sg, &pw, &ph);
        GDALDestroyGenImgProjTransformer(tr);
        if (e != CE_None)
            throw Error("--t_srs " + targetText + ": cannot project " + opt.input + ": " + detail::lastGdalError());
        suggested = std::min({suggested, std::abs(sg[1]), std::abs(sg[5])});
    }
    plan.cell = opt.minCellM ? *opt.minCellM / target.GetLinearUnits() : suggested;
    plan.scale =
        std::min(1.0, suggested / plan.cell);  // coarser than the source: the kernel widens (GDAL's downsampling)
    // Half a pixel more on every side: source pixel centres on the extent's edge (a pole, the
    // antimeridian) then fall inside the output rather than on its closing edge.
    const double cell = plan.cell;
    ext[0] -= cell / 2, ext[1] -= cell / 2, ext[2] += cell / 2, ext[3] += cell / 2;
    // gdalwarp's size for -te and -tr.
    plan.width = size_t((ext[2] - ext[0] + cell / 2) / cell);
    plan.height = size_t((ext[3] - ext[1] + cell / 2) / cell);
    if (plan.width == 0 || plan.height == 0)
        throw Error(opt.input + ": projected to " + targetText + ": an empty raster");
    checkWorkingSize(double(plan.width), double(plan.height), cell * target.GetLinearUnits(), opt);
    // Across the seams, pixels as fine as the source or finer (a coarser output widens GDAL's kernel: not done here).
    if (!seams.empty() && plan.scale == 1.0)
        plan.seams = std::make_unique<detail::WarpSeams>(seams, moved.g, height, srs, target, plan.ct, plan.ext,
                                                         plan.cell, plan.height, fill);
    return plan;
}

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
std::function<void(size_t, std::vector<double>&, std::vector<double>&, std::vector<int>&)> warpRowToWorld(
    const WarpPlan& plan, const GeoTransform& gtIn, double unit) {
    return [ct = plan.ct, gt = gtIn, unit](size_t row, std::vector<double>& x, std::vector<double>& y,
                                           std::vector<int>& ok) {
        for (size_t c = 0; c < x.size(); ++c)
            gt.apply(static_cast<double>(c) + 0.5, static_cast<double>(row) + 0.5, x[c], y[c]);
        CPLErrorReset();
        ct->Transform(static_cast<int>(x.size()), x.data(), y.data(), nullptr, ok.data());
        for (size_t c = 0; c < x.size(); ++c) {
            ok[c] = ok[c] && std::isfinite(x[c]) && std::isfinite(y[c]);
            x[c] *= unit;
            y[c] *= unit;
        }
    };
}

Raster warpToTarget(SourceBand&& src, const GeoTransform& gtIn, const OGRSpatialReference& srs,
                    const OGRSpatialReference& target, const Options& opt, LoadReport& report,
                    detail::SourceTrace* trace) {
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
    plan.checkValid(
        uint64_t(std::count_if(ws.values.begin(), ws.values.end(), [](float v) { return !std::isnan(v); })));
    const WarpedFrame frame = warpedFrame(plan, report);
    Options keep = opt;
    keep.minCellM.reset();  // -tr already applied it
    Raster r = fromSourceAffine(std::move(ws), frame.gt, std::abs(frame.gt.g[1]), detail::toWkt(frame.crs), keep,
                                report, nullptr);
    if (trace) {
        trace->band = std::move(src);
        trace->rowToWorldThreadSafe = false;  // PROJ's transformations
        trace->rowToWorld = warpRowToWorld(plan, gtIn, frame.unit);
    }
    return r;
}

}  // namespace hc::ingest::detail
