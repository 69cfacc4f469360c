// heightcast/ingest/build.h: the error-bounded bottom-up quadtree build (docs/design.md section 2).
//
// Input: a terrain raster and optional water-depth raster of the same geometry (raster.h).
// Every valid pixel starts as a level-0 cell (size = pixelSizeM). Four sibling cells merge into their
// parent while
//   - all four exist (no hole, not outside the raster) and the parent is no larger than maxLevel;
//   - in every layer, the parent's value (the float32 mean of the four, i.e. the mean of every
//     pixel it covers) lies within toleranceM of every pixel it covers;
//   - for water, in every water step: all four are wet or all four are dry (depth 0), so merges never blur a
//     wet/dry edge of any step, and the step's depth stays within toleranceM too (docs/design.md section 6: one
//     structure for every step).
// Merging by the mean keeps volumes: a cell holds exactly the water its pixels held.
// Guarantee (checked pixel by pixel, reported in Grid::stats): every valid pixel differs from the
// stored value of the cell covering it by at most toleranceM, in every layer. Where the terrain carries
// roundingM (a source finer than float32), elevations are checked, and merged, against the source's
// own values; a level-0 cell can then differ from its pixel by float32's rounding (reported, maybe
// above toleranceM: the grid stores float32).
#pragma once

#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "heightcast/grid/grid.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/ingest/raster.h"

namespace hc::ingest {

// The default of --tolerance [m]: the one place it is set (Options, BuildOptions and hc-ingest's --help use it).
constexpr double kDefaultToleranceM = 0.25;

// The one check of a tolerance [m]: throws hc::Error naming --tolerance unless it is a finite number >= 0. hc-ingest
// checks its options with it before reading anything; the build checks its own with it (a library caller's).
void checkToleranceM(double toleranceM);

struct BuildOptions {
    double toleranceM = kDefaultToleranceM;  // >= 0
    int maxLevel = 0;                        // coarsest cell = pixelSizeM * 2^maxLevel
    unsigned threads = 0;                    // 0 = all cores
    bool progress = false;                   // terminal progress on stderr
    // Optional, not owned: resized to the terrain's width * height and filled with the elevation of the
    // cell covering each pixel (NaN where none), for checks against the source after the build.
    std::vector<float>* cellElevations = nullptr;
};

// Receives the cells of a build in Morton order, in batches.
class CellSink {
public:
    virtual ~CellSink() = default;
    virtual void begin(uint64_t cellCount) = 0;
    virtual void append(std::span<const uint64_t> codes, const std::vector<std::span<const float>>& values) = 0;
    // Under mpirun (docs/design.md section 7) every rank writes its own cells into the sink's file: the sink gives rank
    // 0's writer after begin(), and every rank the file's shape for its GridFilePart. A sink without a file (a grid in
    // memory) is built by one process only.
    virtual GridFileWriter* sharedWriter() { return nullptr; }
    virtual const Grid* fileShape() const { return nullptr; }
    // Under mpirun, on a rank other than 0: its own cells, in order, as it writes them into its part.
    virtual void keepOwn(std::span<const uint64_t> /*codes*/) {}
};

// What a streamed build produced: the grid's shape (geometry, CRS, layers, statistics; no cells)
// and counts.
struct BuildSummary {
    Grid shape;
    uint64_t cellCount = 0;
    std::vector<uint64_t> cellsPerLevel;  // index = level
    uint64_t wetCells = 0;                // of the last step
    std::vector<StepInfo> steps;          // time and wet cells of each water step
    uint64_t stepBytes = 0;               // bytes of the steps' sections (8 per wet cell and step)
};

// The water steps of a scenario, loaded one at a time (a series of rasters need not fit in memory together): step k's
// depth [m] on the terrain's working raster (0 = dry, NaN on the terrain's holes), at timesS[k] (strictly increasing).
struct WaterSteps {
    size_t count = 0;
    std::vector<double> timesS;
    std::function<Raster(size_t k)> load;  // called twice per step: for the structure, then for the values
};

// Builds the grid in memory. The grid's origin is the raster's south-west corner; its CRS the raster's.
// waterDepth, when given, must have the raster's geometry; it becomes layer "water_depth" [m], one step at time 0
// (dry = 0, holes wherever the terrain has one). Fills grid.stats deviations (max over every
// layer, RMS over elevation) and sourceWidth/Height/validPixels/toleranceM.
Grid buildGrid(const Raster& terrain, const Raster* waterDepth, const BuildOptions& options);

// A working raster read window by window (hc-ingest under mpirun: each rank reads only the windows of its share, so
// no rank holds the raster whole; in one process, a raster larger than heldPixelsMax; docs/design.md section 7).
struct RasterWindows {
    Raster shape;        // geometry and CRS; values empty
    std::string source;  // the file, for messages
    // Fills values (and rounding: Raster::roundingM, left empty when float32 holds the source) with the working pixels
    // [col0, col0 + w) x [row0, row0 + h), row 0 the northern-most, row-major. Throws hc::Error. `first`: the window's
    // first read (a build in pieces reads each window twice; what the reader counts, it counts once).
    std::function<void(size_t col0, size_t row0, size_t w, size_t h, std::vector<float>& values,
                       std::vector<float>& rounding, bool first)>
        read;
    // One process without water steps: the most working pixels held at once (0: no limit). A larger raster is built in
    // pieces (runs of share nodes in Morton order), each read for the tiles' roots and again for their cells: the
    // same bytes as the raster held whole, memory about heldPixelsMax pixels.
    uint64_t heldPixelsMax = 0;
    // Water steps read window by window too (none without): their times [s], and readStep, which fills `depth` with
    // step k's depths [m] at the same working pixels as read(), given the terrain's elevations there (`terrain`, as
    // read() gave them). Each window of each step is read twice: for the merge masks (`first`: count what it reports
    // once), then for the cells' depths.
    std::vector<double> stepTimesS;
    std::function<void(size_t k, size_t col0, size_t row0, size_t w, size_t h, const float* terrain,
                       std::vector<float>& depth, bool first)>
        readStep;
    // Or bathtub levels [m], one a step (--water-level), instead of readStep: the builder floods its windows itself,
    // joining the ranks' pieces of each flood across their windows' edges.
    std::vector<double> stepLevelsM;
    // Called on every rank once all have read their windows, before anything is written, with the whole raster's valid
    // pixels (every rank's windows added): throws where the raster read whole would have been refused. May be empty.
    std::function<void(uint64_t validPixels)> checkHeld;
};

// Builds the grid straight into a .hcg file (GridFileWriter): the same cells, bytes identical to
// writeGrid(buildGrid(...)) with the same statistics for one step at time 0, but memory stays at the rasters plus a
// few MB of batch buffers whatever the cell count (with water: plus 8 bytes a cell, and one step's raster at a time).
// `extraStats` supplies source path, CRS name and the seconds spent before the build (the build's own time is added).
BuildSummary buildGridFile(const Raster& terrain, const WaterSteps* steps, const BuildOptions& options,
                           const std::string& path, const IngestStats& extraStats);
// The same for a terrain read window by window (and its water steps, RasterWindows::readStep): the same bytes as the
// rasters read whole.
BuildSummary buildGridFile(const RasterWindows& terrain, const BuildOptions& options, const std::string& path,
                           const IngestStats& extraStats);

}  // namespace hc::ingest
