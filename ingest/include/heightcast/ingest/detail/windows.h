// heightcast/ingest/detail/windows.h: the terrain raster read window by window, as the ranks of an MPI run read it
// (docs/design.md: parallel preprocessing). Internal to ingest/: tests may use it (tests/ingest_windows_test.cpp), but
// it is no stable API. No GDAL type appears here.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "heightcast/ingest/ingest.h"
#include "heightcast/ingest/raster.h"

namespace hc::ingest::detail {

// What reading a band found, added over its windows and, under mpirun, over the ranks (plain data: sent as bytes).
struct SourceTally {
    static constexpr size_t kSentinelSlots = 8;
    uint64_t validPixels = 0, infPixels = 0;
    uint64_t sentinels[kSentinelSlots] = {};  // pixels holding each undeclared nodata sentinel (read_source.cpp)
    double maxOther = -HUGE_VAL;              // highest valid elevation that is no sentinel [m]
    void add(const SourceTally& other);
};

// The sums of the check of source pixels against the cells under their centres (LoadReport::sourceCheck), over a part
// of the source: added over the ranks, then finishSourceCheck (ingest.cpp) makes the report's figures.
struct SourceCheckSums {
    uint64_t checked = 0, missed = 0;
    double maxDev = 0, sumSq = 0;
    void add(const SourceCheckSums& o) {
        checked += o.checked, missed += o.missed, sumSq += o.sumSq;
        maxDev = std::max(maxDev, o.maxDev);
    }
    // One valid source pixel (its value in the source's own precision) against the value of the cell under its
    // centre: NaN where no cell is (a hole, outside the working raster), counted as missed.
    void addPixel(double source, float cell) {
        if (std::isnan(cell)) {
            ++missed;
            return;
        }
        const double d = source - cell;
        maxDev = std::max(maxDev, std::abs(d));
        sumSq += d * d;
        ++checked;
    }
};

// The terrain raster read window by window, for ranks that each read only their share of it (docs/design.md section 7).
class TerrainWindows {
public:
    virtual ~TerrainWindows() = default;
    // The working raster's geometry and CRS (values empty).
    virtual const Raster& shape() const = 0;
    // Working pixels [col0, col0 + w) x [row0, row0 + h) (row 0 north) into values (w h, NaN = nodata, metres) and
    // rounding (empty, or w h: Raster::roundingM). `first`: the window's first read; tally() counts only those.
    virtual void read(size_t col0, size_t row0, size_t w, size_t h, std::vector<float>& values,
                      std::vector<float>& rounding, bool first) = 0;
    // What the first reads so far found.
    virtual const SourceTally& tally() const = 0;
    // Once every rank has read its windows, before anything is written: the whole working raster's valid pixels (every
    // rank's windows added). Throws hc::Error where a whole raster's read would have failed on them (a --t_srs warp
    // whose pixel centres miss the data, or whose halves split at 180 degrees land at the map's opposite edges).
    virtual void checkValid(uint64_t validPixels) const { (void)validPixels; }
    // The counts and warnings of the whole raster's tally (every rank's added) into report.
    virtual void finish(const SourceTally& all, LoadReport& report) const = 0;
    // Where the working raster is resampled: after the grid file `gridPath` is written, the check of this rank's share
    // of the source pixels (those tally() counts) against the cells under their centres, read from the file's regions
    // under them; nullopt where the working raster is the source itself (the build's own check is then the one).
    virtual std::optional<SourceCheckSums> checkAgainst(const std::string& gridPath) {
        (void)gridPath;
        return std::nullopt;
    }
};

// Opens opt.input and settles its georeferencing as loadTerrain does, reading no pixel, and returns its window reader:
// the source's own pixels where the working raster is the source as it is (at most mirrored), else the source pixels
// a window's map reaches, resampled on the whole raster's lattice (projected to UTM, rotated, non-square pixels,
// --min-cell). Either way a window holds the same bits as loadTerrain's raster there (tests/ingest_windows_test.cpp).
// A --t_srs source split at 180 degrees warps both its pieces into each window.
std::unique_ptr<TerrainWindows> openTerrainWindows(const Options& opt, LoadReport& report);

}  // namespace hc::ingest::detail
