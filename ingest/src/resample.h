// Resampling a source raster onto a north-up, square-pixel target (private to ingest/).
#pragma once

#include <functional>
#include <vector>

#include "heightcast/ingest/raster.h"

namespace hc::ingest::detail {

// A raster as read from the file, before any geometry change: row-major, NaN = nodata.
struct SourceBand {
    size_t width = 0, height = 0;
    std::vector<float> values;
    float at(size_t col, size_t row) const { return values[row * width + col]; }
};

// Maps a target world position (x, y) [m] to fractional source pixel coordinates (col, row), where
// pixel (c, r) covers [c, c+1) x [r, r+1). Returns false where the position has no source.
using TargetToSource = std::function<bool(double x, double y, double& col, double& row)>;

// Fills target.values (target geometry already set) by bilinear interpolation of `source`; where a
// 2x2 neighbourhood touches nodata, the nearest pixel's value (or nodata). The map is evaluated
// exactly every `lattice` pixels and bilinearly in between (exact for affine maps; for a UTM
// inverse over 16 pixels the error is below 1e-6 pixel, see tests/ingest_test.cpp).
void resample(const SourceBand& source, const TargetToSource& map, Raster& target, int lattice, unsigned threads);

}  // namespace hc::ingest::detail
