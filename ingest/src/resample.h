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

// Fills target.values (target geometry already set) by bilinear interpolation of `source`; next to
// nodata, bilinear weights renormalised over the valid neighbours, with the hole's edge where the
// nearest pixel puts it. The map is evaluated exactly every `lattice` pixels and bilinearly in
// between; the lattice is refined (halved) until that interpolation is within maxErrorPx of the
// exact map at every lattice-cell centre. Returns the lattice step used.
int resample(const SourceBand& source, const TargetToSource& map, Raster& target, int lattice, double maxErrorPx,
             unsigned threads);

}  // namespace hc::ingest::detail
