// heightcast/ingest/ingest.h: raster files (any format GDAL reads, any CRS) -> adaptive grid.
//
// Stages, each a plain function so tools and tests can run them one by one:
//   loadTerrain   read the band (nodata -> NaN, Terrain-RGB decoding, vertical units), then bring it
//                 into a metric, north-up, square-pixel working raster:
//                   projected CRS, square pixels      kept as is (foot units scaled to metres)
//                   geographic CRS                    UTM zone of the raster centre (GeographicLib)
//                   --t_srs                           that CRS, warped by GDAL (bilinear, exact transformer)
//                   no CRS                            local metres, with a warning; degrees (by the
//                                                     extent, or NetCDF units) are taken as WGS 84
//                   longitudes 0..360 / past 180      normalised; split at the antimeridian for --t_srs
//                   non-square, rotated, south-up     resampled / flipped north-up, never mis-placed
//   loadWater     a water depth or water surface raster warped onto the terrain's working raster, or
//                 a bathtub level flood-filled from the domain boundary; one per water step (a series of
//                 rasters or of levels, docs/design.md section 6)
//   buildGrid     the error-bounded quadtree (build.h)
//   (check)       every valid source pixel against the cell covering its centre (LoadReport::sourceCheck)
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "heightcast/grid/grid.h"
#include "heightcast/ingest/build.h"
#include "heightcast/ingest/raster.h"

namespace hc::ingest {

enum class WaterSource { None, Depth, Surface, Level };

// How a flood model's mesh becomes cells: Auto takes a quadtree's faces as they are (a quadtree model's, or a mesh of
// square faces of power-of-two sizes) and samples any other mesh; Cells insists on the faces (refusing a mesh that is
// no quadtree); Sample samples every mesh onto the adaptive grid.
enum class MeshMode { Auto, Cells, Sample };

struct Options {
    std::string input;             // raster path (anything GDAL opens, /vsizip/ and NETCDF:"f.nc":var included)
    int band = 1;                  // 1-based
    bool bandGiven = false;        // --band was given: a 3-band 8-bit image is then read as asked
    std::optional<double> nodata;  // extra nodata value (beside the band's own and NaN)
    bool terrainRgb = false;       // decode h = -10000 + 0.1 * (R * 65536 + G * 256 + B) from bands 1-3
    double zScale = 1.0;           // multiply elevations (e.g. 0.3048 for feet); applied after units
    std::string sourceSrs;         // --s_srs: CRS to assume for the input (overrides its own);
                                   // "local" = metres in a local frame, no CRS (no degree guess)
    std::string targetSrs;         // --t_srs: project into this CRS (GDAL/PROJ) instead of UTM
    double toleranceM = kDefaultToleranceM;  // max |pixel - cell| [m], >= 0
    std::optional<double> minCellM;          // finest cell [m]; default: source pixel size after projection
    std::optional<double> maxCellM;          // coarsest cell [m]; default: largest finest * 2^k <= 96 m
    WaterSource water = WaterSource::None;
    std::string waterPath;                // for Depth and Surface: one step
    double waterLevelM = 0;               // for Level: bathtub water surface elevation [m], one step
    std::vector<std::string> waterPaths;  // for Depth and Surface: a series, one step each (replaces waterPath)
    std::vector<double> waterLevelsM;     // for Level: a series of levels [m], one step each (replaces waterLevelM)
    std::vector<double> timesS;           // time of each step [s], strictly increasing; empty: the step index
    std::vector<int> waterBands;  // band (1-based) of each step's raster, beside waterPaths: a NetCDF time series is
                                  // one file with one band per time (expandWaterTimeSeries); empty: band 1
    std::string terrainVar;       // model results (mesh.h): the bed variable ("" = the format's own: zb, ...)
    std::string waterSurfaceVar;  // model results: the water level over time ("" = the format's own: zs, ...;
                                  // "-" = none, terrain only)
    std::vector<std::string>
        faceLayerVars;  // UGRID meshes: further face variables over time (velocity magnitude, ...),
                        // each a step layer of that name, stored on the wet faces of every step
    // Flood model results (mesh.h, docs/models.md).
    std::string waterMesh;  // --water-mesh: model results whose water levels flood the raster input's terrain
    MeshMode meshMode = MeshMode::Auto;  // --mesh: a model's faces as cells (quadtrees) or sampled onto the grid
    std::optional<double>
        meshToleranceM;          // --mesh-tolerance: how far a quadtree's node may lie from the fitted lattice [m]
    std::string meshSrs;         // --mesh-srs: the CRS of --water-mesh's coordinates (default: the file's own)
    bool samplingGiven = false;  // --tolerance, --min-cell or --max-cell was given: refused for faces taken as cells
    unsigned threads = 0;        // 0 = all cores
    bool progress = false;       // terminal progress on stderr
    // One process, no water: the most memory the working raster may take as float32 [MB] (0 = the default,
    // kDefaultRasterMemoryMB); a larger one is read window by window in pieces, each read twice (same bytes).
    double rasterMemoryMB = 0;
};

constexpr double kDefaultRasterMemoryMB = 256;
// The working pixels one process holds at once (Options::rasterMemoryMB as float32 pixels).
uint64_t heldPixelsMax(const Options& options);

// What the loading stages did, for the tool's summary.
struct LoadReport {
    std::string sourceDescription;  // "384 x 284 px, Int16, 1 band"
    std::string sourceCrsName;      // "WGS 84" or "" if none
    std::string gridCrsName;        // name of the working raster's CRS
    std::string method;             // how it got there ("kept as is", "projected to UTM 32N (GeographicLib), bilinear")
    size_t sourceWidth = 0, sourceHeight = 0;
    std::vector<std::string> warnings;   // things the user should know (no CRS, assumed units, ...)
    uint64_t sourceValidPixels = 0;      // valid pixels of the source as read (before any resampling)
    uint64_t infPixels = 0;              // +-inf pixels taken as nodata (counted in no other figure)
    bool heldInPieces = false;           // the working raster was read in pieces (Options::rasterMemoryMB)
    bool sourcePrecisionDouble = false;  // the source holds more than float32 (Float64, Int32, ...): the
                                         // build checks the tolerance against its own values
    // Every valid source pixel against the cell covering its centre, after the build. Done only when the
    // working raster is not the source itself (projected, warped, resampled by --min-cell or shape);
    // otherwise the build's own pixel-by-pixel check is the check against the source.
    struct SourceCheck {
        bool done = false;
        uint64_t checked = 0;             // valid source pixels whose centre fell on a cell
        uint64_t missed = 0;              // valid source pixels whose centre reached no cell (lost data)
        double maxDevM = 0, rmsDevM = 0;  // |source pixel - covering cell value| over `checked`
    } sourceCheck;
};

// Checks options that need no file (ranges, combinations). Throws hc::Error.
void validateOptions(const Options& options);

// A single water raster that holds a time series (a NetCDF variable with one more dimension than y and x, in CF time
// units, as GDAL reads it: one band per time; docs/design.md section 6) becomes one water step per time: waterPaths and
// waterBands then name each step's band, and timesS holds the file's times in seconds since the units' reference
// (unless times were given: those are kept, with a warning in `report`). Time units that are not CF's take the step
// index as time, with a warning. Any other water raster of several bands is refused (which band is the water?),
// and so is a variable of more than one extra dimension. Returns the steps it made (0: not a time series).
size_t expandWaterTimeSeries(Options& options, LoadReport& report);

Raster loadTerrain(const Options& options, LoadReport& report);
// Depth raster [m] of the terrain's geometry (0 = dry; NaN where terrain is a hole).
// How many water steps the options describe (0 without water).
size_t waterStepCount(const Options& options);
// The time of step k [s]: timesS[k], or k when no times were given.
double waterStepTimeS(const Options& options, size_t k);
// Step k's water (0-based). A series of rasters must agree with its first in size, georeferencing and CRS (checked
// when step k is opened: hc::Error naming both files).
Raster loadWater(const Options& options, const Raster& terrain, LoadReport& report, size_t step = 0);
// Coarsest level for the working raster: --max-cell rounded down to finest * 2^k (default 96 m).
// Throws if --max-cell is below the finest cell.
int chooseMaxLevel(const Options& options, double pixelSizeM, LoadReport& report);
// The build's options (build.h) for a working raster of pixelSizeM [m]: the one place Options map onto them, for
// rasters and for sampled model meshes alike.
BuildOptions buildOptions(const Options& options, double pixelSizeM, LoadReport& report);

// All stages, the grid in memory (tests, small rasters). Throws hc::Error for bad input.
Grid ingest(const Options& options, LoadReport& report);
// All stages, the grid streamed into `path` (the tool's job): peak memory is the working rasters
// plus a few MB, however many cells. Nothing is left at `path` on failure.
BuildSummary ingestToFile(const Options& options, const std::string& path, LoadReport& report);

}  // namespace hc::ingest
