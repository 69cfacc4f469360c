// Reading a terrain band (whole or window by window) and resampling it onto a north-up, square-pixel target (private to
// ingest/).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "heightcast/ingest/ingest.h"
#include "heightcast/ingest/raster.h"
#include "heightcast/ingest/detail/windows.h"

class GDALDataset;
class GDALRasterBand;

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

// One band of an open raster, read window by window (read_source.cpp): into floats with every kind of nodata as NaN,
// in metres (Terrain-RGB decoded). The constructor checks the bands and warns about the units; finish() warns about
// what the pixels showed (+-inf, undeclared sentinels). zCrs: metres per elevation unit that the CRS declares (a
// compound CRS's vertical part), used when the band declares no unit of its own. `ds` must outlive the reader.
class BandReader {
public:
    BandReader(GDALDataset& ds, const Options& opt, LoadReport& report, double zCrs, const std::string& zCrsUnit);
    size_t width() const { return width_; }
    size_t height() const { return height_; }
    // Source pixels [c0, c0 + w) x [r0, r0 + h) into values (w h, row-major). What float32 loses of a Float64 source
    // goes to residual[residualAt + i], the vector sized residualSize (zeros) when the first such pixel comes.
    void read(size_t c0, size_t r0, size_t w, size_t h, float* values, std::vector<float>& residual, size_t residualAt,
              size_t residualSize, SourceTally& tally);
    // Rows a strip of whole rows should hold to read the band once: about `bytes` of buffers (8 bytes a pixel), rounded
    // up to whole rows of the file's blocks. A strip thinner than a block would decode every tile of a tiled file once
    // per strip (dropCache throws it away between strips): 21 times for 256-row tiles and 12-row strips.
    size_t stripRows(size_t bytes) const;
    size_t blockRows() const { return blockRows_; }
    // Drops GDAL's cached blocks of what was read (a second copy of the file otherwise).
    void dropCache();
    // The counts and warnings of a tally (the whole band's, every window and rank added) into report.
    void finish(const SourceTally& tally, LoadReport& report) const;

private:
    GDALDataset& ds_;
    const Options& opt_;
    GDALRasterBand* band_ = nullptr;
    size_t width_ = 0, height_ = 0, blockRows_ = 1;
    bool hasNodata_ = false, useMask_ = false, exactInFloat_ = false;
    double nodata_ = 0, zScale_ = 1;
    std::vector<double> buf_;
    std::vector<uint8_t> rgb_, mask_;
};

// The working raster's pixel (row * width + col) whose square holds world position (x, y), or -1 where none (or where
// the position does not exist: !ok): the rule of the check against the source, in one process and on the ranks.
inline int64_t workingPixelAt(const Raster& t, double x, double y, bool ok) {
    const double col = std::floor((x - t.westWorld) / t.pixelSizeM);
    const double row = std::floor((t.northWorld - y) / t.pixelSizeM);
    if (!(ok && col >= 0 && row >= 0 && col < double(t.width) && row < double(t.height))) return -1;
    return int64_t(size_t(row) * t.width + size_t(col));
}

// loadTerrain (ingest.h), keeping the source in `trace` (when given) if the working raster is not the
// source itself; trace->band stays empty otherwise.
Raster loadTerrainTraced(const Options& opt, LoadReport& report, SourceTrace* trace);

// Fills target.values (target geometry already set) by bilinear interpolation of `source`; next to
// nodata, bilinear weights renormalised over the valid neighbours, with the hole's edge where the
// nearest pixel puts it. The map is evaluated exactly every `lattice` pixels and bilinearly in
// between; the lattice is refined (halved) until that interpolation is within maxErrorPx of the
// exact map at every lattice-cell centre. Returns the lattice step used.
//
// The same in pieces, for a target filled window by window (each rank its own, docs/design.md section 7): latticeStep
// over the whole target (the map only, no pixel; two rows of nodes held at a time), then resampleWindow per window,
// which asks for the source pixels it reads. The lattice is the whole target's, so a window's pixels are the same bits
// as resample() gives them (resample() is latticeStep and one window over the whole target).
int resample(const SourceBand& source, const TargetToSource& map, Raster& target, int lattice, double maxErrorPx,
             unsigned threads);

// A source raster or a window of it: source pixel (col, row) at values[(row - r0) * w + (col - c0)]; width x height is
// the whole source's size (the bounds and edge clamps are the whole source's).
struct SourceView {
    const float* values = nullptr;
    size_t c0 = 0, r0 = 0, w = 0;
    size_t width = 0, height = 0;
    float at(size_t col, size_t row) const { return values[(row - r0) * w + (col - c0)]; }
};
// resample()'s lattice step for this target geometry and map.
int latticeStep(const Raster& target, const TargetToSource& map, int lattice, double maxErrorPx, unsigned threads);
// Target pixels [col0, col0 + w) x [row0, row0 + h) into out (w h, row-major, NaN = nodata). read(c0, r0, c1, r1) is
// asked once, for the source pixels [c0, c1] x [r0, r1] the window's map reaches (not at all when it reaches none:
// every pixel is then nodata), and returns a view holding at least those; sourceWidth x sourceHeight: the whole source.
void resampleWindow(const TargetToSource& map, const Raster& target, int step, size_t col0, size_t row0, size_t w,
                    size_t h, size_t sourceWidth, size_t sourceHeight,
                    const std::function<SourceView(size_t c0, size_t r0, size_t c1, size_t r1)>& read, float* out,
                    unsigned threads);

}  // namespace hc::ingest::detail
