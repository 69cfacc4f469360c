// bench/bench_render.h: hc-bench's pieces: bench_render.cpp parses the options and runs the scenarios,
// bench_render_run.cpp runs one scenario in a child process, bench_render_report.cpp prints the tables and writes the
// CSV, JSON and plot. What a scenario's child sends back (RunResult) is plain bytes through a pipe.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "heightcast/render/renderer.h"
#include "heightcast/scenes/scenes.h"
#include "heightcast/support/backend_choice.h"

namespace hc::bench {

// Targets (2 cores).
constexpr double kTargetGaussiansPerS = 2e9;  // approximation: kernel evaluations per second
constexpr double kTargetRaycastMs = 250.0;    // ray casting of a 1920 x 1080 frame
constexpr double kTargetRaysPerS = 1920.0 * 1080.0 / (kTargetRaycastMs / 1e3);  // the same as a rate (other sizes)
constexpr double kTargetGlFrameMs = 8.0;  // GL backend on a GPU (issue 5): a whole 1920 x 1080 frame

constexpr int kMaxLevels = 24;  // cells-per-level slots sent back from a child

struct CascadeOut {
    double nearM, farM, texelM, approximationMs;
    uint64_t visibleTexels, gaussians;
    int pyramidLevel;              // -1: no pyramid level fits the cascade (or none was built)
    uint64_t pyramidTexels;        // texels copied from the pyramid
    uint64_t pyramidInterpolated;  // texels interpolated from a coarser pyramid level
    double errorBoundM;            // CascadeStats::errorBoundM: NaN without a pyramid
};

// --trade: one setting's frame (best of the repeats, from scratch) and its error, on one backend.
constexpr int kMaxTradePoints = 32;
struct TradePoint {
    char label[24] = {};     // "0.1 m", "2 px", "default", "--pyramid-coarse", "--texels 512"
    bool gl = false;         // the GL backend, else the CPU
    bool budget = false;     // an error budget in metres (a line in the plot); else a fixed knob or a pixel budget
    bool isDefault = false;  // no option: today's picture
    double maxErrorM = 0, maxErrorPx = 0;                        // the budget asked (0: none)
    double totalMs = 1e300, approximationMs = 0, raycastMs = 0;  // of the fastest repeat
    uint64_t texels = 0;                                         // visible texels over the cascades
    double boundM = 0, boundPx = 0;                              // Timings::errorBoundM, errorBoundPx
    uint64_t checked = 0;                                        // hits checked against the exact surface
    double maxM = 0, p99M = 0, medianM = 0, maxPx = 0;           // their error (render::ErrorCheck)
    double shoreBoundM = 0, shoreM = 0;  // with water: Timings::shoreBoundM, ErrorCheck::shoreDistanceM (0: none)
    char skipped[160] = {};              // why the backend could not render it (the GL driver's limits), or empty
};

// What a scenario's child reports. Plain bytes through a pipe, so trivially copyable.
struct RunResult {
    double extentXM = 0, extentYM = 0, finestM = 0, coarsestM = 0;
    uint64_t cells = 0, wetCells = 0;
    uint64_t cellsPerLevel[kMaxLevels] = {};
    double thresholdM = 0, calibrationS = 0, generationS = 0;
    uint64_t sampleTiles = 0, tiles = 0;
    bool finestRaised = false, finestLowered = false;
    double targetCells = 0;
    // The guard before the lists: their estimated bytes, the render's estimated need (out of core: the lists path's, by
    // bytes a cell), what was available.
    uint64_t listsEstimateBytes = 0, renderNeedBytes = 0, memAvailableBytes = 0;
    bool renderSkipped = false;  // the need exceeded what was available: no lists, no frames
    bool outOfCore = false;      // the grid streamed to a file and rendered from it (--out-of-core, or lists too large)
    bool pyramid = false;        // a surface pyramid was built (--pyramid, or out of core without --out-of-core)
    double listsMs = 0, listMean = 0;
    uint64_t listP99 = 0, listMax = 0, listBytes = 0;
    double camera[6] = {};  // x, y, z (world), yaw, pitch, fov
    int width = 0, height = 0, repeats = 0;
    // Best over the repeats, per stage.
    double fittingMs = 1e300, approximationMs = 1e300, mipmapMs = 1e300, raycastMs = 1e300, shadingMs = 1e300,
           totalMs = 1e300;
    double worstApproximationMs = 0, worstRaycastMs = 0;
    double gpuMs = 1e300, readbackMs = 0;  // GL: best GPU span; one read-back of the frame to host memory
    uint64_t gaussians = 0, rays = 0, hits = 0, wetHits = 0;
    int cascadeCount = 0;
    CascadeOut cascades[4] = {};                         // of the run with the best approximation time
    uint64_t baselineRss = 0, gridRss = 0, peakRss = 0;  // bytes: before generating; after the grid; at the end
    char image[512] = {};                                // the PNG written, or empty
    char device[256] = {};                               // what rendered: "CPU" or the GL renderer and version
    // --fly-frames: means over frames 2..N of a camera flying forward, without and with a CascadeCache.
    double flyApproxFreshMs = 0, flyApproxCachedMs = 0, flyTotalFreshMs = 0, flyTotalCachedMs = 0, flyKept = 0;
    double flyUploadFreshMs = 0, flyUploadCachedMs = 0, flyUploadFreshMB = 0, flyUploadCachedMB = 0;  // GL out of core
    double flyCellsFresh = 0,
           flyCellsCached = 0;  // grid cells the approximation visited per frame (CascadeStats::cellsVisited)
    // --pyramid: the surface pyramid's build time and bytes.
    double pyramidMs = 0;
    uint64_t pyramidBytes = 0;
    // --accuracy: |hit height - exact surface height| over terrain hits of the last frame (walls and water aside) [m].
    uint64_t accuracySamples = 0;
    double accuracyMaxM = 0, accuracyRmsM = 0, accuracyP99M = 0;
    // --trade: every setting on every backend asked (bench_render_trade.cpp).
    char name[64] = {};  // the scenario's, or the grid file's stem
    int tradeCount = 0;
    TradePoint trade[kMaxTradePoints] = {};
};

struct Settings {
    double scale = 1;
    double cells = 0;  // --cells: every scenario's target cell count (0: the report's count / scale)
    int width = 1920, height = 1080, repeat = 3;
    hc::render::RenderOptions options;
    std::string imagesDir;
    bool interactive = false;
    hc::cli::Backend backend = hc::cli::Backend::Cpu;  // Cpu or Gl (Auto is resolved in main)
    int flyFrames = 0;      // after the timed frames: a fly-through of this many frames, fresh and incremental
    double flyStepM = 10;   // metres forward per fly-through frame
    bool pyramid = false;   // build the surface pyramid and render from it (CPU: copies; texel sizes on its ladder)
    bool accuracy = false;  // measure the last frame's hits against the exact surface
    bool outOfCore =
        false;  // write the grid to a file and render from it out of core (render::Scene over a GridRegionReader)
    double memoryGb = 0;  // --memory-gb: what a scenario may hold (0: what the machine has available)
    // --trade: frame time against error over error budgets and fixed knobs, on the backends asked.
    bool trade = false, tradeCpu = false, tradeGl = false;
    size_t tradeSamples = 20000;  // hits checked against the exact surface per frame
};

// Removes the temporary grid files (and their writers' temporaries) of hc-bench runs that were killed: the name holds
// the process id, so a file whose process is gone is stale. Says what it removed.
void removeStaleGrids();

// Where a long run is: on a terminal the one status line, overwritten (the scene, then what it does); in a log a line
// of its own, with the seconds since the scene began where secondsIn >= 0.
void progressLine(bool interactive, const char* scene, const std::string& what, double secondsIn = -1);

// One scenario, generated, prepared and rendered in a forked child (bench_render_run.cpp).
RunResult runScenario(const scenes::Scenario& sc, const Settings& set);

// --trade (bench_render_trade.cpp): the sweep over a scene already built (the child's part); a real grid file with
// its surface pyramid beside it, in a child of its own; the table and the targets; the JSON; the plot.
void tradeSweep(const render::Scene& scene, const render::Camera& camera, const Settings& set, RunResult& r);
RunResult runTradeOnGrid(const std::string& gridPath, const Settings& set);
void printTrade(const std::vector<RunResult>& results, const Settings& set);
void writeTradeJson(const std::vector<RunResult>& results, const Settings& set, const std::string& path);
void writeTradePlot(const std::vector<RunResult>& results, const Settings& set, const std::string& path);

// The tables (grids, rendering, cascades, fly-through, targets) for `results` of `chosen`; the scenarios whose
// rendering was skipped are said so and dropped from both.
void printTables(std::vector<const scenes::Scenario*>& chosen, std::vector<RunResult>& results, const Settings& set,
                 double wallS);
void writeCsv(const std::vector<const scenes::Scenario*>& scs, const std::vector<RunResult>& rs, const Settings& set,
              const std::string& path);
void writeJson(const std::vector<const scenes::Scenario*>& scs, const std::vector<RunResult>& rs, const Settings& set,
               const std::string& path);
// The best stage times as stacked bars with the targets (SVG); sizeText: the run's cells or scale.
void writePlot(const std::vector<const scenes::Scenario*>& chosen, const std::vector<RunResult>& results,
               const Settings& set, const std::string& sizeText, const std::string& path);

}  // namespace hc::bench
