// ingest/src/warp_seam.h: --t_srs output pixels between two source columns that the warp reads from different pieces
// (a geographic source split at 180 degrees, and a grid around the globe across its own west and east edges),
// interpolated across the seam (private to ingest/).
//
// GDAL's bilinear kernel at a piece's edge weighs only the columns the piece has: an output pixel whose source position
// lies between the last column west of the seam and the first east of it would take the nearer piece's edge column
// alone. For those pixels the interpolation is done here, from both columns, as the kernel does it inside a piece
// (the four neighbours' bilinear weights, NaN neighbours left out and the rest renormalised). Pixels are found by the
// exact inverse transform of each output pixel centre near the seam's own footprint in the output.
#pragma once

#include <functional>
#include <memory>
#include <mutex>
#include <vector>

#include <ogr_spatialref.h>

namespace hc::ingest::detail {

class WarpSeams {
public:
    using Fill =
        std::function<void(size_t col0, size_t row0, size_t w, size_t h, float* out)>;  // source columns, row-major
    // A seam between source columns colW and colE, colW's centre at lonW [degrees] and colE's at lonW + dx.
    struct Seam {
        size_t colW = 0, colE = 0;
        double lonW = 0;
    };
    // `gt`: the source's geotransform (north-up, degrees); srcHeight its rows; `ct`: source -> target; the output's
    // west and north edges, pixel size [target units] and row count.
    WarpSeams(std::vector<Seam> seams, const double gt[6], size_t srcHeight, const OGRSpatialReference& source,
              const OGRSpatialReference& target, std::shared_ptr<OGRCoordinateTransformation> ct, const double ext[4],
              double cell, size_t height, Fill fill);
    bool empty() const { return seams_.empty(); }
    // Re-interpolates the pixels [c0, c0 + w) x [r0, r0 + h) of `out` (the warped window) that lie between a seam's
    // columns.
    void apply(size_t c0, size_t r0, size_t w, size_t h, float* out) const;

private:
    struct Band {
        std::vector<int64_t> first, last;  // per output row: the output columns the seam may cross (first > last: none)
    };
    void readColumns() const;
    double interpolate(const Seam& s, size_t k, double lon, double lat) const;
    std::vector<Seam> seams_;
    std::vector<Band> bands_;
    double gt_[6];
    size_t srcHeight_;
    std::unique_ptr<OGRCoordinateTransformation> inverse_;  // target -> source
    double ext_[4], cell_;
    size_t height_;
    Fill fill_;
    mutable std::once_flag read_;
    mutable std::vector<std::vector<float>> west_, east_;  // per seam, its two columns (srcHeight values each)
};

}  // namespace hc::ingest::detail
