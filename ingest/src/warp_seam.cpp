// Output pixels of a --t_srs warp between two source pieces, interpolated across the seam (warp_seam.h).
#include "warp_seam.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "gdal_util.h"
#include "heightcast/core/error.h"

namespace hc::ingest::detail {

WarpSeams::WarpSeams(std::vector<Seam> seams, const double gt[6], size_t srcHeight, const OGRSpatialReference& source,
                     const OGRSpatialReference& target, std::shared_ptr<OGRCoordinateTransformation> ct,
                     const double ext[4], double cell, size_t height, Fill fill)
    : seams_(std::move(seams)), srcHeight_(srcHeight), cell_(cell), height_(height), fill_(std::move(fill)) {
    std::copy(gt, gt + 6, gt_);
    std::copy(ext, ext + 4, ext_);
    OGRSpatialReference from = target, to = source;
    from.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    to.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    inverse_.reset(OGRCreateCoordinateTransformation(&from, &to));
    if (!inverse_) throw Error("cannot transform back from the target CRS: " + lastGdalError());
    // Each seam's footprint: both columns' meridians, sampled every quarter source row, mapped into output pixels;
    // every output row between consecutive samples gets the columns between them, two more on each side.
    const double dx = gt_[1];
    for (const Seam& s : seams_) {
        Band b;
        b.first.assign(height_, std::numeric_limits<int64_t>::max());
        b.last.assign(height_, std::numeric_limits<int64_t>::min());
        for (double lon : {s.lonW, s.lonW + dx}) {
            std::vector<double> x, y;
            for (size_t q = 0; q <= 4 * srcHeight_; ++q)
                x.push_back(lon), y.push_back(gt_[3] + double(q) / 4.0 * gt_[5]);
            std::vector<int> ok(x.size());
            CPLErrorStateBackuper quiet;
            ct->Transform(int(x.size()), x.data(), y.data(), nullptr, ok.data());
            double pc = NAN, pr = NAN;
            for (size_t q = 0; q < x.size(); ++q) {
                if (!ok[q] || !std::isfinite(x[q]) || !std::isfinite(y[q])) {
                    pc = pr = NAN;
                    continue;
                }
                const double c = (x[q] - ext_[0]) / cell_, r = (ext_[3] - y[q]) / cell_;
                const double ca = std::isnan(pc) ? c : pc, ra = std::isnan(pr) ? r : pr;
                const double r0 = std::floor(std::min(r, ra)) - 1, r1 = std::floor(std::max(r, ra)) + 1;
                for (double row = std::max(0.0, r0); row <= std::min(double(height_) - 1, r1); ++row) {
                    b.first[size_t(row)] = std::min(b.first[size_t(row)], int64_t(std::floor(std::min(c, ca))) - 2);
                    b.last[size_t(row)] = std::max(b.last[size_t(row)], int64_t(std::ceil(std::max(c, ca))) + 2);
                }
                pc = c, pr = r;
            }
        }
        bands_.push_back(std::move(b));
    }
}

void WarpSeams::readColumns() const {
    std::call_once(read_, [&] {
        for (const Seam& s : seams_) {
            west_.emplace_back(srcHeight_), east_.emplace_back(srcHeight_);
            fill_(s.colW, 0, 1, srcHeight_, west_.back().data());
            fill_(s.colE, 0, 1, srcHeight_, east_.back().data());
        }
    });
}

// The bilinear value at (lon, lat), lon between the seam's columns: the four neighbours (two rows of the two columns)
// weighted as GDAL's kernel weighs them, NaN ones left out and the others renormalised; NaN where all are NaN.
double WarpSeams::interpolate(const Seam& s, size_t k, double lon, double lat) const {
    const double fx = (lon - s.lonW) / gt_[1];
    const double fy = (lat - gt_[3]) / gt_[5] - 0.5;  // rows from the first row's centre
    const double r0 = std::floor(fy), wy = fy - r0;
    double sum = 0, weight = 0;
    for (int dr = 0; dr < 2; ++dr) {
        const double row = r0 + dr;
        if (row < 0 || row >= double(srcHeight_)) continue;
        const double wr = dr ? wy : 1 - wy;
        const float a = west_[k][size_t(row)], b = east_[k][size_t(row)];
        if (!std::isnan(a)) sum += wr * (1 - fx) * a, weight += wr * (1 - fx);
        if (!std::isnan(b)) sum += wr * fx * b, weight += wr * fx;
    }
    return weight > 1e-5 ? sum / weight : NAN;
}

void WarpSeams::apply(size_t c0, size_t r0, size_t w, size_t h, float* out) const {
    if (seams_.empty()) return;
    readColumns();
    std::vector<double> x, y;
    std::vector<int> ok;
    for (size_t k = 0; k < seams_.size(); ++k) {
        const Seam& s = seams_[k];
        for (size_t r = r0; r < r0 + h; ++r) {
            const int64_t a = std::max(bands_[k].first[r], int64_t(c0)),
                          b = std::min(bands_[k].last[r], int64_t(c0 + w) - 1);
            if (a > b) continue;
            x.clear(), y.clear();
            for (int64_t c = a; c <= b; ++c)
                x.push_back(ext_[0] + (double(c) + 0.5) * cell_), y.push_back(ext_[3] - (double(r) + 0.5) * cell_);
            ok.assign(x.size(), 0);
            CPLErrorStateBackuper quiet;
            inverse_->Transform(int(x.size()), x.data(), y.data(), nullptr, ok.data());
            for (size_t i = 0; i < x.size(); ++i) {
                if (!ok[i]) continue;
                const double lon =
                    s.lonW + std::remainder(x[i] - s.lonW - gt_[1] / 2, 360.0) + gt_[1] / 2;  // near the seam
                if (!(lon > s.lonW && lon < s.lonW + gt_[1])) continue;
                const double v = interpolate(s, k, lon, y[i]);
                out[(r - r0) * w + size_t(a - int64_t(c0)) + i] = float(v);
            }
        }
    }
}

}  // namespace hc::ingest::detail
