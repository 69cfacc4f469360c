// bench/bench_render_run.cpp: one hc-bench scenario in a forked child (bench_render.h): generate the grid (in memory,
// or streamed into a file where the lists would not fit), build the lists or the surface pyramid, render the frames.
#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>

#include "bench_common.h"
#include "heightcast/support/backend_choice.h"
#include "heightcast/core/error.h"
#include "heightcast/core/heap.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/progress.h"
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

#include "bench_render.h"

namespace fs = std::filesystem;
using hc::Grid;
using hc::scenes::Scenario;

namespace hc::bench {
namespace {

// The memory guard before building lists: cells sampled for their estimated size, and what a render holds beside
// the grid and the lists: per cell (the Scene's arrays) and per cascade texel and pixel (the frame's buffers).
// Measured as peak RSS - grid RSS - list bytes of two scenes (Petzenkirchen 1.84 M cells: 240 MB, Marchfeld 7.53 M:
// 386 MB, 1920x1080, 3 x 1024^2; hc-bench --scenarios Petzenkirchen,Marchfeld --repeat 1 --json), solved for the
// two parts (26 B a cell, 193 MB for 5.2 M texels and pixels = 37 B each) and rounded up.
constexpr size_t kListsEstimateSample = 20000;
constexpr double kRenderBytesPerCellBesideLists = 32;
constexpr double kRenderBytesPerTexelOrPixel = 40;

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

// The temporary grid of a scene run out of core by process `pid`: hc_bench_SCENE_PID.hcg in the temp folder (the one
// name removeStaleGrids() parses).
constexpr const char* kTempGridPrefix = "hc_bench_";
fs::path tempGridPath(const char* scene, pid_t pid) {
    return fs::temp_directory_path() / fmt::format("{}{}_{}.hcg", kTempGridPrefix, scene, pid);
}

}  // namespace

void progressLine(bool interactive, const char* scene, const std::string& what, double secondsIn) {
    if (interactive)
        std::fprintf(stderr, "\r%-14s %-40s", scene, what.c_str());
    else if (secondsIn >= 0)
        std::fprintf(stderr, "hc-bench: %s: %s (%.0f s in)\n", scene, what.c_str(), secondsIn);
    else
        std::fprintf(stderr, "hc-bench: %s: %s\n", scene, what.c_str());
}

void removeStaleGrids() {
    // hc_bench_SCENE_PID.hcg (its pyramid hc_bench_SCENE_PID.hcg.hcp, and their writers' OUTPUT.tmp.XXXXXX) of a
    // process that is gone: 5 GB at 400 M cells, and the pyramid 7-11 GB.
    std::error_code ec;
    for (const fs::directory_entry& e : fs::directory_iterator(fs::temp_directory_path(), ec)) {
        const std::string name = e.path().filename().string();
        if (name.rfind(kTempGridPrefix, 0) != 0) continue;
        const size_t dot = name.find(".hcg"), under = name.rfind('_', dot);
        if (dot == std::string::npos || under == std::string::npos || under + 1 >= dot) continue;
        const std::string pidText = name.substr(under + 1, dot - under - 1);
        if (pidText.find_first_not_of("0123456789") != std::string::npos || pidText.size() > 9) continue;
        const pid_t pid = pid_t(std::stol(pidText));
        if (pid <= 0 || pid == ::getpid() || ::kill(pid, 0) == 0 || errno != ESRCH) continue;  // alive, or not ours
        const uintmax_t bytes = e.file_size(ec);
        if (fs::remove(e.path(), ec))
            std::printf("removed %s (%.1f GB), left by hc-bench process %d, which is gone\n", e.path().c_str(),
                        double(bytes) / 1e9, int(pid));
    }
}

RunResult runScenario(const Scenario& sc, const Settings& set) {
    return inChild<RunResult>(sc.name, [&](RunResult& r) {
        auto say = [&](const char* what) {  // a frame's progress: on a terminal only
            if (set.interactive) progressLine(true, sc.name, what);
        };
        // A stage that may take minutes (at 400 M cells, an hour in all): in a log too.
        const hc::Stopwatch since;
        auto stage = [&](const char* what) { progressLine(set.interactive, sc.name, what, since.seconds()); };
        r.baselineRss = hc::currentRssBytes();
        std::snprintf(r.name, sizeof r.name, "%s", sc.name);
        stage("generating the grid ...");
        hc::Stopwatch clock;
        r.targetCells = set.cells > 0 ? set.cells : hc::scenes::targetCells(sc, set.scale);
        // Where the lists would not fit, the scenario runs as the tools do by default at such sizes: the grid streamed
        // into a file, the surface pyramid built from it a node at a time, the frames rendered out of core.
        r.memAvailableBytes = memoryForScenario(set);
        const double listsPath = listsPathBytes(set, r.targetCells);
        r.outOfCore = set.outOfCore || listsPath > double(r.memAvailableBytes);
        if (r.outOfCore) r.renderNeedBytes = uint64_t(listsPath);  // what the lists path would have needed
        r.pyramid = set.pyramid || (!set.outOfCore && r.outOfCore);
        std::optional<hc::scenes::Generated> gen;  // in memory
        std::unique_ptr<hc::GridRegionReader> file;
        struct RemoveFile {
            fs::path path;
            ~RemoveFile() {
                std::error_code ec;
                if (!path.empty()) fs::remove(path, ec);
            }
        } written, writtenPyramid;
        double topM = 0;  // the highest terrain or water surface [m]
        if (r.outOfCore) {
            written.path = tempGridPath(sc.name, ::getpid());
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
            stage("building influence lists ...");
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
            stage("building the surface pyramid ...");
            clock.restart();
            // Out of core as hc-influence builds it by default: a node of the file at a time into a file beside the
            // grid (the same samples), read back as a renderer reads it.
            if (file) {
                writtenPyramid.path = written.path.string() + ".hcp";  // removeStaleGrids() parses it as the grid's
                hc::influence::writePyramidOnRanks(*file, hc::influence::KernelParams{}, set.options.threads, false,
                                                   false, writtenPyramid.path.string());
                pyramid = hc::influence::readSurfacePyramid(writtenPyramid.path.string(), file->info(),
                                                            hc::influence::KernelParams{});
            } else {
                pyramid = hc::influence::buildSurfacePyramid(g, hc::influence::KernelParams{}, set.options.threads);
            }
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
        if (set.trade) {  // the sweep instead of the timed frames (bench_render_trade.cpp)
            tradeSweep(scene, cam, set, r);
            r.peakRss = hc::peakRssBytes();
            say("");
            return;
        }
        hc::render::Frame frame;
        // The GL backend: a headless context in this child; one unmeasured warm-up frame first, since
        // drivers (llvmpipe among them) compile shaders at their first dispatch.
        std::unique_ptr<hc::render::GlRenderer> gl;
        std::snprintf(r.device, sizeof r.device, "CPU, %u threads", hc::resolveThreads(set.options.threads));
        if (set.backend == hc::cli::Backend::Gl) {
            // Warm-up frames, unmeasured, for at least a second: drivers compile shaders at the first dispatch, and an
            // idle GPU takes a moment to leave its idle clocks (on an H100 the first scene's stages ran 2-3x slower
            // after a single warm-up frame).
            stage("GL warm-up frames ...");
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
                        r.cascades[c] = {
                            cs.nearM,     cs.farM,         cs.texelM,        cs.approximationMs,     cs.visibleTexels,
                            cs.gaussians, cs.pyramidLevel, cs.pyramidTexels, cs.pyramidInterpolated, cs.errorBoundM};
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
            stage("reading the frame back ...");
            hc::render::Timings tm;
            gl->forgetCascades();  // from scratch, as the measured frames (after a flight it would keep its last
                                   // frame's texels)
            frame = gl->render(cam, set.options, tm);
            r.readbackMs = tm.readbackMs;
        }
        for (size_t i = 0; i < frame.waterDepthM.size(); ++i) r.wetHits += frame.waterDepthM[i] > 0;
        if (set.accuracy) {
            stage("measuring hits against the exact surface ...");
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

}  // namespace hc::bench
