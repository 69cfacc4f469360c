// hc-bench: how fast does the CPU renderer draw the report's four flood scenes, and in how much memory?
//
// The scenes are the report's four flood simulations as synthetic stand-ins with the same extents, cell sizes
// and cell counts, generated deterministically by hc_scenes (bench/scenes/include/heightcast/scenes/scenes.h
// says how: terrain, water, the calibrated quadtree, the camera); --scale divides every cell count (below 1: more
// cells than the report's), --cells asks every scenario for the same count, and the actual count is printed beside
// the target (the table's cell sizes show where the finest size was raised or lowered).
// Each scenario then runs in its own forked child (so getrusage's peak RSS is that scenario's alone, and
// its memory is returned before the next): generate the grid, build the influence lists (sigma 1, R 3.5;
// timed), and render --repeat frames (default 3) at 1920 x 1080 with three 1024^2 cascades from the scene's
// fixed oblique camera over the flood (hc::scenes::floodCamera). Where the lists (~220 B a cell) and a frame would not
// fit the memory available (MemAvailable, or what ulimit -v leaves, or --memory-gb), a scenario runs as the tools do
// by default at such sizes: the grid streamed into a temporary file, its surface pyramid built from it a node at a
// time, the frames rendered out of core (as with --out-of-core --pyramid; at 400 M cells the lists would take 88 GB).
// Nearer the limit the child estimates the lists' size from the generated grid (hc::scenes::estimateInfluenceLists)
// and skips the lists and frames if they would not fit, rather than being killed for memory. Stage times are the best
// over the repeats; Gaussians/s = the cascades' kernel evaluations / approximation time; rays/s = pixels / ray casting
// time.
// Targets on this 2-core machine: approximation >= 2 G Gaussians/s; ray casting of 1920 x 1080 within 250 ms
// (>= 8.29 M rays/s at other sizes).
// Why a program and not a test: the figures depend on the machine; tests never time anything.
#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include "bench_common.h"
#include "svg_plot.h"
#include "heightcast/support/backend_choice.h"
#include "heightcast/support/cli.h"
#include "heightcast/core/error.h"
#include "heightcast/core/heap.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
#include "heightcast/core/rounded.h"
#include "heightcast/core/timer.h"
#include "heightcast/grid/grid.h"
#include "heightcast/influence/influence.h"
#include "heightcast/influence/on_ranks.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/influence/pyramid.h"
#include "heightcast/influence/region.h"
#include "heightcast/influence/surface.h"
#include "heightcast/render/gl/gl_renderer.h"
#include "heightcast/render/image_io.h"
#include "heightcast/render/renderer.h"
#include "heightcast/scenes/scenes.h"

namespace fs = std::filesystem;
using hc::Grid;
using hc::scenes::Scenario;

namespace {

using namespace hc::bench;

// Targets (2 cores).
constexpr double kTargetGaussiansPerS = 2e9;  // approximation: kernel evaluations per second
constexpr double kTargetRaycastMs = 250.0;    // ray casting of a 1920 x 1080 frame
constexpr double kTargetRaysPerS = 1920.0 * 1080.0 / (kTargetRaycastMs / 1e3);  // the same as a rate (other sizes)
constexpr double kTargetGlFrameMs = 8.0;  // GL backend on a GPU (issue 5): a whole 1920 x 1080 frame

constexpr int kMaxLevels = 24;  // cells-per-level slots sent back from a child
// The memory guard before building lists: cells sampled for their estimated size, and what a render holds beside
// the grid and the lists: per cell (the Scene's arrays) and per cascade texel and pixel (the frame's buffers).
// Measured as peak RSS - grid RSS - list bytes of two scenes (Petzenkirchen 1.84 M cells: 240 MB, Marchfeld 7.53 M:
// 386 MB, 1920x1080, 3 x 1024^2; hc-bench --scenarios Petzenkirchen,Marchfeld --repeat 1 --json), solved for the
// two parts (26 B a cell, 193 MB for 5.2 M texels and pixels = 37 B each) and rounded up.
constexpr size_t kListsEstimateSample = 20000;
constexpr double kRenderBytesPerCellBesideLists = 32;
constexpr double kRenderBytesPerTexelOrPixel = 40;

// ---------------- one scenario, in a child ----------------

struct CascadeOut {
    double nearM, farM, texelM, approximationMs;
    uint64_t visibleTexels, gaussians;
    int pyramidLevel;              // -1: no pyramid level fits the cascade (or none was built)
    uint64_t pyramidTexels;        // texels copied from the pyramid
    uint64_t pyramidInterpolated;  // texels interpolated from a coarser pyramid level
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
    // The guard before the lists: their estimated bytes, the render's estimated need, what was available.
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
};

// The rendered error (--accuracy): every terrain hit of the frame (not a wall, no water over it) against the exact
// surface at the hit's position, in parallel; the quantity the issue 13 targets keep "no worse than today's".
// `lists` null: out of core, the exact surface from the cells around the hits, read from `file`.
void measureAccuracy(const hc::render::Frame& f, const Grid& g, const hc::influence::InfluenceLists* lists,
                     const hc::GridRegionReader* file, unsigned threads, RunResult& r) {
    std::vector<std::array<double, 2>> points;
    std::vector<double> heights;
    for (size_t i = 0; i < f.distanceM.size(); ++i) {
        if (!std::isfinite(f.distanceM[i]) || f.wall[i] > 0 || f.waterDepthM[i] > 0) continue;
        points.push_back({double(f.posX[i]), double(f.posY[i])});
        heights.push_back(double(f.posZ[i]));
    }
    const auto layer = hc::influence::Layer::byName(g, "elevation");
    const auto want = lists ? hc::influence::SurfaceEvaluator(g, *lists).values(points, layer, threads)
                            : hc::influence::valuesFromFile(*file, points, layer, {}, threads);
    std::vector<double> errors;
    for (size_t k = 0; k < points.size(); ++k)
        if (want[k]) errors.push_back(std::abs(heights[k] - *want[k]));
    if (errors.empty()) return;
    double sum2 = 0;
    for (double e : errors) sum2 += e * e, r.accuracyMaxM = std::max(r.accuracyMaxM, e);
    r.accuracySamples = errors.size();
    r.accuracyRmsM = std::sqrt(sum2 / double(errors.size()));
    auto p99 = errors.begin() + std::ptrdiff_t(errors.size() * 99 / 100);
    std::nth_element(errors.begin(), p99, errors.end());
    r.accuracyP99M = *p99;
}

double texelsAndPixels(const Settings& set) {
    return double(set.options.cascades) * double(set.options.texelsPerSide) * double(set.options.texelsPerSide) +
           double(set.width) * double(set.height);
}

// The influence lists and a frame beside them, at the lists' typical bytes a cell (influence::kListBytesPerCell) and
// the grid's 16: where they exceed what a scenario may hold, it runs out of core from the start instead of generating a
// grid in memory whose lists would not fit (the exact estimate after generating guards the rest).
double listsPathBytes(const Settings& set, double cells) {
    return cells * (hc::influence::kListBytesPerCell + 16 + kRenderBytesPerCellBesideLists) +
           kRenderBytesPerTexelOrPixel * texelsAndPixels(set);
}
uint64_t memoryForScenario(const Settings& set) {
    return set.memoryGb > 0 ? uint64_t(set.memoryGb * 1e9) : hc::bench::memoryAvailableBytes();
}

// What the tables say of a generated grid.
void recordGrid(const Scenario& sc, const hc::scenes::Calibration& c, const Grid& shape, uint64_t cells,
                uint64_t wetCells, const std::vector<uint64_t>& perLevel, RunResult& r) {
    r.extentXM = hc::scenes::extentXM(sc);
    r.extentYM = hc::scenes::extentYM(sc);
    r.finestM = shape.finestCellM;
    r.coarsestM = shape.levelSizeM(shape.maxLevel);
    r.cells = cells;
    r.wetCells = wetCells;
    for (size_t l = 0; l < perLevel.size() && l < size_t(kMaxLevels); ++l) r.cellsPerLevel[l] = perLevel[l];
    r.thresholdM = c.thresholdM;
    r.calibrationS = c.calibrationS;
    r.sampleTiles = c.sampleTiles;
    r.tiles = c.tiles;
    r.finestRaised = c.finestRaised;
    r.finestLowered = c.finestLowered;
}

RunResult runScenario(const Scenario& sc, const Settings& set) {
    return inChild<RunResult>(sc.name, [&](RunResult& r) {
        auto say = [&](const char* what) {
            if (set.interactive) std::fprintf(stderr, "\r%-14s %-40s", sc.name, what);
        };
        r.baselineRss = hc::currentRssBytes();
        say("generating the grid ...");
        hc::Stopwatch clock;
        r.targetCells = set.cells > 0 ? set.cells : hc::scenes::targetCells(sc, set.scale);
        // Where the lists would not fit, the scenario runs as the tools do by default at such sizes: the grid streamed
        // into a file, the surface pyramid built from it a node at a time, the frames rendered out of core.
        r.memAvailableBytes = memoryForScenario(set);
        r.outOfCore = set.outOfCore || listsPathBytes(set, r.targetCells) > double(r.memAvailableBytes);
        r.pyramid = set.pyramid || (!set.outOfCore && r.outOfCore);
        std::optional<hc::scenes::Generated> gen;  // in memory
        std::unique_ptr<hc::GridRegionReader> file;
        struct RemoveFile {
            fs::path path;
            ~RemoveFile() {
                std::error_code ec;
                if (!path.empty()) fs::remove(path, ec);
            }
        } written;
        double topM = 0;  // the highest terrain or water surface [m]
        if (r.outOfCore) {
            written.path = fs::temp_directory_path() / fmt::format("hc_bench_{}_{}.hcg", sc.name, ::getpid());
            const hc::scenes::GeneratedFile gf =
                hc::scenes::generateToFile(sc, r.targetCells, set.options.threads, written.path.string());
            file = std::make_unique<hc::GridRegionReader>(written.path.string());
            recordGrid(sc, gf, gf.shape, gf.cells, gf.wetCells, gf.cellsPerLevel, r);
            topM = gf.topM;
        } else {
            gen = hc::scenes::generateCells(sc, r.targetCells, set.options.threads);
            const Grid& g = gen->grid;
            if (std::string why = g.validate(); !why.empty()) throw hc::Error("generated grid is invalid: " + why);
            uint64_t wet = 0;
            for (float d : g.values[1]) wet += d > 0;
            recordGrid(sc, *gen, g, g.cellCount(), wet, g.cellsPerLevel(), r);
        }
        r.generationS = clock.lap();
        r.gridRss = hc::currentRssBytes();
        const Grid& g = file ? file->shape() : gen->grid;  // out of core: the shape only, no cells

        std::optional<hc::influence::InfluenceLists> lists;
        if (!file) {
            // Lists that would not fit are not built: the scenario reports its grid and skips the frames.
            r.listsEstimateBytes =
                hc::scenes::estimateInfluenceLists(g, hc::influence::KernelParams{}, kListsEstimateSample).bytes;
            r.renderNeedBytes = r.listsEstimateBytes + uint64_t(kRenderBytesPerCellBesideLists * double(g.cellCount()) +
                                                                kRenderBytesPerTexelOrPixel * texelsAndPixels(set));
            if (r.renderNeedBytes > r.memAvailableBytes) {
                r.renderSkipped = true;
                r.peakRss = hc::peakRssBytes();
                say("");
                return;
            }
            say("building influence lists ...");
            clock.restart();
            lists = hc::influence::buildInfluenceLists(g, hc::influence::KernelParams{}, set.options.threads);
            r.listsMs = clock.milliseconds();
            const auto st = lists->stats();
            r.listMean = st.meanLength;
            r.listP99 = st.p99Length;
            r.listMax = st.maxLength;
            r.listBytes = st.bytes;
        }

        std::optional<hc::influence::SurfacePyramid> pyramid;
        if (r.pyramid) {
            say("building the surface pyramid ...");
            clock.restart();
            // Out of core as hc-influence builds it by default: a node of the file at a time (the same samples).
            pyramid = file ? hc::influence::buildPyramidOnRanks(*file, hc::influence::KernelParams{},
                                                                set.options.threads, false, false)
                           : hc::influence::buildSurfacePyramid(g, hc::influence::KernelParams{}, set.options.threads);
            r.pyramidMs = clock.milliseconds();
            r.pyramidBytes = pyramid->bytes();
        }
        const hc::influence::SurfacePyramid* pyr = pyramid ? &*pyramid : nullptr;
        std::unique_ptr<hc::render::Scene> scenePtr =
            file ? std::make_unique<hc::render::Scene>(*file, hc::influence::KernelParams{}, pyr)
                 : std::make_unique<hc::render::Scene>(g, *lists, pyr);
        hc::render::Scene& scene = *scenePtr;
        if (file) scene.zMax = topM;  // the same view box as in memory (the file's summary bounds it more loosely)
        const hc::render::Camera cam = hc::scenes::floodCamera(sc, g, set.width, set.height);
        r.camera[0] = cam.xWorld, r.camera[1] = cam.yWorld, r.camera[2] = cam.zWorld;
        r.camera[3] = cam.yawDeg, r.camera[4] = cam.pitchDeg, r.camera[5] = cam.fovYDeg;
        r.width = set.width;
        r.height = set.height;
        r.repeats = set.repeat;
        hc::render::Frame frame;
        // The GL backend: a headless context in this child; one unmeasured warm-up frame first, since
        // drivers (llvmpipe among them) compile shaders at their first dispatch.
        std::unique_ptr<hc::render::GlRenderer> gl;
        std::snprintf(r.device, sizeof r.device, "CPU, %u threads", hc::resolveThreads(set.options.threads));
        if (set.backend == hc::cli::Backend::Gl) {
            // Warm-up frames, unmeasured, for at least a second: drivers compile shaders at the first dispatch, and an
            // idle GPU takes a moment to leave its idle clocks (on an H100 the first scene's stages ran 2-3x slower
            // after a single warm-up frame).
            say("GL warm-up frames ...");
            gl = hc::render::GlRenderer::headless(scene);
            std::snprintf(r.device, sizeof r.device, "%s", gl->deviceName().c_str());
            const hc::Stopwatch warmUp;
            do {  // from scratch, as the measured frames below (with texels kept the GPU would hardly work)
                hc::render::Timings warm;
                gl->forgetCascades(), gl->renderToTexture(cam, set.options, warm);
            } while (warmUp.seconds() < 1.0);
        }
        for (int k = 0; k < set.repeat; ++k) {
            say(fmt::format("rendering, frame {} of {} ...", k + 1, set.repeat).c_str());
            hc::render::Timings tm;
            // GL: the measured frames end in the texture, as the viewer draws them; the picture is read back once
            // below. Each from scratch: the renderer would keep the last frame's texels (the same camera: all).
            if (gl)
                gl->forgetCascades(), gl->renderToTexture(cam, set.options, tm);
            else
                frame = hc::render::renderFrame(scene, cam, set.options, tm);
            r.gpuMs = std::min(r.gpuMs, tm.gpuMs);
            r.fittingMs = std::min(r.fittingMs, tm.fittingMs);
            r.mipmapMs = std::min(r.mipmapMs, tm.mipmapMs);
            r.raycastMs = std::min(r.raycastMs, tm.raycastMs);
            r.shadingMs = std::min(r.shadingMs, tm.shadingMs);
            r.totalMs = std::min(r.totalMs, tm.totalMs);
            r.worstApproximationMs = std::max(r.worstApproximationMs, tm.approximationMs);
            r.worstRaycastMs = std::max(r.worstRaycastMs, tm.raycastMs);
            if (tm.approximationMs < r.approximationMs) {
                r.approximationMs = tm.approximationMs;
                r.gaussians = 0;
                r.cascadeCount = int(std::min<size_t>(tm.cascades.size(), 4));
                for (size_t c = 0; c < tm.cascades.size(); ++c) {
                    const auto& cs = tm.cascades[c];
                    r.gaussians += cs.gaussians;
                    if (c < 4)
                        r.cascades[c] = {cs.nearM,           cs.farM,          cs.texelM,
                                         cs.approximationMs, cs.visibleTexels, cs.gaussians,
                                         cs.pyramidLevel,    cs.pyramidTexels, cs.pyramidInterpolated};
                }
            }
            r.rays = tm.rays;
            r.hits = tm.hits;
        }
        if (set.flyFrames > 1) {
            // The camera flies forward (horizontally, along its yaw) flyStepM a frame: every frame evaluated afresh,
            // then the same frames through a CascadeCache (incremental cascades). Means over frames 2..N (the
            // first has nothing to reuse). GL: frames ending in the texture, back to back as a viewer draws them;
            // the renderer keeps the texels on the GPU itself (forgetCascades starts each fresh frame).
            for (int cached = 0; cached < 2; ++cached) {
                hc::render::CascadeCache cache;
                double approx = 0, total = 0, upload = 0;
                uint64_t kept = 0, visible = 0, cells = 0, uploadBytes = 0;
                for (int k = 0; k < set.flyFrames; ++k) {
                    say(fmt::format("fly-through {}, frame {} of {} ...", cached ? "with the cache" : "fresh", k + 1,
                                    set.flyFrames)
                            .c_str());
                    const hc::render::Camera c = hc::render::flightFrame(cam, set.flyStepM, unsigned(k));
                    hc::render::Timings tm;
                    if (gl) {
                        if (!cached || k == 0) gl->forgetCascades();
                        gl->renderToTexture(c, set.options, tm);
                    } else {
                        (void)hc::render::renderFrame(scene, c, set.options, tm, cached ? &cache : nullptr);
                    }
                    if (k == 0) continue;
                    approx += tm.approximationMs, total += tm.totalMs, upload += tm.uploadMs,
                        uploadBytes += tm.uploadBytes;
                    for (const auto& cs : tm.cascades)
                        kept += cs.reusedTexels, visible += cs.visibleTexels, cells += cs.cellsVisited;
                }
                const double frames = set.flyFrames - 1;
                (cached ? r.flyApproxCachedMs : r.flyApproxFreshMs) = approx / frames;
                (cached ? r.flyTotalCachedMs : r.flyTotalFreshMs) = total / frames;
                (cached ? r.flyUploadCachedMs : r.flyUploadFreshMs) = upload / frames;
                (cached ? r.flyUploadCachedMB : r.flyUploadFreshMB) = double(uploadBytes) / 1e6 / frames;
                (cached ? r.flyCellsCached : r.flyCellsFresh) = double(cells) / frames;
                if (cached) r.flyKept = visible ? double(kept) / double(visible) : 0;
            }
        }
        if (gl) {
            say("reading the frame back ...");
            hc::render::Timings tm;
            gl->forgetCascades();  // from scratch, as the measured frames (after a flight it would keep its last
                                   // frame's texels)
            frame = gl->render(cam, set.options, tm);
            r.readbackMs = tm.readbackMs;
        }
        for (size_t i = 0; i < frame.waterDepthM.size(); ++i) r.wetHits += frame.waterDepthM[i] > 0;
        if (set.accuracy) {
            say("measuring hits against the exact surface ...");
            measureAccuracy(frame, g, lists ? &*lists : nullptr, file.get(), set.options.threads, r);
        }
        if (!set.imagesDir.empty()) {
            const std::string path = (fs::path(set.imagesDir) / (std::string(sc.name) + ".png")).string();
            hc::render::writePng(frame, path);
            std::snprintf(r.image, sizeof r.image, "%s", path.c_str());
        }
        r.peakRss = hc::peakRssBytes();
        say("");
    });
}

// ---------------- output ----------------

double mb(uint64_t bytes) { return double(bytes) / 1e6; }

std::string sizesText(const RunResult& r) { return fmt::format("{:g} - {:g}", r.finestM, r.coarsestM); }
std::string extentText(const RunResult& r) {
    return fmt::format("{:.1f} x {:.1f}", r.extentXM / 1e3, r.extentYM / 1e3);
}
double gaussiansPerS(const RunResult& r) { return double(r.gaussians) / (r.approximationMs / 1e3); }
double raysPerS(const RunResult& r) { return double(r.rays) / (r.raycastMs / 1e3); }
bool approximationMet(const RunResult& r) { return gaussiansPerS(r) >= kTargetGaussiansPerS; }
bool glFrameMet(const RunResult& r) { return r.gpuMs < 1e300 && r.totalMs <= kTargetGlFrameMs; }
bool raycastMet(const RunResult& r) {
    return (r.width == 1920 && r.height == 1080) ? r.raycastMs <= kTargetRaycastMs : raysPerS(r) >= kTargetRaysPerS;
}

// JSON numbers as the tables print them (core/rounded.h).
double ms(double v) { return hc::rounded(v, std::chars_format::fixed, 3); }
double sig6(double v) { return hc::rounded(v, std::chars_format::general, 6); }
double fixed1(double v) { return hc::rounded(v, std::chars_format::fixed, 1); }

void writeJson(const std::vector<const Scenario*>& scs, const std::vector<RunResult>& rs, const Settings& set,
               const std::string& path) {
    using Json = nlohmann::ordered_json;  // keys in the order written
    Json all = Json::array();
    for (size_t k = 0; k < rs.size(); ++k) {
        const Scenario& sc = *scs[k];
        const RunResult& r = rs[k];
        Json o;
        o["scenario"] = sc.name;
        o["cells"] = r.cells;
        o["approximation_ms"] = ms(r.approximationMs);
        o["raycast_ms"] = ms(r.raycastMs);
        o["gaussians_per_s"] = sig6(gaussiansPerS(r));
        o["rays_per_s"] = sig6(raysPerS(r));
        o["peak_rss_mb"] = fixed1(mb(r.peakRss));
        o["scale"] = set.scale;
        o["target_cells"] = static_cast<int64_t>(std::nearbyint(r.targetCells));  // ties to even, as the tables
        o["extent_x_m"] = std::llround(r.extentXM);
        o["extent_y_m"] = std::llround(r.extentYM);
        o["finest_m"] = r.finestM;
        o["coarsest_m"] = r.coarsestM;
        o["wet_cells"] = r.wetCells;
        o["threshold_m"] = sig6(r.thresholdM);
        o["generation_s"] = ms(r.generationS);
        o["calibration_s"] = ms(r.calibrationS);
        Json perLevel = Json::array();
        for (int l = 0; l <= int(std::lround(std::log2(r.coarsestM / r.finestM))) && l < kMaxLevels; ++l)
            perLevel.push_back(r.cellsPerLevel[l]);
        o["cells_per_level"] = perLevel;
        o["lists_ms"] = ms(r.listsMs);
        o["list_mean"] = ms(r.listMean);
        o["list_p99"] = r.listP99;
        o["list_max"] = r.listMax;
        o["lists_mb"] = ms(mb(r.listBytes));
        auto degrees = [](double v) { return hc::rounded(v, std::chars_format::fixed, 4); };
        o["camera"] = {{"x", ms(r.camera[0])},
                       {"y", ms(r.camera[1])},
                       {"z", ms(r.camera[2])},
                       {"yaw_deg", degrees(r.camera[3])},
                       {"pitch_deg", degrees(r.camera[4])},
                       {"fov_y_deg", degrees(r.camera[5])}};
        o["width"] = r.width;
        o["height"] = r.height;
        o["cascades_requested"] = set.options.cascades;
        o["texels"] = set.options.texelsPerSide;
        o["repeat"] = r.repeats;
        o["fitting_ms"] = ms(r.fittingMs);
        o["mipmap_ms"] = ms(r.mipmapMs);
        o["shading_ms"] = ms(r.shadingMs);
        o["total_ms"] = ms(r.totalMs);
        o["worst_approximation_ms"] = ms(r.worstApproximationMs);
        o["worst_raycast_ms"] = ms(r.worstRaycastMs);
        o["gaussians"] = r.gaussians;
        o["rays"] = r.rays;
        o["hits"] = r.hits;
        o["water_hits"] = r.wetHits;
        o["backend"] = hc::cli::backendName(set.backend);
        o["device"] = std::string(r.device);
        o["gpu_ms"] = ms(r.gpuMs < 1e300 ? r.gpuMs : 0.0);
        o["readback_ms"] = ms(r.readbackMs);
        if (set.backend == hc::cli::Backend::Gl) o["gl_frame_target"] = glFrameMet(r) ? "met" : "MISSED";
        Json cascades = Json::array();
        for (int c = 0; c < r.cascadeCount; ++c) {
            const CascadeOut& cs = r.cascades[c];
            cascades.push_back({{"near_m", ms(cs.nearM)},
                                {"far_m", ms(cs.farM)},
                                {"texel_m", sig6(cs.texelM)},
                                {"visible_texels", cs.visibleTexels},
                                {"gaussians", cs.gaussians},
                                {"approximation_ms", ms(cs.approximationMs)},
                                {"pyramid_level", cs.pyramidLevel},
                                {"pyramid_texels", cs.pyramidTexels},
                                {"pyramid_interpolated", cs.pyramidInterpolated}});
        }
        o["cascades"] = cascades;
        o["report_gtx1080_approximation_ms"] = sc.gpuApproxMs;
        o["report_gtx1080_raycast_ms"] = sc.gpuRaycastMs;
        o["baseline_rss_mb"] = fixed1(mb(r.baselineRss));
        o["grid_rss_mb"] = fixed1(mb(r.gridRss));
        o["approximation_target"] = approximationMet(r) ? "met" : "MISSED";
        o["raycast_target"] = raycastMet(r) ? "met" : "MISSED";
        if (r.image[0]) o["image"] = std::string(r.image);
        o["out_of_core"] = r.outOfCore;
        if (r.pyramid) {
            o["pyramid_ms"] = ms(r.pyramidMs);
            o["pyramid_mb"] = ms(mb(r.pyramidBytes));
        }
        if (set.accuracy) {
            o["accuracy_samples"] = r.accuracySamples;
            o["accuracy_max_m"] = sig6(r.accuracyMaxM);
            o["accuracy_p99_m"] = sig6(r.accuracyP99M);
            o["accuracy_rms_m"] = sig6(r.accuracyRmsM);
        }
        if (set.flyFrames > 1) {
            o["fly_frames"] = set.flyFrames;
            o["fly_step_m"] = set.flyStepM;
            o["fly_approximation_ms_fresh"] = ms(r.flyApproxFreshMs);
            o["fly_approximation_ms_cached"] = ms(r.flyApproxCachedMs);
            o["fly_total_ms_fresh"] = ms(r.flyTotalFreshMs);
            o["fly_total_ms_cached"] = ms(r.flyTotalCachedMs);
            o["fly_texels_kept"] = hc::rounded(r.flyKept, std::chars_format::fixed, 4);
            o["fly_upload_ms_fresh"] = ms(r.flyUploadFreshMs);
            o["fly_upload_ms_cached"] = ms(r.flyUploadCachedMs);
            o["fly_upload_mb_fresh"] = sig6(r.flyUploadFreshMB);
            o["fly_upload_mb_cached"] = sig6(r.flyUploadCachedMB);
            o["fly_cells_visited_fresh"] = std::llround(r.flyCellsFresh);
            o["fly_cells_visited_cached"] = std::llround(r.flyCellsCached);
        }
        all.push_back(std::move(o));
    }
    std::ofstream f(path);
    if (!f) throw hc::Error(path + ": cannot open for writing (--json)");
    // Device names and paths are outside text: bytes that are not UTF-8 become U+FFFD rather than an exception.
    f << all.dump(2, ' ', false, Json::error_handler_t::replace) << "\n";
    if (!f.flush()) throw hc::Error(path + ": write failed (--json)");
}

void writeCsv(const std::vector<const Scenario*>& scs, const std::vector<RunResult>& rs, const Settings& set,
              const std::string& path) {
    std::ofstream f(path);
    if (!f) throw hc::Error(path + ": cannot open for writing (--csv)");
    f << "scenario,scale,extent_x_m,extent_y_m,finest_m,coarsest_m,target_cells,cells,wet_cells,threshold_m,generation_"
         "s,lists_ms,list_mean,"
         "lists_mb,width,height,cascades,texels,fitting_ms,approximation_ms,mipmap_ms,raycast_ms,shading_ms,total_ms,"
         "gaussians,"
         "gaussians_per_s,rays,rays_per_s,peak_rss_mb,gtx1080_approximation_ms,gtx1080_raycast_ms,approximation_target,"
         "raycast_target,"
         "gpu_ms,readback_ms\n";
    for (size_t k = 0; k < rs.size(); ++k) {
        const Scenario& sc = *scs[k];
        const RunResult& r = rs[k];
        f << fmt::format(
            "{},{:g},{:.0f},{:.0f},{:g},{:g},{:.0f},{},{},{:.6g},{:.3f},{:.3f},{:.3f},{:.3f},{},{},{},{},{:.3f},{:.3f},"
            "{:.3f},{:.3f},{:.3f},{:.3f},{},{:.6g},{},{:.6g},"
            "{:.1f},{:.1f},{:.1f},{},{},{:.3f},{:.3f}\n",
            sc.name, set.scale, r.extentXM, r.extentYM, r.finestM, r.coarsestM, r.targetCells, r.cells, r.wetCells,
            r.thresholdM, r.generationS, r.listsMs, r.listMean, mb(r.listBytes), r.width, r.height,
            set.options.cascades, set.options.texelsPerSide, r.fittingMs, r.approximationMs, r.mipmapMs, r.raycastMs,
            r.shadingMs, r.totalMs, r.gaussians, gaussiansPerS(r), r.rays, raysPerS(r), mb(r.peakRss), sc.gpuApproxMs,
            sc.gpuRaycastMs, approximationMet(r) ? "met" : "MISSED", raycastMet(r) ? "met" : "MISSED",
            r.gpuMs < 1e300 ? r.gpuMs : 0.0, r.readbackMs);
    }
    if (!f.flush()) throw hc::Error(path + ": write failed (--csv)");
}

}  // namespace

int main(int argc, char** argv) {
    hc::keepFreedMemory();  // frames reuse the last one's pages, as in hc-view and hc-render's flights (core/heap.h)
    return hc::cli::run("hc-bench", [&] {
        Settings set;
        std::string size = "1920x1080", scenarios = "Marchfeld,Petzenkirchen,Wachau,Florence", csv, json, plot,
                    backendText = "cpu";
        hc::cli::Parser p(
            "hc-bench", "[options]",
            "Benchmarks the CPU renderer on synthetic stand-ins for the technical report's four flood scenes\n"
            "(Marchfeld 82.9 x 57.1 km, 3-96 m cells, 7.46 M cells; Petzenkirchen 15.4 x 16.0 km, 0.75-96 m, 1.81 M;\n"
            "Wachau 24.1 x 16.5 km, 3-96 m, 1.95 M; Florence 44.6 x 28.2 km, 3-96 m, 4.53 M): terrain with a "
            "meandering\n"
            "river valley and a flood (water_depth), generated deterministically as an adaptive quadtree with about\n"
            "the report's cell count. Each scenario runs in its own process: generate, build the influence lists\n"
            "(sigma 1, R 3.5), render --repeat frames from a fixed oblique camera over the flood; it prints the best\n"
            "stage times beside the report's GTX 1080 times, Gaussians/s, rays/s and peak RSS, then checks the\n"
            "targets (approximation >= 2 G Gaussians/s; ray casting of 1920x1080 within 250 ms). MB = 10^6 bytes.");
        p.option(
            "--scale", "F",
            "divide every scenario's cell count by F > 0; below 1 asks for more cells than the report's\n"
            "      (the refinement threshold follows; the finest size doubles where the forced wet-edge and bank cells "
            "alone\n"
            "      exceed the count, and halves where the domain holds fewer than 1.5 x the count at it) (default 1)",
            set.scale);
        p.option("--cells", "N",
                 "every scenario's target cell count instead (e.g. 1e8; scenarios whose influence lists and\n"
                 "      frame would not fit in the memory available are generated but not rendered, and say so)\n"
                 "      (default: the report's count / --scale)",
                 set.cells);
        p.option("--scenarios", "LIST",
                 "comma-separated subset, in the order given (default Marchfeld,Petzenkirchen,Wachau,Florence)",
                 scenarios);
        p.option("--size", "WxH", "image size in pixels (default 1920x1080)", size);
        p.option("--cascades", "K", "cascades per frame, 1..4 (default 3)", set.options.cascades);
        p.option("--texels", "N", "texels per cascade side, 16..8192 (default 1024)", set.options.texelsPerSide);
        p.option("--repeat", "N", "frames rendered per scenario; each stage's time is the best frame's (default 3)",
                 set.repeat);
        p.option("--threads", "N", "worker threads for generation, lists and rendering (default 0 = all cores)",
                 set.options.threads);
        p.option("--images", "DIR",
                 "also write each scenario's last frame as DIR/SCENARIO.png; DIR is created if missing\n"
                 "      (default: none)",
                 set.imagesDir);
        p.option("--backend", "B",
                 "cpu or gl: the OpenGL 4.3 compute backend in a headless context, stage times from GPU timer\n"
                 "      queries, after one unmeasured warm-up frame (default cpu)",
                 backendText);
        p.option("--csv", "OUT.csv", "also write one row per scenario as CSV with a header line (default: none)", csv);
        p.option("--json", "OUT.json",
                 "also write a JSON array, one object per scenario (scenario, cells, approximation_ms,\n"
                 "      raycast_ms, gaussians_per_s, rays_per_s, peak_rss_mb, and more) (default: none)",
                 json);
        p.option("--fly-frames", "N",
                 "after the timed frames, fly the camera forward for N frames, each evaluated afresh and\n"
                 "      then with incremental cascades (texels kept from the last frame); prints both (default 0: "
                 "off). GL:\n"
                 "      frames back to back into the texture, the texels kept on the GPU (in memory and --out-of-core)",
                 set.flyFrames);
        p.option("--fly-step", "M", "metres the camera moves forward per fly-through frame (default 10)", set.flyStepM);
        p.flag("--pyramid",
               "also build the surface pyramid (hc-influence's .hcp, docs/design.md section 4) and render from it:\n"
               "      texel sizes on its ladder (powers of two of the finest cell), texels it holds copied (CPU)",
               set.pyramid);
        p.flag("--pyramid-coarse",
               "with --pyramid: texels up to 2x coarser than without it (N a side) instead of up to\n"
               "      2x finer (up to 2N a side)",
               set.options.pyramidCoarseTexels);
        p.option("--pyramid-interpolate", "L",
                 "with --pyramid: texels finer than every level stored around them interpolated\n"
                 "      (bicubic) from a coarser stored level, at most L levels up; 0 sums them from the kernels "
                 "(default 3)",
                 set.options.pyramidInterpolateLevels);
        p.option("--beam-tile", "P",
                 "ray casting, both backends: tiles of P x P pixels march their beam first and start their rays'\n"
                 "      walks there (the same hits); 0 walks every ray from its cascade's start (default 4)",
                 set.options.beamTilePx);
        p.flag(
            "--out-of-core",
            "stream each grid into a temporary .hcg and render out of core from it, without lists\n"
            "      (render::Scene over a GridRegionReader; with --pyramid the texels it holds need no cell; GL: the\n"
            "      texels a frame newly sees evaluated on the CPU, the cascades kept on the GPU, the mipmaps, ray\n"
            "      casting and shading there)",
            set.outOfCore);
        p.option("--memory-gb", "G",
                 "memory a scenario may hold [GB]; where its influence lists (~220 B a cell) and frame would\n"
                 "      not fit, it runs as --out-of-core --pyramid (default: what the machine has available,\n"
                 "      MemAvailable or what ulimit -v leaves)",
                 set.memoryGb);
        p.flag("--accuracy",
               "measure the last frame's terrain hits against the exact surface: max, p99 and RMS of\n"
               "      |hit height - exact height| [m] (walls and water aside)",
               set.accuracy);
        p.option("--plot", "OUT.svg",
                 "also draw each scenario's best stage times as stacked bars with the targets, SVG\n"
                 "      (default: none)",
                 plot);
        if (!p.parse(argc, argv)) return 0;
        if (!(set.scale > 0) || !std::isfinite(set.scale))
            throw hc::Error("--scale " + fmt::format("{:g}", set.scale) + ": must be a number > 0");
        if (!(set.cells >= 0) || !std::isfinite(set.cells) || (set.cells > 0 && set.cells < 1000) || set.cells >= 4e9)
            throw hc::Error("--cells " + fmt::format("{:g}", set.cells) +
                            ": must be a count in 1000 .. 4e9 (a grid holds fewer than 2^32 cells)");
        if (set.cells > 0 && set.scale != 1) throw hc::Error("--cells and --scale: give one of them");
        if (!(set.memoryGb >= 0) || !std::isfinite(set.memoryGb))
            throw hc::Error("--memory-gb " + fmt::format("{:g}", set.memoryGb) +
                            ": must be a number of GB, >= 0 (0: what is available)");
        if (set.repeat < 1) throw hc::Error("--repeat " + std::to_string(set.repeat) + ": must be at least 1");
        set.backend = hc::cli::parseBackend(backendText);
        if (set.backend == hc::cli::Backend::Auto)
            throw hc::Error("--backend auto: a benchmark names its backend, cpu or gl");
        if (set.flyFrames < 0 || set.flyFrames == 1)
            throw hc::Error("--fly-frames " + std::to_string(set.flyFrames) + ": 0 (off) or at least 2");
        if (!(set.flyStepM >= 0) || !std::isfinite(set.flyStepM))
            throw hc::Error("--fly-step " + fmt::format("{:g}", set.flyStepM) + ": metres >= 0");
        if (std::string why = set.options.validate(); !why.empty()) throw hc::Error(why);
        {
            auto x = size.find('x');
            if (x == std::string::npos) throw hc::Error("--size " + size + ": expected WxH, e.g. 1920x1080");
            const double w = hc::cli::parseNumber(size.substr(0, x), "--size"),
                         h = hc::cli::parseNumber(size.substr(x + 1), "--size");
            if (w != std::floor(w) || h != std::floor(h) || w < 1 || h < 1 || w > 16384 || h > 16384)
                throw hc::Error("--size " + size + ": width and height must be whole numbers in 1..16384");
            set.width = int(w), set.height = int(h);
        }
        std::vector<const Scenario*> chosen;
        for (const std::string& name : splitList(scenarios, "--scenarios")) {
            const Scenario* found = hc::scenes::findScenario(name);
            if (!found)
                throw hc::Error("--scenarios " + name +
                                ": not a scenario (Marchfeld, Petzenkirchen, Wachau or Florence)");
            chosen.push_back(found);
        }
        for (const std::string* o : {&csv, &json, &plot})
            if (!o->empty()) hc::cli::checkWritable(*o, o == &csv ? "--csv" : o == &json ? "--json" : "--plot");
        if (!set.imagesDir.empty()) {
            std::error_code ec;
            fs::create_directories(set.imagesDir, ec);
            if (!fs::is_directory(set.imagesDir))
                throw hc::Error(set.imagesDir + ": cannot create the image folder (--images)");
        }
        set.interactive = isatty(STDERR_FILENO);
        const unsigned threads = hc::resolveThreads(set.options.threads);

        const std::string sizeText =
            set.cells > 0 ? fmt::format("{:g} cells each", set.cells) : fmt::format("scale {:g}", set.scale);
        std::printf(
            "hc-bench: %u worker thread%s (hardware threads: %u), %s, %dx%d, %d cascade%s of %d^2 texels, best of %d\n",
            threads, threads == 1 ? "" : "s", std::thread::hardware_concurrency(), sizeText.c_str(), set.width,
            set.height, set.options.cascades, set.options.cascades == 1 ? "" : "s", set.options.texelsPerSide,
            set.repeat);
        std::printf("load average (1 min) at start: %s\n", loadAverage().c_str());
        const hc::Stopwatch wall;
        std::vector<RunResult> results;
        for (const Scenario* sc : chosen) results.push_back(runScenario(*sc, set));
        if (set.interactive) std::fprintf(stderr, "\r%60s\r", "");
        const double wallS = wall.seconds();

        // ---- table 1: the grids ----
        std::printf(
            "\n1. grids: synthetic, deterministic; extent rounded to whole 96 m cells; target = the report's cells / "
            "scale;\n"
            "T = calibrated refinement threshold [m]; wet = cells with water; calib s = finding T, build s = building "
            "the\n"
            "grid (neither is part of a frame); lists = buildInfluenceLists (sigma 1, R 3.5, all threads, one run): "
            "time,\n"
            "mean / p99 / max entries per cell, offsets + indices\n\n");
        std::printf("%-14s %13s %10s %10s %10s %7s %8s %6s %7s %7s %9s %6s %5s %5s %8s\n", "scenario", "extents km",
                    "cells m", "target", "cells", "diff %", "T m", "wet %", "calib s", "build s", "lists ms", "mean",
                    "p99", "max", "lists MB");
        for (size_t k = 0; k < results.size(); ++k) {
            const RunResult& r = results[k];
            const double target = r.targetCells;
            std::printf("%-14s %13s %10s %10.0f %10llu %+7.1f %8.3g %6.1f %7.1f %7.1f %9.1f %6.1f %5llu %5llu %8.1f\n",
                        chosen[k]->name, extentText(r).c_str(), sizesText(r).c_str(), target,
                        (unsigned long long)r.cells, (double(r.cells) / target - 1) * 100, r.thresholdM,
                        100.0 * double(r.wetCells) / double(r.cells), r.calibrationS, r.generationS - r.calibrationS,
                        r.listsMs, r.listMean, (unsigned long long)r.listP99, (unsigned long long)r.listMax,
                        mb(r.listBytes));
        }
        for (size_t k = 0; k < results.size(); ++k) {
            const RunResult& r = results[k];
            std::string counts;
            const int levels = int(std::lround(std::log2(r.coarsestM / r.finestM)));
            for (int l = 0; l <= levels && l < kMaxLevels; ++l)
                counts += fmt::format("{}{:g} m: {}", l ? ", " : "", r.finestM * double(1 << l), r.cellsPerLevel[l]);
            std::printf("%-14s cells per size: %s%s\n", chosen[k]->name, counts.c_str(),
                        r.finestRaised    ? " (finest size raised: the forced cells alone exceeded the scaled count)"
                        : r.finestLowered ? " (finest size lowered: the domain held too few cells at the scenario's)"
                                          : "");
            if (r.outOfCore && !set.outOfCore)
                std::printf(
                    "%-14s out of core: lists and frame ~%.1f GB (%.0f B a cell) would not fit %.1f GB available; the "
                    "grid was\n%-14s streamed into a file, its surface pyramid built a node at a time and the frames "
                    "rendered from the file,\n%-14s as hc-influence and hc-render do by default at this size\n",
                    chosen[k]->name, listsPathBytes(set, r.targetCells) / 1e9, hc::influence::kListBytesPerCell,
                    double(r.memAvailableBytes) / 1e9, "", "");
        }
        // Scenarios whose lists and frame would not fit were generated only: said here, left out of what follows.
        {
            std::vector<const Scenario*> renderedScenarios;
            std::vector<RunResult> rendered;
            for (size_t k = 0; k < results.size(); ++k) {
                const RunResult& r = results[k];
                if (!r.renderSkipped) {
                    renderedScenarios.push_back(chosen[k]);
                    rendered.push_back(r);
                    continue;
                }
                std::printf(
                    "%-14s RENDERING SKIPPED: influence lists ~%.1f GB (estimated) + frame ~%.1f GB need %.1f GB; %.1f "
                    "GB available"
                    " (MemAvailable, what ulimit -v leaves or --memory-gb); grid generated in %.1f s, peak RSS %.0f "
                    "MB\n",
                    chosen[k]->name, double(r.listsEstimateBytes) / 1e9,
                    double(r.renderNeedBytes - r.listsEstimateBytes) / 1e9, double(r.renderNeedBytes) / 1e9,
                    double(r.memAvailableBytes) / 1e9, r.generationS, mb(r.peakRss));
            }
            chosen = std::move(renderedScenarios);
            results = std::move(rendered);
        }

        // ---- table 2: the renderer, in the report's form ----
        std::printf(
            "\n2. rendering with the %s backend (%s): %dx%d, %d cascade%s of %d^2 texels, best of %d frames per stage "
            "(worst in brackets); camera 1.5 km\n"
            "above the river 10 %% downstream, looking along it, pitch -20, fov 50; G Gauss/s = kernel evaluations in\n"
            "the approximation / its time; M rays/s = pixels / ray casting time; peak RSS = the scenario's process\n"
            "(getrusage) at the end; GTX 1080 = the report's times for the real data\n\n",
            hc::cli::backendName(set.backend), results.empty() ? "-" : results[0].device, set.width, set.height,
            set.options.cascades, set.options.cascades == 1 ? "" : "s", set.options.texelsPerSide, set.repeat);
        std::printf("%-14s %13s %10s %7s %19s %19s %8s %7s %8s %8s %11s %10s %8s %11s %11s\n", "scenario", "extents km",
                    "cells m", "cells M", "approximation ms", "ray casting ms", "fit ms", "mip ms", "shade ms",
                    "total ms", "G Gauss/s", "M rays/s", "peak MB", "GTX appr ms", "GTX ray ms");
        for (size_t k = 0; k < results.size(); ++k) {
            const RunResult& r = results[k];
            std::printf(
                "%-14s %13s %10s %7.2f %8.1f (%8.1f) %8.1f (%8.1f) %8.2f %7.1f %8.1f %8.1f %11.3f %10.2f %8.0f %11.1f "
                "%11.1f\n",
                chosen[k]->name, extentText(r).c_str(), sizesText(r).c_str(), double(r.cells) / 1e6, r.approximationMs,
                r.worstApproximationMs, r.raycastMs, r.worstRaycastMs, r.fittingMs, r.mipmapMs, r.shadingMs, r.totalMs,
                gaussiansPerS(r) / 1e9, raysPerS(r) / 1e6, mb(r.peakRss), chosen[k]->gpuApproxMs,
                chosen[k]->gpuRaycastMs);
        }
        if (set.backend == hc::cli::Backend::Gl) {
            std::printf(
                "\nGL frames: total = wall time of a frame ending in the texture, as hc-view draws it (fitting and "
                "visible spans on\n"
                "the CPU, uploads, the GPU's stages, waiting for its timers); GPU = its span from the first stage's "
                "start to\n"
                "shading's end; read back = copying one finished frame to host memory (hc-render's path, not the "
                "viewer's)\n");
            for (size_t k = 0; k < results.size(); ++k)
                std::printf("  %-14s total %7.2f ms   GPU %7.2f ms   CPU and waiting %7.2f ms   read back %7.2f ms\n",
                            chosen[k]->name, results[k].totalMs, results[k].gpuMs,
                            results[k].totalMs - results[k].gpuMs, results[k].readbackMs);
        }
        std::printf(
            "\ncascades (best approximation frame): offsets along the view [m], texel [m], visible texels, Gaussians, "
            "ms\n");
        for (size_t k = 0; k < results.size(); ++k) {
            const RunResult& r = results[k];
            for (int c = 0; c < r.cascadeCount; ++c) {
                const CascadeOut& cs = r.cascades[c];
                std::printf("  %-14s %d  %8.0f..%-8.0f %8.3g %9llu %11llu %8.1f", chosen[k]->name, c, cs.nearM, cs.farM,
                            cs.texelM, (unsigned long long)cs.visibleTexels, (unsigned long long)cs.gaussians,
                            cs.approximationMs);
                if (cs.pyramidLevel >= 0)
                    std::printf("   %llu copied from pyramid level %d", (unsigned long long)cs.pyramidTexels,
                                cs.pyramidLevel);
                if (cs.pyramidInterpolated)
                    std::printf(", %llu interpolated", (unsigned long long)cs.pyramidInterpolated);
                std::printf("\n");
            }
            if (r.pyramid)
                std::printf(
                    "  %-14s    surface pyramid built in %.1f s (not part of a frame), %.1f MB = %.1f bytes per cell\n",
                    chosen[k]->name, r.pyramidMs / 1e3, mb(r.pyramidBytes), double(r.pyramidBytes) / double(r.cells));
            if (set.accuracy)
                std::printf(
                    "  %-14s    rendered error (terrain hits vs exact surface, %llu hits): max %.3g m, p99 %.3g m, RMS "
                    "%.3g m\n",
                    chosen[k]->name, (unsigned long long)r.accuracySamples, r.accuracyMaxM, r.accuracyP99M,
                    r.accuracyRmsM);
            std::printf("  %-14s    hits %.1f %% of pixels, water %.1f %%; camera %.0f, %.0f, %.0f yaw %.1f\n",
                        chosen[k]->name, 100.0 * double(r.hits) / double(r.rays),
                        100.0 * double(r.wetHits) / double(r.rays), r.camera[0], r.camera[1], r.camera[2], r.camera[3]);
        }

        if (set.flyFrames > 1) {
            std::printf(
                "\nincremental cascades: the camera flies forward %g m a frame for %d frames; means over frames "
                "2..%d,\n"
                "every frame evaluated afresh against frames through a CascadeCache (texels kept from the last "
                "frame);\n"
                "cells = grid cells the approximation visited per frame\n\n",
                set.flyStepM, set.flyFrames, set.flyFrames);
            std::printf("%-14s %16s %16s %6s %14s %14s %14s %12s %12s\n", "scenario", "approx ms fresh",
                        "approx ms cache", "x", "frame ms fresh", "frame ms cache", "texels kept %", "cells fresh",
                        "cells cache");
            for (size_t k = 0; k < results.size(); ++k) {
                const RunResult& r = results[k];
                std::printf("%-14s %16.1f %16.1f %6.1f %14.1f %14.1f %14.1f %12.0f %12.0f\n", chosen[k]->name,
                            r.flyApproxFreshMs, r.flyApproxCachedMs,
                            r.flyApproxCachedMs > 0 ? r.flyApproxFreshMs / r.flyApproxCachedMs : 0.0, r.flyTotalFreshMs,
                            r.flyTotalCachedMs, 100 * r.flyKept, r.flyCellsFresh, r.flyCellsCached);
            }
            bool uploads = false;
            for (const RunResult& r : results) uploads = uploads || r.flyUploadFreshMB > 0;
            if (uploads) {  // the GL backend: the cascades' rows and (out of core) the texels the CPU evaluated
                            // (Timings::uploadMs)
                std::printf("\n%-14s %16s %16s %16s %16s\n", "GL upload", "ms fresh", "ms cache", "MB fresh",
                            "MB cache");
                for (size_t k = 0; k < results.size(); ++k) {
                    const RunResult& r = results[k];
                    std::printf("%-14s %16.2f %16.2f %16.2f %16.3f\n", chosen[k]->name, r.flyUploadFreshMs,
                                r.flyUploadCachedMs, r.flyUploadFreshMB, r.flyUploadCachedMB);
                }
            }
        }

        // ---- targets ----
        const bool glRun = set.backend == hc::cli::Backend::Gl;
        std::printf("\ntargets%s\n", glRun ? "" : " (2 cores)");
        if (glRun) {
            std::printf("  GL whole frame (issue 5, on a GPU): 1920x1080, 3 x 1024^2 cascades, within %.0f ms%s\n",
                        kTargetGlFrameMs, set.width == 1920 && set.height == 1080 ? "" : " (this run is another size)");
            for (size_t k = 0; k < results.size(); ++k)
                std::printf("    %-14s %8.2f ms   %s\n", chosen[k]->name, results[k].totalMs,
                            glFrameMet(results[k]) ? "met" : "MISSED");
        }
        std::printf("  approximation: >= %.0f G Gaussians/s\n", kTargetGaussiansPerS / 1e9);
        for (size_t k = 0; k < results.size(); ++k)
            std::printf("    %-14s %7.3f G Gaussians/s (%5.1f %% of the target), %8.1f ms vs GTX 1080 %5.1f ms   %s\n",
                        chosen[k]->name, gaussiansPerS(results[k]) / 1e9,
                        100 * gaussiansPerS(results[k]) / kTargetGaussiansPerS, results[k].approximationMs,
                        chosen[k]->gpuApproxMs, approximationMet(results[k]) ? "met" : "MISSED");
        if (set.width == 1920 && set.height == 1080)
            std::printf("  ray casting: 1920x1080 within %.0f ms\n", kTargetRaycastMs);
        else
            std::printf("  ray casting: >= %.2f M rays/s (1920x1080 within %.0f ms; this run is %dx%d)\n",
                        kTargetRaysPerS / 1e6, kTargetRaycastMs, set.width, set.height);
        for (size_t k = 0; k < results.size(); ++k)
            std::printf("    %-14s %8.1f ms, %6.2f M rays/s (%5.1f %% of the target rate), vs GTX 1080 %4.1f ms   %s\n",
                        chosen[k]->name, results[k].raycastMs, raysPerS(results[k]) / 1e6,
                        100 * raysPerS(results[k]) / kTargetRaysPerS, chosen[k]->gpuRaycastMs,
                        raycastMet(results[k]) ? "met" : "MISSED");

        for (size_t k = 0; k < results.size(); ++k)
            if (results[k].image[0]) std::printf("\nimage: %s", results[k].image);
        std::printf("%swall time %.1f s; load average (1 min) at the end: %s\n", set.imagesDir.empty() ? "\n" : "\n\n",
                    wallS, loadAverage().c_str());
        if (!csv.empty()) {
            writeCsv(chosen, results, set, csv);
            std::printf("rows written to %s\n", csv.c_str());
        }
        if (!json.empty()) {
            writeJson(chosen, results, set, json);
            std::printf("objects written to %s\n", json.c_str());
        }
        if (!plot.empty()) {
            const bool gl = set.backend == hc::cli::Backend::Gl;
            hc::bench::BarPlot bp;
            bp.title = std::string("hc-bench, ") + (gl ? "GL" : "CPU") + " backend: best stage times of a " +
                       std::to_string(set.width) + "x" + std::to_string(set.height) + " frame, " +
                       std::to_string(set.options.cascades) + " cascades of " +
                       std::to_string(set.options.texelsPerSide) + "^2" +
                       (set.cells > 0 || set.scale != 1 ? ", " + sizeText : "");
            bp.xLabel = "milliseconds";
            // Ray casting first, so its bar ends where the ray casting target's line can meet it.
            bp.segmentNames = {"ray casting", "approximation", "mipmaps", "shading", "fitting"};
            for (size_t k = 0; k < results.size(); ++k) {
                const RunResult& r = results[k];
                if (r.totalMs >= 1e300) continue;  // the scenario failed
                bp.rows.push_back(
                    {chosen[k]->name, {r.raycastMs, r.approximationMs, r.mipmapMs, r.shadingMs, r.fittingMs}});
            }
            if (gl)
                bp.markers.push_back(
                    {"whole-frame target " + fmt::format("{:g}", kTargetGlFrameMs) + " ms", kTargetGlFrameMs});
            else if (set.width == 1920 && set.height == 1080)
                bp.markers.push_back(
                    {"ray casting target " + fmt::format("{:g}", kTargetRaycastMs) + " ms (first segment)",
                     kTargetRaycastMs});
            if (!bp.rows.empty()) {
                hc::bench::writeSvg(plot, bp.svg());
                std::printf("plot written to %s\n", plot.c_str());
            }
        }
        return 0;
    });
}
