// Resampling a source raster onto a north-up, square-pixel target (private to ingest/).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "heightcast/ingest/ingest.h"
#include "heightcast/ingest/raster.h"

class GDALDataset;

namespace hc::ingest::detail {

// A raster as read from the file, before any geometry change: row-major, NaN = nodata.
struct SourceBand {
    size_t width = 0, height = 0;
    std::vector<float> values;
    std::vector<float> residual;  // empty, or the source value minus values[i] (a Float64 source's precision)
    float at(size_t col, size_t row) const { return values[row * width + col]; }
    double exact(size_t i) const { return residual.empty() ? values[i] : double(values[i]) + residual[i]; }
};

// The source as read, and where its pixel centres land in the grid CRS: what loadTerrain keeps when
// the working raster is not the source itself, for the check of the finished grid against the source.
struct SourceTrace {
    SourceBand band;
    // World position [m, grid CRS] of the centre of every pixel of source row `row`; ok[c] = 0 where
    // the position does not exist (outside the projection's domain). The caller sizes the vectors to
    // the source's width.
    std::function<void(size_t row, std::vector<double>& x, std::vector<double>& y, std::vector<int>& ok)> rowToWorld;
    bool rowToWorldThreadSafe = true;  // false for PROJ's transformations: then called from one thread
};

// Maps a target world position (x, y) [m] to fractional source pixel coordinates (col, row), where
// pixel (c, r) covers [c, c+1) x [r, r+1). Returns false where the position has no source.
using TargetToSource = std::function<bool(double x, double y, double& col, double& row)>;

// Reads the band (or decodes Terrain-RGB) into floats with every kind of nodata as NaN; warns about
// what the file leaves unsaid (read_source.cpp). zCrs: metres per elevation unit that the CRS declares
// (a compound CRS's vertical part), used when the band declares no unit of its own.
SourceBand readSource(GDALDataset& ds, const Options& opt, LoadReport& report, double zCrs, const std::string& zCrsUnit);

// loadTerrain (ingest.h), keeping the source in `trace` (when given) if the working raster is not the
// source itself; trace->band stays empty otherwise.
Raster loadTerrainTraced(const Options& opt, LoadReport& report, SourceTrace* trace);

// Fills target.values (target geometry already set) by bilinear interpolation of `source`; next to
// nodata, bilinear weights renormalised over the valid neighbours, with the hole's edge where the
// nearest pixel puts it. The map is evaluated exactly every `lattice` pixels and bilinearly in
// between; the lattice is refined (halved) until that interpolation is within maxErrorPx of the
// exact map at every lattice-cell centre. Returns the lattice step used.
int resample(const SourceBand& source, const TargetToSource& map, Raster& target, int lattice, double maxErrorPx,
             unsigned threads);

}  // namespace hc::ingest::detail
