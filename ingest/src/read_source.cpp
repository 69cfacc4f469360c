// BandReader: one band of a raster file -> floats, every kind of nodata as NaN, window by window (loadTerrain's first
// step). Also where the file's silent conventions are caught: +-inf pixels, undeclared nodata sentinels (-9999, -32768,
// ...), RGB images read as elevations, elevation units, and what float32 loses of a Float64 source.
#include <algorithm>
#include <cmath>
#include <limits>

#include "gdal_util.h"
#include "heightcast/core/error.h"
#include "resample.h"

namespace hc::ingest::detail {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Metres per unit of the band's elevation values, from its unit type; 1 when unknown or metres.
double verticalUnitScale(GDALRasterBand* band, std::string& unitName) {
    unitName = band->GetUnitType() ? band->GetUnitType() : "";
    std::string u = lower(unitName);
    if (u.find("us") != std::string::npos &&
        (u.find("ft") != std::string::npos || u.find("foot") != std::string::npos ||
         u.find("feet") != std::string::npos))
        return 1200.0 / 3937.0;
    if (u == "ft" || u == "foot" || u == "feet" || u.find("international foot") != std::string::npos) return 0.3048;
    return 1.0;
}

// Values that files use for "no data" without always saying so. `impossible`: no elevation on Earth
// (warned at any count); -9999 m is a possible ocean depth, warned from 0.1 % of the pixels on.
struct Sentinel {
    double value;
    bool impossible;
};
constexpr Sentinel kSentinels[] = {{-9999, false},
                                   {-99999, true},
                                   {-32768, true},
                                   {-32767, true},
                                   {-3.4028234663852886e38, true},
                                   {-3.4e38, true},
                                   {9.969209968386869e36, true}};
constexpr size_t kSentinelCount = sizeof kSentinels / sizeof kSentinels[0];

// Index into kSentinels of a value (compared in float32 too: an .asc's -3.4e38 and a Float32 file's
// -FLT_MAX), or kSentinelCount.
size_t sentinelIndex(double v) {
    if (v > -9999 && v < 1e36) return kSentinelCount;  // the common case, in one comparison
    for (size_t k = 0; k < kSentinelCount; ++k)
        if (v == kSentinels[k].value || static_cast<float>(v) == static_cast<float>(kSentinels[k].value)) return k;
    return kSentinelCount;
}

}  // namespace

BandReader::BandReader(GDALDataset& ds, const Options& opt, LoadReport& report, double zCrs,
                       const std::string& zCrsUnit)
    : ds_(ds), opt_(opt) {
    width_ = static_cast<size_t>(ds.GetRasterXSize());
    height_ = static_cast<size_t>(ds.GetRasterYSize());
    const int bandCount = ds.GetRasterCount();
    if (opt.terrainRgb && bandCount < 3)
        throw Error(opt.input + ": --terrain-rgb needs 3 bands (R, G, B), the raster has " + std::to_string(bandCount));
    if (!opt.terrainRgb && opt.band > bandCount)
        throw Error(opt.input + ": --band " + std::to_string(opt.band) + " is out of range: the raster has " +
                    std::to_string(bandCount) + " band" + (bandCount == 1 ? "" : "s"));
    band_ = ds.GetRasterBand(opt.terrainRgb ? 1 : opt.band);
    auto isByte = [&](int b) { return ds.GetRasterBand(b)->GetRasterDataType() == GDT_Byte; };
    if (!opt.terrainRgb && !opt.bandGiven && bandCount >= 3 && isByte(1) && isByte(2) && isByte(3))
        throw Error(
            opt.input + ": has " + std::to_string(bandCount) + " 8-bit bands, an RGB" + (bandCount > 3 ? "A" : "") +
            " image: read as elevations, band 1 would make a terrain of 0..255 m steps; if it is a Terrain-RGB tile "
            "(Mapbox, MapTiler) add --terrain-rgb, or name the band that holds elevations with --band N");
    if (opt.terrainRgb)
        for (int b = 1; b <= 3; ++b)
            if (ds.GetRasterBand(b)->GetRasterDataType() != GDT_Byte)
                throw Error(opt.input + ": --terrain-rgb needs 8-bit bands; band " + std::to_string(b) + " is " +
                            GDALGetDataTypeName(ds.GetRasterBand(b)->GetRasterDataType()));

    int blockX = 0, blockY = 0;
    band_->GetBlockSize(&blockX, &blockY);
    blockRows_ = size_t(std::clamp(blockY, 1, 4096));  // a strip of 4096 rows at most, whatever a driver says
    report.sourceDescription = std::to_string(width_) + " x " + std::to_string(height_) + " px, " +
                               GDALGetDataTypeName(band_->GetRasterDataType()) + ", " + std::to_string(bandCount) +
                               " band" + (bandCount == 1 ? "" : "s") + ", " + ds.GetDriver()->GetDescription();
    int hasNodata = 0;
    nodata_ = band_->GetNoDataValue(&hasNodata);  // used only when the band declares one
    hasNodata_ = hasNodata != 0;
    const int maskFlags = band_->GetMaskFlags();
    useMask_ = !(maskFlags & GMF_ALL_VALID) && !(maskFlags & GMF_NODATA) && (maskFlags & (GMF_PER_DATASET | GMF_ALPHA));
    std::string unitName;
    double zUnit = opt.terrainRgb ? 1.0 : verticalUnitScale(band_, unitName);
    if (zUnit != 1.0)
        report.warnings.push_back("elevations are in '" + unitName + "': converted to metres (x" + fmt(zUnit, 10) +
                                  ")");
    if (!opt.terrainRgb && unitName.empty() && zCrs != 1.0) {
        zUnit = zCrs;
        report.warnings.push_back("the band declares no unit; the CRS's vertical unit is " + zCrsUnit +
                                  ": elevations converted to metres (x" + fmt(zCrs, 10) +
                                  "; if they are metres after all, add --z-scale " + fmt(1.0 / zCrs, 10) + ")");
    }
    zScale_ = zUnit * opt.zScale;
    const GDALDataType sampleType = band_->GetRasterDataType();
    exactInFloat_ =
        sampleType == GDT_Byte || sampleType == GDT_UInt16 || sampleType == GDT_Int16 || sampleType == GDT_Float32;
    report.sourcePrecisionDouble = !opt.terrainRgb && !exactInFloat_;
}

void SourceTally::add(const SourceTally& o) {
    validPixels += o.validPixels;
    infPixels += o.infPixels;
    for (size_t k = 0; k < kSentinelSlots; ++k) sentinels[k] += o.sentinels[k];
    maxOther = std::max(maxOther, o.maxOther);
}

void BandReader::read(size_t c0, size_t r0, size_t w, size_t h, float* dst, std::vector<float>& residual,
                      size_t residualAt, size_t residualSize, SourceTally& tally) {
    static_assert(kSentinelCount <= SourceTally::kSentinelSlots);
    const size_t n = w * h;
    if (n == 0) return;
    auto rasterIO = [&](GDALRasterBand* b, void* to, GDALDataType type) {
        CPLErrorReset();
        if (b->RasterIO(GF_Read, static_cast<int>(c0), static_cast<int>(r0), static_cast<int>(w), static_cast<int>(h),
                        to, static_cast<int>(w), static_cast<int>(h), type, 0, 0, nullptr) != CE_None)
            throw Error(opt_.input + ": cannot read rows " + std::to_string(r0) + ".." + std::to_string(r0 + h - 1) +
                        (w == width_ ? "" : ", columns " + std::to_string(c0) + ".." + std::to_string(c0 + w - 1)) +
                        " (truncated or corrupt file?): " + detail::lastGdalError());
    };
    if (opt_.terrainRgb) {
        rgb_.resize(3 * n);
        for (int b = 0; b < 3; ++b)
            rasterIO(ds_.GetRasterBand(b + 1), rgb_.data() + static_cast<size_t>(b) * n, GDT_Byte);
        for (size_t i = 0; i < n; ++i) {
            double v = -10000.0 + 0.1 * (rgb_[i] * 65536.0 + rgb_[n + i] * 256.0 + rgb_[2 * n + i]);
            dst[i] = static_cast<float>(v * zScale_);
        }
    } else {
        // Exact types are read straight into place (float32 holds all their values); the others
        // through doubles, keeping what float32 loses in `residual`.
        if (exactInFloat_) {
            rasterIO(band_, dst, GDT_Float32);
        } else {
            buf_.resize(n);
            rasterIO(band_, buf_.data(), GDT_Float64);
        }
        // The rules, pixel by pixel.
        auto convert = [&](size_t i, double& maxOther) {
            double v = exactInFloat_ ? static_cast<double>(dst[i]) : buf_[i];
            bool isNodata =
                std::isnan(v) ||
                (hasNodata_ && (v == nodata_ || static_cast<float>(v) == static_cast<float>(nodata_))) ||
                // --nodata: in float32 for float32 data (as the user reads it), exactly otherwise
                (opt_.nodata &&
                 (v == *opt_.nodata || (exactInFloat_ && static_cast<float>(v) == static_cast<float>(*opt_.nodata))));
            if (!isNodata && std::isinf(v)) {
                ++tally.infPixels;
                isNodata = true;
            }
            if (isNodata) {
                dst[i] = kNaN;
                return;
            }
            const double exact = v * zScale_;
            dst[i] = static_cast<float>(exact);
            if (!std::isfinite(dst[i]))
                throw Error(opt_.input + ": elevation " + fmt(v) + " x " + fmt(zScale_) +
                            " is beyond the float32 range");
            if (size_t k = sentinelIndex(v); k < kSentinelCount)
                ++tally.sentinels[k];
            else
                maxOther = std::max(maxOther, exact);
            const float lost = static_cast<float>(exact - static_cast<double>(dst[i]));
            if (lost != 0.0f) {
                if (residual.empty()) residual.assign(residualSize, 0.0f);
                residual[residualAt + i] = lost;
            }
        };
        double maxOther = tally.maxOther;  // in a register, not stored through `tally` a pixel
        // A chunk of plain float32 pixels (finite, above the sentinels' range, not a nodata value) read at scale 1
        // stays as read and only raises the maximum: checked branch-free, eight lanes at a time, before the exact
        // pixel-by-pixel rules below take any chunk that is not all plain.
        const bool plainPossible = exactInFloat_ && zScale_ == 1.0;
        const float nodata32 = hasNodata_ ? static_cast<float>(nodata_) : kNaN;
        const float userNodata32 = opt_.nodata ? static_cast<float>(*opt_.nodata) : kNaN;
        constexpr size_t kChunk = 256;
        for (size_t c = 0; c < n; c += kChunk) {
            const size_t end = std::min(n, c + kChunk);
            if (plainPossible && end - c == kChunk) {
                std::array<float, 8> top;
                top.fill(-HUGE_VALF);
                bool plain = true;
                for (size_t i = c; i < end; i += 8)
                    for (size_t k = 0; k < 8; ++k) {
                        const float v = dst[i + k];
                        plain &= (v > -9999.0f) & (v < 1e36f) & (v != nodata32) & (v != userNodata32);
                        top[k] = v > top[k] ? v : top[k];
                    }
                if (plain) {
                    maxOther = std::max(maxOther, static_cast<double>(*std::max_element(top.begin(), top.end())));
                    continue;
                }
            }
            for (size_t i = c; i < end; ++i) convert(i, maxOther);
        }
        tally.maxOther = maxOther;
    }
    if (useMask_) {
        mask_.resize(n);
        rasterIO(band_->GetMaskBand(), mask_.data(), GDT_Byte);
        for (size_t i = 0; i < n; ++i)
            if (mask_[i] == 0) dst[i] = kNaN;
    }
    uint64_t valid = 0;
    for (size_t i = 0; i < n; ++i) valid += !std::isnan(dst[i]);
    tally.validPixels += valid;
}

size_t BandReader::stripRows(size_t bytes) const {
    const size_t rows = std::max<size_t>(1, bytes / (width_ * 8 + 1));
    return std::min(height_, (rows + blockRows_ - 1) / blockRows_ * blockRows_);
}

void BandReader::dropCache() {
    // Drop GDAL's cached blocks of the rows just read: otherwise its block cache holds a second
    // copy of the whole file at the peak of the read.
    for (int b = 1; b <= ds_.GetRasterCount(); ++b) ds_.GetRasterBand(b)->FlushCache(false);
    if (useMask_) band_->GetMaskBand()->FlushCache(false);
}

void BandReader::finish(const SourceTally& tally, LoadReport& report) const {
    report.sourceValidPixels = tally.validPixels;
    report.infPixels = tally.infPixels;
    if (tally.infPixels > 0)
        report.warnings.push_back(std::to_string(tally.infPixels) + " pixels hold +-inf: taken as nodata (holes)");
    for (size_t k = 0; k < kSentinelCount; ++k) {
        const uint64_t count = tally.sentinels[k];
        const double share = tally.validPixels ? double(count) / double(tally.validPixels) : 0.0;
        if (count == 0 || (!kSentinels[k].impossible && share < 1e-3)) continue;
        const double z = kSentinels[k].value * zScale_;
        std::string cliff = std::isfinite(tally.maxOther)
                                ? " (cliffs of up to " + fmt(std::abs(tally.maxOther - z) / 1000.0, 3) + " km)"
                                : "";
        report.warnings.push_back(std::to_string(count) + " pixels (" + fmt(100.0 * share, 3) +
                                  " % of the valid ones) hold " + fmt(kSentinels[k].value, 9) +
                                  ", a classic nodata sentinel, but the file declares no such nodata value: " +
                                  "they are taken as elevations" + cliff + "; if they are nodata, add --nodata " +
                                  fmt(kSentinels[k].value, 9));
    }
}

}  // namespace hc::ingest::detail
