// loadWater: a water depth or water surface raster warped onto the terrain, or a bathtub level.
#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <limits>

#include <fmt/format.h>

#include "gdal_util.h"
#include "heightcast/core/error.h"
#include "heightcast/core/progress.h"
#include "heightcast/ingest/ingest.h"
#include "resample.h"

namespace hc::ingest {
namespace detail {
DatasetPtr warp(GDALDataset& src, const std::vector<std::string>& args, const std::string& what);
SourceBand readFloatBand(GDALDataset& ds, const std::string& what);
}  // namespace detail

namespace {

// Bathtub: depth = level - z in the pixels below `level` that water can reach from the domain
// boundary (the raster edge and the edge of every nodata hole: water enters from outside the survey)
// through 4-connected pixels below the level. Closed depressions stay dry, as they would in a flood.
Raster bathtub(const Raster& t, double level) {
    Raster d = t;
    d.values.assign(t.values.size(), 0.0f);
    const size_t w = t.width, h = t.height;
    std::vector<uint8_t> seen(w * h, 0);
    std::deque<size_t> queue;
    auto below = [&](size_t i) { return !std::isnan(t.values[i]) && t.values[i] < level; };
    auto isHole = [&](long c, long r) {
        return c < 0 || r < 0 || c >= static_cast<long>(w) || r >= static_cast<long>(h) ||
               std::isnan(t.values[static_cast<size_t>(r) * w + static_cast<size_t>(c)]);
    };
    for (size_t r = 0; r < h; ++r)
        for (size_t c = 0; c < w; ++c) {
            size_t i = r * w + c;
            auto lc = static_cast<long>(c), lr = static_cast<long>(r);
            bool boundary = isHole(lc - 1, lr) || isHole(lc + 1, lr) || isHole(lc, lr - 1) || isHole(lc, lr + 1);
            if (boundary && below(i)) {
                seen[i] = 1;
                queue.push_back(i);
            }
        }
    while (!queue.empty()) {
        size_t i = queue.front();
        queue.pop_front();
        d.values[i] = static_cast<float>(level - t.values[i]);
        size_t c = i % w, r = i / w;
        size_t next[4] = {c > 0 ? i - 1 : i, c + 1 < w ? i + 1 : i, r > 0 ? i - w : i, r + 1 < h ? i + w : i};
        for (size_t n : next)
            if (!seen[n] && below(n)) {
                seen[n] = 1;
                queue.push_back(n);
            }
    }
    for (size_t i = 0; i < t.values.size(); ++i)
        if (std::isnan(t.values[i])) d.values[i] = std::numeric_limits<float>::quiet_NaN();
    return d;
}

// opt.waterPath's raster (open as `ds`) warped onto exactly the terrain's working raster, as depth [m].
Raster warpedWater(const Options& opt, GDALDataset& ds, const Raster& terrain, LoadReport& report) {
    const OGRSpatialReference* srs = ds.GetSpatialRef();
    bool waterHasCrs = srs && !srs->IsEmpty();
    if (waterHasCrs != !terrain.crsWkt.empty())
        report.warnings.push_back(opt.waterPath + ": " + (waterHasCrs ? "the terrain has no CRS" : "has no CRS") +
                                  "; both taken to be in the same frame");
    // Warp onto exactly the terrain's working raster: same CRS, extent and pixel size.
    const double west = terrain.westWorld, north = terrain.northWorld;
    const double east = west + static_cast<double>(terrain.width) * terrain.pixelSizeM, south = terrain.southWorld();
    auto num = [](double v) { return fmt::format("{:.17g}", v); };
    std::vector<std::string> args{"-of", "MEM", "-ot", "Float32", "-r", "bilinear", "-et", "0", "-dstnodata", "nan",
                                  "-te", num(west), num(south), num(east), num(north),
                                  "-ts", std::to_string(terrain.width), std::to_string(terrain.height)};
    if (waterHasCrs && !terrain.crsWkt.empty()) args.insert(args.end(), {"-t_srs", terrain.crsWkt});
    detail::DatasetPtr warped = detail::warp(ds, args, opt.waterPath + ": resampling onto the terrain");
    detail::SourceBand band = detail::readFloatBand(*warped, opt.waterPath);
    Raster d = terrain;
    size_t negative = 0;
    for (size_t i = 0; i < d.values.size(); ++i) {
        float z = terrain.values[i];
        float v = band.values[i];
        if (std::isnan(z)) {
            d.values[i] = std::numeric_limits<float>::quiet_NaN();
            continue;
        }
        if (std::isnan(v)) {  // no water data here: dry
            d.values[i] = 0;
            continue;
        }
        float depth = opt.water == WaterSource::Depth ? v : v - z;
        if (opt.water == WaterSource::Depth && depth < 0) ++negative;
        d.values[i] = depth > 0 ? depth : 0.0f;
    }
    if (negative > 0)
        report.warnings.push_back(opt.waterPath + ": " + std::to_string(negative) + " pixels of negative depth taken as dry");
    return d;
}

// Steps of one series must be one simulation's output: the same raster size, georeferencing and CRS as the first.
void checkAgreesWithFirst(GDALDataset& ds, const std::string& path, const std::string& firstPath, const std::string& role) {
    detail::DatasetPtr first = detail::openRaster(firstPath, role);
    auto fail = [&](const std::string& what) {
        throw Error(path + ": " + what + " differs from the series' first step " + firstPath +
                    ": every water step must come from the same grid (same size, georeferencing and CRS)");
    };
    if (ds.GetRasterXSize() != first->GetRasterXSize() || ds.GetRasterYSize() != first->GetRasterYSize())
        fail("size " + std::to_string(ds.GetRasterXSize()) + " x " + std::to_string(ds.GetRasterYSize()) + " px");
    std::array<double, 6> a{}, b{};
    const bool ga = ds.GetGeoTransform(a.data()) == CE_None, gb = first->GetGeoTransform(b.data()) == CE_None;
    if (ga != gb) fail("having a georeferencing");
    for (int i = 0; ga && i < 6; ++i)
        if (std::abs(a[size_t(i)] - b[size_t(i)]) > 1e-9 * std::max({1.0, std::abs(a[size_t(i)]), std::abs(b[size_t(i)])}))
            fail("the georeferencing (geotransform)");
    const OGRSpatialReference* sa = ds.GetSpatialRef();
    const OGRSpatialReference* sb = first->GetSpatialRef();
    const bool ha = sa && !sa->IsEmpty(), hb = sb && !sb->IsEmpty();
    if (ha != hb || (ha && !sa->IsSame(sb))) fail("the CRS");
}

}  // namespace

Raster loadWater(const Options& opt, const Raster& terrain, LoadReport& report, size_t step) {
    if (step >= waterStepCount(opt)) throw Error("water step " + std::to_string(step) + " of " + std::to_string(waterStepCount(opt)));
    if (opt.water == WaterSource::Level) return bathtub(terrain, opt.waterLevelsM.empty() ? opt.waterLevelM : opt.waterLevelsM[step]);
    const std::string role = opt.water == WaterSource::Depth ? "water depth raster" : "water surface raster";
    const std::string& path = opt.waterPaths.empty() ? opt.waterPath : opt.waterPaths[step];
    detail::DatasetPtr ds = detail::openRaster(path, role);
    if (step > 0) checkAgreesWithFirst(*ds, path, opt.waterPaths[0], role);
    Options one = opt;
    one.waterPath = path;
    return warpedWater(one, *ds, terrain, report);
}

}  // namespace hc::ingest
