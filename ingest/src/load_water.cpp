// loadWater: a water depth or water surface raster warped onto the terrain, or a bathtub level.
#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <limits>

#include <fmt/format.h>

#include <gdalwarper.h>

#include "gdal_util.h"
#include "heightcast/core/error.h"
#include "heightcast/core/progress.h"
#include "heightcast/ingest/ingest.h"
#include "load_water.h"
#include "resample.h"

namespace hc::ingest {
namespace {

// Bathtub: depth = level - z in the pixels below `level` that water can reach from the domain
// boundary (the raster edge and the edge of every nodata hole: water enters from outside the survey)
// through 4-connected pixels below the level. Closed depressions stay dry, as they would in a flood.
// One process, the whole raster held: a flood fill. Under mpirun no rank holds the raster, and Builder::bathtubBlocks
// labels each window's components and joins them across the ranks instead; this fill is its reference (the MPI tests
// compare the grids of 1, 2 and 3 ranks byte for byte, tests/cli/mpi.cmake).
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

// Steps of one series must be one simulation's output: the same raster size, georeferencing and CRS as the first.
void checkAgreesWithFirst(GDALDataset& ds, const std::string& path, const std::string& firstPath,
                          const std::string& role) {
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
        if (std::abs(a[size_t(i)] - b[size_t(i)]) >
            1e-9 * std::max({1.0, std::abs(a[size_t(i)]), std::abs(b[size_t(i)])}))
            fail("the georeferencing (geotransform)");
    const OGRSpatialReference* sa = ds.GetSpatialRef();
    const OGRSpatialReference* sb = first->GetSpatialRef();
    const bool ha = sa && !sa->IsEmpty(), hb = sb && !sb->IsEmpty();
    if (ha != hb || (ha && !sa->IsSame(sb))) fail("the CRS");
}

}  // namespace

namespace detail {

WaterStepWarp::WaterStepWarp(const Options& opt, const Raster& frame, size_t step, LoadReport& report) {
    if (opt.water != WaterSource::Depth && opt.water != WaterSource::Surface)
        throw Error("internal: a water step warp without a water raster");
    surface_ = opt.water == WaterSource::Surface;
    const std::string role = surface_ ? "water surface raster" : "water depth raster";
    const std::string& path = opt.waterPaths.empty() ? opt.waterPath : opt.waterPaths[step];
    ds_ = openRaster(path, role);
    if (step > 0 && path != opt.waterPaths[0]) checkAgreesWithFirst(*ds_, path, opt.waterPaths[0], role);
    what_ = waterStepName(opt, step);
    const int band = opt.waterBands.empty() ? 1 : opt.waterBands.at(step);
    if (band < 1 || band > ds_->GetRasterCount()) throw Error(path + ": has no band " + std::to_string(band));
    const OGRSpatialReference* srs = ds_->GetSpatialRef();
    const bool waterHasCrs = srs && !srs->IsEmpty();
    if (waterHasCrs != !frame.crsWkt.empty())
        report.warnings.push_back(what_ + ": " + (waterHasCrs ? "the terrain has no CRS" : "has no CRS") +
                                  "; both taken to be in the same frame");
    const std::string dstWkt = waterHasCrs && !frame.crsWkt.empty() ? frame.crsWkt : std::string();
    // The kernel's scale, fixed for the whole raster (GDAL's XSCALE, YSCALE): working pixels per water pixel, at most 1
    // (a water raster coarser than the working pixel is interpolated, a finer one averaged over the kernel's width).
    // GDAL estimates it from each chunk it warps, so without this a window could differ from the whole.
    char** opts = dstWkt.empty() ? nullptr : CSLSetNameValue(nullptr, "DST_SRS", dstWkt.c_str());
    void* tr = GDALCreateGenImgProjTransformer2(GDALDataset::ToHandle(ds_.get()), nullptr, opts);
    CSLDestroy(opts);
    if (!tr) throw Error(what_ + ": cannot transform onto the terrain: " + lastGdalError());
    double sg[6];
    int pw = 0, ph = 0;
    const CPLErr e =
        GDALSuggestedWarpOutput(GDALDataset::ToHandle(ds_.get()), GDALGenImgProjTransform, tr, sg, &pw, &ph);
    GDALDestroyGenImgProjTransformer(tr);
    if (e != CE_None) throw Error(what_ + ": cannot resample onto the terrain: " + lastGdalError());
    int has = 0;
    const double nd = ds_->GetRasterBand(band)->GetNoDataValue(&has);
    warp_.src = ds_.get();
    warp_.band = band;
    warp_.hasSrcNoData = has != 0, warp_.srcNoData = has ? nd : 0;
    const double gt[6] = {frame.westWorld, frame.pixelSizeM, 0, frame.northWorld, 0, -frame.pixelSizeM};
    std::copy(gt, gt + 6, warp_.gt);
    warp_.width = frame.width, warp_.height = frame.height;
    warp_.dstSrs = dstWkt, warp_.dstWkt = dstWkt;
    warp_.scale = std::min(1.0, std::min(std::abs(sg[1]), std::abs(sg[5])) / frame.pixelSizeM);
    warp_.threads = opt.threads;
    warp_.setupError = what_ + ": cannot transform onto the terrain";
    warp_.warpError = what_ + ": resampling onto the terrain";
}

void WaterStepWarp::warp(size_t c0, size_t r0, size_t w, size_t h, float* out) const {
    std::fill(out, out + w * h, std::numeric_limits<float>::quiet_NaN());
    if (w == 0 || h == 0) return;
    warp_.into(c0, r0, w, h, out);
    ds_->FlushCache(false);  // drops its blocks from GDAL's cache: the next window reads what it reaches
}

void WaterStepWarp::depth(size_t c0, size_t r0, size_t w, size_t h, const float* terrainZ, float* out,
                          uint64_t& negative) const {
    warp(c0, r0, w, h, out);
    for (size_t i = 0; i < w * h; ++i) {
        const float z = terrainZ[i], v = out[i];
        if (std::isnan(z)) {
            out[i] = std::numeric_limits<float>::quiet_NaN();
            continue;
        }
        if (std::isnan(v)) {  // no water data here: dry
            out[i] = 0;
            continue;
        }
        const float d = surface_ ? v - z : v;
        if (!surface_ && d < 0) ++negative;
        out[i] = d > 0 ? d : 0.0f;
    }
}

std::string waterStepName(const Options& opt, size_t step) {
    const std::string& path = opt.waterPaths.empty() ? opt.waterPath : opt.waterPaths.at(step);
    return opt.waterBands.empty() ? path : fmt::format("{} (band {}, step {})", path, opt.waterBands.at(step), step);
}

std::string negativeDepthWarning(const std::string& what, uint64_t negative) {
    return what + ": " + std::to_string(negative) + " pixels of negative depth taken as dry";
}

}  // namespace detail

Raster loadWater(const Options& opt, const Raster& terrain, LoadReport& report, size_t step) {
    if (step >= waterStepCount(opt))
        throw Error("water step " + std::to_string(step) + " of " + std::to_string(waterStepCount(opt)));
    if (opt.water == WaterSource::Level)
        return bathtub(terrain, opt.waterLevelsM.empty() ? opt.waterLevelM : opt.waterLevelsM[step]);
    // Warped in strips of rows, as a rank warps its windows (WaterStepWarp): the same bits.
    const detail::WaterStepWarp warp(opt, terrain, step, report);
    Raster d = terrain;
    const size_t w = terrain.width, strip = std::max<size_t>(1, (size_t{1} << 22) / std::max<size_t>(1, w));
    uint64_t negative = 0;
    for (size_t r0 = 0; r0 < terrain.height; r0 += strip) {
        const size_t h = std::min(strip, terrain.height - r0);
        warp.depth(0, r0, w, h, terrain.values.data() + r0 * w, d.values.data() + r0 * w, negative);
    }
    if (negative > 0) report.warnings.push_back(detail::negativeDepthWarning(warp.what(), negative));
    return d;
}

size_t expandWaterTimeSeries(Options& o, LoadReport& report) {
    if (o.water != WaterSource::Depth && o.water != WaterSource::Surface) return 0;
    if (o.waterPaths.size() > 1) {  // a list of files: one step each, each of one band
        for (const std::string& p : o.waterPaths)
            if (int n = detail::openRaster(p, "water raster")->GetRasterCount(); n != 1)
                throw Error(p + ": has " + std::to_string(n) +
                            " bands: each file of a series of water rasters is one step of one band");
        return 0;
    }
    const std::string path = o.waterPaths.empty() ? o.waterPath : o.waterPaths[0];
    detail::DatasetPtr ds = detail::openRaster(path, "water raster");
    const int bands = ds->GetRasterCount();
    // GDAL's netCDF driver lists a variable's dimensions beyond y and x as NETCDF_DIM_EXTRA "{time}", and gives each
    // band its coordinate there (band metadata NETCDF_DIM_time) and the dimension's units (time#units).
    std::string extra = ds->GetMetadataItem("NETCDF_DIM_EXTRA") ? ds->GetMetadataItem("NETCDF_DIM_EXTRA") : "";
    extra.erase(std::remove_if(extra.begin(), extra.end(), [](char c) { return c == '{' || c == '}' || c == ' '; }),
                extra.end());
    if (extra.empty()) {
        if (bands > 1)
            throw Error(path + ": has " + std::to_string(bands) +
                        " bands and no time dimension: which is the water? Give one band per file " +
                        "(gdal_translate -b N), or a NetCDF variable over time (one step per time)");
        return 0;
    }
    if (extra.find(',') != std::string::npos)
        throw Error(path + ": the variable has dimensions " + extra +
                    " beside y and x: only one, time, can make water steps " +
                    "(take a slice with gdal_translate -b N)");
    const std::string dim = extra;
    const char* unitsItem = ds->GetMetadataItem((dim + "#units").c_str());
    const double unit = detail::cfSecondsPerUnit(unitsItem ? unitsItem : "");
    std::vector<double> times;
    for (int b = 1; b <= bands; ++b) {
        const char* v = ds->GetRasterBand(b)->GetMetadataItem(("NETCDF_DIM_" + dim).c_str());
        char* end = nullptr;
        const double t = v ? std::strtod(v, &end) : 0.0;
        if (!v || end == v || !std::isfinite(t))
            throw Error(path + ": band " + std::to_string(b) + " has no " + dim + " coordinate");
        times.push_back(unit > 0 ? t * unit : double(b - 1));
    }
    for (size_t k = 1; k < times.size(); ++k)
        if (!(times[k] > times[k - 1]))
            throw Error(
                fmt::format("{}: the times of its {} dimension do not increase: step {} at {:.9g} s follows {:.9g} s",
                            path, dim, k, times[k], times[k - 1]));
    if (unit == 0)
        report.warnings.push_back(path + ": the " + dim + " dimension has no CF time units (" +
                                  (unitsItem ? unitsItem : "none") +
                                  "): the step index is taken as time (--times sets the times)");
    if (o.timesS.empty()) {
        if (unit > 0) o.timesS = times;
    } else {
        report.warnings.push_back(path + ": --times replaces the file's own times");
    }
    o.waterPaths.assign(size_t(bands), path);
    o.waterBands.resize(size_t(bands));
    for (int b = 1; b <= bands; ++b) o.waterBands[size_t(b - 1)] = b;
    o.waterPath.clear();
    return size_t(bands);
}

}  // namespace hc::ingest
