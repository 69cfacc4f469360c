// loadTerrain: raster file -> metric, north-up, square-pixel working raster (ingest.h).
#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include <unistd.h>

#include <GeographicLib/TransverseMercator.hpp>
#include <GeographicLib/UTMUPS.hpp>
#include <gdal_alg.h>
#include <gdal_utils.h>

#include "gdal_util.h"
#include "heightcast/grid/error.h"
#include "heightcast/grid/progress.h"
#include "heightcast/ingest/ingest.h"
#include "resample.h"

namespace hc::ingest {

using detail::DatasetPtr;
using detail::SourceBand;

namespace {

constexpr double kSquareTolerance = 1e-3;  // pixels within 0.1 % of square are taken as square
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

std::string fmt(double v, int precision = 6) {
    std::ostringstream s;
    s.precision(precision);
    s << v;
    return s.str();
}

std::string lower(std::string s) {
    for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

// Metres per unit of the band's elevation values, from its unit type; 1 when unknown or metres.
double verticalUnitScale(GDALRasterBand* band, std::string& unitName) {
    unitName = band->GetUnitType() ? band->GetUnitType() : "";
    std::string u = lower(unitName);
    if (u.find("us") != std::string::npos && (u.find("ft") != std::string::npos || u.find("foot") != std::string::npos || u.find("feet") != std::string::npos))
        return 1200.0 / 3937.0;
    if (u == "ft" || u == "foot" || u == "feet" || u.find("international foot") != std::string::npos) return 0.3048;
    return 1.0;
}

// Reads the band (or decodes Terrain-RGB) into floats with every kind of nodata as NaN.
SourceBand readSource(GDALDataset& ds, const Options& opt, LoadReport& report) {
    SourceBand out;
    out.width = static_cast<size_t>(ds.GetRasterXSize());
    out.height = static_cast<size_t>(ds.GetRasterYSize());
    const int bandCount = ds.GetRasterCount();
    if (opt.terrainRgb && bandCount < 3)
        throw Error(opt.input + ": --terrain-rgb needs 3 bands (R, G, B), the raster has " + std::to_string(bandCount));
    if (!opt.terrainRgb && opt.band > bandCount)
        throw Error(opt.input + ": --band " + std::to_string(opt.band) + " is out of range: the raster has " +
                    std::to_string(bandCount) + " band" + (bandCount == 1 ? "" : "s"));
    GDALRasterBand* band = ds.GetRasterBand(opt.terrainRgb ? 1 : opt.band);
    if (opt.terrainRgb)
        for (int b = 1; b <= 3; ++b)
            if (ds.GetRasterBand(b)->GetRasterDataType() != GDT_Byte)
                throw Error(opt.input + ": --terrain-rgb needs 8-bit bands; band " + std::to_string(b) + " is " +
                            GDALGetDataTypeName(ds.GetRasterBand(b)->GetRasterDataType()));

    report.sourceDescription = std::to_string(out.width) + " x " + std::to_string(out.height) + " px, " +
                               GDALGetDataTypeName(band->GetRasterDataType()) + ", " + std::to_string(bandCount) +
                               " band" + (bandCount == 1 ? "" : "s") + ", " + ds.GetDriver()->GetDescription();
    int hasNodata = 0;
    double nodata = band->GetNoDataValue(&hasNodata);  // used only when the band declares one
    int maskFlags = band->GetMaskFlags();
    bool useMask = !(maskFlags & GMF_ALL_VALID) && !(maskFlags & GMF_NODATA) && (maskFlags & (GMF_PER_DATASET | GMF_ALPHA));
    std::string unitName;
    double zUnit = opt.terrainRgb ? 1.0 : verticalUnitScale(band, unitName);
    if (zUnit != 1.0) report.warnings.push_back("elevations are in '" + unitName + "': converted to metres (x" + fmt(zUnit, 10) + ")");
    const double zScale = zUnit * opt.zScale;

    out.values.assign(out.width * out.height, kNaN);
    const GDALDataType sampleType = band->GetRasterDataType();
    const bool exactInFloat = sampleType == GDT_Byte || sampleType == GDT_UInt16 || sampleType == GDT_Int16 || sampleType == GDT_Float32;
    const size_t strip = std::max<size_t>(1, (size_t{1} << 20) / (out.width * 8 + 1));  // ~1 MB buffers
    std::vector<double> buf;
    std::vector<uint8_t> rgb, mask;
    Progress progress("reading " + opt.input, out.height, opt.progress);
    for (size_t r0 = 0; r0 < out.height; r0 += strip) {
        const size_t rows = std::min(strip, out.height - r0);
        const size_t n = rows * out.width;
        auto rasterIO = [&](GDALRasterBand* b, void* dst, GDALDataType type) {
            CPLErrorReset();
            if (b->RasterIO(GF_Read, 0, static_cast<int>(r0), static_cast<int>(out.width), static_cast<int>(rows), dst,
                            static_cast<int>(out.width), static_cast<int>(rows), type, 0, 0, nullptr) != CE_None)
                throw Error(opt.input + ": cannot read rows " + std::to_string(r0) + ".." + std::to_string(r0 + rows - 1) +
                            " (truncated or corrupt file?): " + detail::lastGdalError());
        };
        float* dst = out.values.data() + r0 * out.width;
        if (opt.terrainRgb) {
            rgb.resize(3 * n);
            for (int b = 0; b < 3; ++b) rasterIO(ds.GetRasterBand(b + 1), rgb.data() + static_cast<size_t>(b) * n, GDT_Byte);
            for (size_t i = 0; i < n; ++i) {
                double h = -10000.0 + 0.1 * (rgb[i] * 65536.0 + rgb[n + i] * 256.0 + rgb[2 * n + i]);
                dst[i] = static_cast<float>(h * zScale);
            }
        } else if (exactInFloat) {
            // Read straight into place: float32 holds every value of these types exactly.
            rasterIO(band, dst, GDT_Float32);
            for (size_t i = 0; i < n; ++i) {
                double v = dst[i];
                bool isNodata = std::isnan(v) || (hasNodata && static_cast<float>(v) == static_cast<float>(nodata)) ||
                                (opt.nodata && static_cast<float>(v) == static_cast<float>(*opt.nodata)) || std::isinf(v);
                dst[i] = isNodata ? kNaN : static_cast<float>(v * zScale);
                if (!isNodata && !std::isfinite(dst[i]))
                    throw Error(opt.input + ": elevation " + fmt(v) + " x " + fmt(zScale) + " is beyond the float32 range");
            }
        } else {
            buf.resize(n);
            rasterIO(band, buf.data(), GDT_Float64);
            for (size_t i = 0; i < n; ++i) {
                double v = buf[i];
                bool isNodata = std::isnan(v) || (hasNodata && (v == nodata || static_cast<float>(v) == static_cast<float>(nodata))) ||
                                (opt.nodata && v == *opt.nodata) || std::isinf(v);
                dst[i] = isNodata ? kNaN : static_cast<float>(v * zScale);
                if (!isNodata && !std::isfinite(dst[i]))
                    throw Error(opt.input + ": elevation " + fmt(v) + " x " + fmt(zScale) + " is beyond the float32 range");
            }
        }
        if (useMask) {
            mask.resize(n);
            rasterIO(band->GetMaskBand(), mask.data(), GDT_Byte);
            for (size_t i = 0; i < n; ++i)
                if (mask[i] == 0) dst[i] = kNaN;
        }
        // Drop GDAL's cached blocks of the rows just read: otherwise its block cache holds a second
        // copy of the whole file at the peak of the read.
        for (int b = 1; b <= bandCount; ++b) ds.GetRasterBand(b)->FlushCache(false);
        if (useMask) band->GetMaskBand()->FlushCache(false);
        progress.advance(rows);
    }
    progress.finish();
    return out;
}

// Geotransform of the source in metres (or in degrees for geographic sources).
struct GeoTransform {
    double g[6] = {0, 1, 0, 0, 0, -1};
    bool rotated() const { return g[2] != 0 || g[4] != 0; }
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

Raster fromSourceAffine(SourceBand&& src, const GeoTransform& gt, double pixelM, const std::string& wkt,
                        const Options& opt, LoadReport& report) {
    Raster r;
    r.crsWkt = wkt;
    const double* g = gt.g;
    bool square = std::abs(std::abs(g[1]) - std::abs(g[5])) <= kSquareTolerance * std::max(std::abs(g[1]), std::abs(g[5]));
    bool sameSize = !opt.minCellM || std::abs(*opt.minCellM - std::abs(g[1])) <= 1e-9 * std::abs(g[1]);
    if (!gt.rotated() && square && sameSize) {
        // Kept as is; flip rows (south-up) or columns (east-to-west) so row 0 is north, column 0 west.
        r.width = src.width;
        r.height = src.height;
        r.pixelSizeM = std::abs(g[1]);
        bool flipX = g[1] < 0, flipY = g[5] > 0;
        r.westWorld = flipX ? g[0] + g[1] * static_cast<double>(src.width) : g[0];
        r.northWorld = flipY ? g[3] + g[5] * static_cast<double>(src.height) : g[3];
        if (std::abs(g[1]) != std::abs(g[5])) {
            double shift = std::abs(std::abs(g[5]) - std::abs(g[1])) * static_cast<double>(src.height);
            report.warnings.push_back("pixels of " + fmt(std::abs(g[1])) + " x " + fmt(std::abs(g[5])) +
                                      " m taken as square " + fmt(r.pixelSizeM) + " m (the south edge moves by " + fmt(shift, 3) + " m)");
        }
        if (flipX || flipY) {
            report.method += std::string(report.method.empty() ? "" : "; ") + (flipY ? "south-up rows flipped north-up" : "") +
                             (flipX && flipY ? ", " : "") + (flipX ? "east-to-west columns flipped" : "");
            r.values.resize(src.values.size());
            for (size_t row = 0; row < src.height; ++row)
                for (size_t col = 0; col < src.width; ++col)
                    r.values[row * src.width + col] = src.at(flipX ? src.width - 1 - col : col, flipY ? src.height - 1 - row : row);
        } else {
                r.values = std::move(src.values);
        }
        if (report.method.empty()) report.method = "kept as is";
        return r;
    }
    // Resample: rotated, non-square, or a finest cell other than the pixel size.
    double inv[6];
    if (!gt.invert(inv)) throw Error(opt.input + ": geotransform cannot be inverted (degenerate pixel size)");
    double xs[4], ys[4];
    double cw = static_cast<double>(src.width), ch = static_cast<double>(src.height);
    const double corners[4][2] = {{0, 0}, {cw, 0}, {0, ch}, {cw, ch}};
    for (int k = 0; k < 4; ++k) {
        xs[k] = g[0] + corners[k][0] * g[1] + corners[k][1] * g[2];
        ys[k] = g[3] + corners[k][0] * g[4] + corners[k][1] * g[5];
    }
    double xmin = *std::min_element(xs, xs + 4), xmax = *std::max_element(xs, xs + 4);
    double ymin = *std::min_element(ys, ys + 4), ymax = *std::max_element(ys, ys + 4);
    r.pixelSizeM = opt.minCellM ? *opt.minCellM : pixelM;
    checkWorkingSize(std::ceil((xmax - xmin) / r.pixelSizeM), std::ceil((ymax - ymin) / r.pixelSizeM), r.pixelSizeM, opt);
    r.width = static_cast<size_t>(std::ceil((xmax - xmin) / r.pixelSizeM - 1e-9));
    r.height = static_cast<size_t>(std::ceil((ymax - ymin) / r.pixelSizeM - 1e-9));
    r.westWorld = xmin;
    r.northWorld = ymax;
    std::string why = gt.rotated() ? "rotated geotransform" : (!square ? "non-square pixels" : "--min-cell");
    report.method += std::string(report.method.empty() ? "" : "; ") + "resampled north-up onto " + fmt(r.pixelSizeM) +
                     " m squares (" + why + ", bilinear)";
    detail::SourceBand source = std::move(src);
    resample(source, [&](double x, double y, double& col, double& row) {
        col = inv[0] + x * inv[1] + y * inv[2];
        row = inv[3] + x * inv[4] + y * inv[5];
        return true;
    }, r, 16, 1e-9, opt.threads);  // affine: the lattice interpolation is exact (the check confirms it)
    return r;
}

// Geographic -> UTM zone of the raster centre, on the source's own ellipsoid (GeographicLib's
// Krueger series: accurate to 5 nm within 3900 km of the central meridian).
Raster projectToUtm(SourceBand&& src, const GeoTransform& gt, const OGRSpatialReference& geo, const Options& opt,
                    LoadReport& report) {
    const double* g = gt.g;
    const double degPerUnit = geo.GetAngularUnits() * 180.0 / M_PI;
    const double pm = geo.GetPrimeMeridian();  // degrees east of Greenwich
    auto lonLat = [&](double col, double row, double& lon, double& lat) {
        lon = (g[0] + col * g[1] + row * g[2]) * degPerUnit + pm;
        lat = (g[3] + col * g[4] + row * g[5]) * degPerUnit;
    };
    // The outline, sampled along every edge.
    double lonMin = HUGE_VAL, lonMax = -HUGE_VAL, latMin = HUGE_VAL, latMax = -HUGE_VAL;
    const double cw = static_cast<double>(src.width), ch = static_cast<double>(src.height);
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
    double lonC, latC;
    lonLat(cw / 2, ch / 2, lonC, latC);
    auto hint = std::string("; choose a projection with --t_srs (for example a Lambert azimuthal equal-area CRS centred on the data)");
    if (latMin < -80.0 || latMax > 84.0 || lonMin < -180.0 || lonMax > 180.0)
        throw Error(opt.input + ": spans longitude " + fmt(lonMin) + ".." + fmt(lonMax) + " and latitude " + fmt(latMin) + ".." +
                    fmt(latMax) + " degrees: no UTM zone holds it (UTM covers 80S..84N)" + hint);
    int zone = GeographicLib::UTMUPS::StandardZone(latC, lonC);
    const double lon0 = 6.0 * zone - 183.0;
    const double maxOff = std::max(std::abs(lonMin - lon0), std::abs(lonMax - lon0));
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

    Raster r;
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
    checkWorkingSize(std::ceil((xmax - xmin) / r.pixelSizeM), std::ceil((ymax - ymin) / r.pixelSizeM), r.pixelSizeM, opt);
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
    report.method = "projected to UTM zone " + std::to_string(zone) + (north ? "N" : "S") + " (GeographicLib, " +
                    "pixels " + fmt(dx, 4) + " x " + fmt(dy, 4) + " m) and resampled onto " + fmt(r.pixelSizeM, 4) +
                    " m squares (bilinear)";

    double inv[6];
    if (!gt.invert(inv)) throw Error(opt.input + ": geotransform cannot be inverted (degenerate pixel size)");
    // 1e-5 pixel: at slopes of 100 m per pixel (alpine SRTM) that is 1 mm of elevation.
    int lattice = resample(src, [&](double x, double y, double& col, double& row) {
        double lat, lon;
        tm.Reverse(lon0, x - fe, y - fn, lat, lon);
        double gx = (lon - pm) / degPerUnit, gy = lat / degPerUnit;
        col = inv[0] + gx * inv[1] + gy * inv[2];
        row = inv[3] + gx * inv[4] + gy * inv[5];
        return std::isfinite(col) && std::isfinite(row);
    }, r, 16, 1e-5, opt.threads);
    report.method += ", map exact every " + std::to_string(lattice) + " px";
    return r;
}

// Wraps a source band in a GDAL MEM dataset (for GDALWarp).
DatasetPtr memDataset(const SourceBand& src, const GeoTransform& gt, const OGRSpatialReference* srs) {
    GDALDriver* mem = GetGDALDriverManager()->GetDriverByName("MEM");
    DatasetPtr ds(mem->Create("", static_cast<int>(src.width), static_cast<int>(src.height), 1, GDT_Float32, nullptr));
    if (!ds) throw Error("cannot create an in-memory raster: " + detail::lastGdalError());
    ds->SetGeoTransform(const_cast<double*>(gt.g));
    if (srs) ds->SetSpatialRef(srs);
    GDALRasterBand* b = ds->GetRasterBand(1);
    b->SetNoDataValue(std::numeric_limits<double>::quiet_NaN());
    if (b->RasterIO(GF_Write, 0, 0, static_cast<int>(src.width), static_cast<int>(src.height),
                    const_cast<float*>(src.values.data()), static_cast<int>(src.width), static_cast<int>(src.height),
                    GDT_Float32, 0, 0, nullptr) != CE_None)
        throw Error("cannot fill an in-memory raster: " + detail::lastGdalError());
    return ds;
}

}  // namespace

namespace detail {

// GDALWarp of `src` into a MEM dataset with the given arguments (GDAL's own option syntax).
DatasetPtr warp(GDALDataset& src, const std::vector<std::string>& args, const std::string& what) {
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    GDALWarpAppOptions* options = GDALWarpAppOptionsNew(argv.data(), nullptr);
    if (!options) throw Error(what + ": invalid warp options: " + lastGdalError());
    GDALDatasetH in = GDALDataset::ToHandle(&src);
    int usageError = 0;
    CPLErrorReset();
    GDALDatasetH out = GDALWarp("", nullptr, 1, &in, options, &usageError);
    GDALWarpAppOptionsFree(options);
    if (!out || usageError) throw Error(what + ": " + lastGdalError());
    return DatasetPtr(GDALDataset::FromHandle(out));
}

// Reads band 1 of a (warped, float) dataset into a SourceBand (NaN nodata kept).
SourceBand readFloatBand(GDALDataset& ds, const std::string& what) {
    SourceBand s;
    s.width = static_cast<size_t>(ds.GetRasterXSize());
    s.height = static_cast<size_t>(ds.GetRasterYSize());
    s.values.resize(s.width * s.height);
    if (ds.GetRasterBand(1)->RasterIO(GF_Read, 0, 0, static_cast<int>(s.width), static_cast<int>(s.height), s.values.data(),
                                      static_cast<int>(s.width), static_cast<int>(s.height), GDT_Float32, 0, 0, nullptr) != CE_None)
        throw Error(what + ": cannot read the warped raster: " + lastGdalError());
    int has = 0;
    double nd = ds.GetRasterBand(1)->GetNoDataValue(&has);
    if (has && !std::isnan(nd))
        for (float& v : s.values)
            if (v == static_cast<float>(nd)) v = kNaN;
    return s;
}

}  // namespace detail

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
    if ((o.water == WaterSource::Depth || o.water == WaterSource::Surface) && o.waterPath.empty()) bad("no water raster given");
    if (o.water == WaterSource::Level && !std::isfinite(o.waterLevelM)) bad("--water-level must be a finite elevation in metres");
}

Raster loadTerrain(const Options& opt, LoadReport& report) {
    validateOptions(opt);
    DatasetPtr ds = detail::openRaster(opt.input, "terrain raster");
    report.sourceWidth = static_cast<size_t>(ds->GetRasterXSize());
    report.sourceHeight = static_cast<size_t>(ds->GetRasterYSize());

    OGRSpatialReference srs;
    srs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    bool hasSrs = false;
    if (!opt.sourceSrs.empty()) {
        if (srs.SetFromUserInput(opt.sourceSrs.c_str()) != OGRERR_NONE)
            throw Error("--s_srs " + opt.sourceSrs + ": not a CRS that GDAL/PROJ knows");
        hasSrs = true;
    } else if (const OGRSpatialReference* own = ds->GetSpatialRef(); own && !own->IsEmpty()) {
        srs = *own;
        srs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
        hasSrs = true;
    }
    report.sourceCrsName = hasSrs ? detail::crsName(&srs) : "";

    GeoTransform gt;
    bool hasGt = ds->GetGeoTransform(gt.g) == CE_None;
    if (hasGt && (gt.g[1] == 0 || gt.g[5] == 0) && !gt.rotated())
        throw Error(opt.input + ": geotransform has a zero pixel size");
    SourceBand src = readSource(*ds, opt, report);
    ds.reset();  // releases GDAL's cached blocks of the file before the working raster is made
    if (!hasGt) {
        // No georeferencing: pixel (c, r) -> (c, -r) metres; the file itself can't say more.
        gt = GeoTransform{};
        gt.g[3] = static_cast<double>(src.height);
        report.warnings.push_back("no georeferencing: pixels taken as 1 m squares in a local frame (assign one with gdal_translate -a_ullr / -a_srs)");
    }

    if (!opt.targetSrs.empty()) {
        OGRSpatialReference target;
        if (target.SetFromUserInput(opt.targetSrs.c_str()) != OGRERR_NONE)
            throw Error("--t_srs " + opt.targetSrs + ": not a CRS that GDAL/PROJ knows");
        if (!target.IsProjected()) throw Error("--t_srs " + opt.targetSrs + ": not a projected CRS (the grid needs metres)");
        if (!hasSrs) throw Error(opt.input + ": has no CRS to project from; name it with --s_srs");
        DatasetPtr mem = memDataset(src, gt, &srs);
        src = {};
        std::vector<std::string> args{"-t_srs", opt.targetSrs, "-r", "bilinear", "-of", "MEM", "-ot", "Float32",
                                      "-srcnodata", "nan", "-dstnodata", "nan", "-wo", "NUM_THREADS=ALL_CPUS"};
        if (opt.minCellM) {
            args.insert(args.end(), {"-tr", fmt(*opt.minCellM, 17), fmt(*opt.minCellM, 17)});
        } else {
            // GDAL's suggested output, made square with the smaller side.
            // The option list is ours to free (issue 11: LeakSanitizer found it leaked, Ingest.TargetSrsWarpsWithGdal).
            char** trOptions = CSLSetNameValue(nullptr, "DST_SRS", opt.targetSrs.c_str());
            void* tr = GDALCreateGenImgProjTransformer2(GDALDataset::ToHandle(mem.get()), nullptr, trOptions);
            CSLDestroy(trOptions);
            if (!tr) throw Error("--t_srs " + opt.targetSrs + ": cannot transform from " + report.sourceCrsName + ": " + detail::lastGdalError());
            double sg[6];
            int pw = 0, ph = 0;
            CPLErr e = GDALSuggestedWarpOutput(GDALDataset::ToHandle(mem.get()), GDALGenImgProjTransform, tr, sg, &pw, &ph);
            GDALDestroyGenImgProjTransformer(tr);
            if (e != CE_None) throw Error("--t_srs " + opt.targetSrs + ": cannot project " + opt.input + ": " + detail::lastGdalError());
            double c = std::min(std::abs(sg[1]), std::abs(sg[5]));
            args.insert(args.end(), {"-tr", fmt(c, 17), fmt(c, 17)});
        }
        DatasetPtr warped = detail::warp(*mem, args, opt.input + ": projecting to " + opt.targetSrs);
        mem.reset();
        OGRSpatialReference out = *warped->GetSpatialRef();
        GeoTransform wgt;
        warped->GetGeoTransform(wgt.g);
        SourceBand ws = detail::readFloatBand(*warped, opt.input);
        warped.reset();
        if (std::none_of(ws.values.begin(), ws.values.end(), [](float v) { return !std::isnan(v); }))
            throw Error(opt.input + ": projected to " + opt.targetSrs + " on " + std::to_string(ws.width) + " x " + std::to_string(ws.height) +
                        " pixels of " + fmt(std::abs(wgt.g[1]), 6) + " (CRS units), no pixel centre falls inside the data: " +
                        "the footprint is too thin for that resolution; give a finer one with --min-cell");
        double unit = out.GetLinearUnits();
        for (double& v : wgt.g) v *= unit;
        if (unit != 1.0) out.SetLinearUnitsAndUpdateParameters(SRS_UL_METER, 1.0);
        report.gridCrsName = detail::crsName(&out);
        report.method = "warped to " + report.gridCrsName + " by GDAL (bilinear)";
        Options keep = opt;
        keep.minCellM.reset();  // -tr already applied it
        return fromSourceAffine(std::move(ws), wgt, std::abs(wgt.g[1]), detail::toWkt(out), keep, report);
    }

    if (!hasSrs) {
        const double* g = gt.g;
        if (hasGt && std::abs(g[1]) < 0.01 && std::abs(g[0]) <= 360 && std::abs(g[3]) <= 90)
            report.warnings.push_back("no CRS, and the coordinates look like degrees: taken as metres all the same; "
                                      "if they are degrees, say so with --s_srs EPSG:4326");
        else if (hasGt)
            report.warnings.push_back("no CRS: coordinates taken as metres in a local frame (name the CRS with --s_srs)");
        report.gridCrsName = "";
        return fromSourceAffine(std::move(src), gt, std::min(std::abs(gt.g[1]), std::abs(gt.g[5])), "", opt, report);
    }
    if (srs.IsGeographic()) {
        if (gt.rotated()) throw Error(opt.input + ": rotated geotransform on a geographic CRS is not supported; warp it with gdalwarp first");
        return projectToUtm(std::move(src), gt, srs, opt, report);
    }
    if (!srs.IsProjected())
        throw Error(opt.input + ": CRS '" + report.sourceCrsName + "' is neither projected nor geographic (geocentric or vertical?)");
    const char* unitName = nullptr;
    double unit = srs.GetLinearUnits(&unitName);
    if (unit != 1.0) {
        for (double& v : gt.g) v *= unit;
        srs.SetLinearUnitsAndUpdateParameters(SRS_UL_METER, 1.0);
        report.warnings.push_back(std::string("horizontal units are ") + (unitName ? unitName : "?") +
                                  ": converted to metres (x" + fmt(unit, 10) + ")");
    }
    report.gridCrsName = detail::crsName(&srs);
    double pixel = std::min(std::abs(gt.g[1]), std::abs(gt.g[5]));
    if (gt.rotated()) pixel = std::min(std::hypot(gt.g[1], gt.g[4]), std::hypot(gt.g[2], gt.g[5]));
    return fromSourceAffine(std::move(src), gt, pixel, detail::toWkt(srs), opt, report);
}

}  // namespace hc::ingest
