// hc-render: a picture (PNG, and EXR layers) of the smooth surface of a grid from a camera.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "heightcast/support/backend_choice.h"
#include "heightcast/support/cli.h"
#include "heightcast/support/render_setup.h"
#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"
#include "heightcast/core/heap.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/timer.h"
#include "heightcast/render/gl/gl_renderer.h"
#include "heightcast/render/image_io.h"
#include "heightcast/render/renderer.h"
#include "render/outputs.h"

namespace {

struct RenderArgs {
    std::string gridPath, out, exr, timingsPath, video;
    hc::cli::Backend backend = hc::cli::Backend::Auto;
    hc::cli::RenderSetup setup{"1280x720"};
    bool sequence = false;  // --steps A:B: one image per step
    unsigned firstStep = 0, lastStep = 0;
    unsigned flyFrames = 0;     // --fly N: one image per frame of a flight (0: no flight)
    double flyStepM = 10;       // --fly-step M: metres forward per frame
    bool flyFresh = false;      // --fly-fresh: every frame of the flight from scratch (no texels kept)
    bool flyLastImage = false;  // --fly-last-image: only the last frame's outputs; GL frames before it left on the GPU
    double fps = 4;             // --fps, of the --video
    int verifyHits = 0;         // --verify-error N: hits checked against the exact surface (0: none)
    // The numbered images' first number and count (a sequence or a flight).
    unsigned firstImage() const { return sequence ? firstStep : 0; }
    unsigned imageCount() const { return sequence ? lastStep - firstStep + 1 : flyFrames; }
};

using hc::render_app::numbered;
using hc::render_app::onPath;
using hc::render_app::Rendered;

// The files of a's frames.
hc::render_app::OutputPaths pathsOf(const RenderArgs& a) { return {a.out, a.exr, a.timingsPath}; }

// With --video: ffmpeg started, reading the frames as they come.
std::unique_ptr<hc::render_app::VideoPipe> videoFor(const RenderArgs& a, const std::string& ffmpeg,
                                                    const hc::render::Camera& camera) {
    if (a.video.empty()) return nullptr;
    return std::make_unique<hc::render_app::VideoPipe>(ffmpeg, a.video, a.fps, camera.width, camera.height);
}

// The options, validated with the camera's numbers before any expensive work; false after --help.
bool parseOptions(int argc, char** argv, RenderArgs& a) {
    std::string view, backendText = "auto";
    hc::cli::Parser p(
        "hc-render",
        "GRID.hcg -o OUT.png [--camera X,Y,Z,YAW,PITCH,FOV[,ROLL] | --look-at EX,EY,EZ,TX,TY,TZ[,FOV] | --view "
        "overview] [options]",
        "Ray-casts the smooth surface of a grid (terrain, and water where the grid has water_depth) into a PNG\n"
        "and optionally EXR layers, and prints per-stage timings. Coordinates in the grid's CRS [m]; angles in\n"
        "degrees: yaw 0 looks north, 90 east; pitch negative looks down. The terrain is drawn as a solid block:\n"
        "where its surface ends (holes, the domain's edge) a brown wall goes down to the lowest elevation.\n"
        "A camera below the terrain surface is refused (every ray would start inside it and see nothing), unless\n"
        "--near starts the rays farther out.");
    p.positional("GRID.hcg", "grid file", a.gridPath);
    p.option("-o", "OUT.png", "colour image, 8-bit sRGB PNG (required)", a.out);
    a.setup.addCameraOptions(p, "--view");
    p.option("--view", "overview", "a camera framing the whole grid obliquely from the south-south-west (the default)",
             view);
    a.setup.addRenderOptions(p);
    p.option("--exr", "OUT.exr",
             "also write float layers: Z, P.X/Y/Z, N.X/Y/Z, cascade, water_depth, wall (1 on hits on\n"
             "the walls drawn at hole and domain edges, 0 elsewhere)",
             a.exr);
    p.option("--timings", "OUT.json", "also write the per-stage timings as JSON", a.timingsPath);
    std::string stepsText;
    p.option(
        "--steps", "A:B",
        "render water steps A..B (0-based, inclusive), one image each: OUT_0007.png for step 7 (likewise\n"
        "      --exr and --timings); the camera is the same for every step, and only the water changes between them",
        stepsText);
    p.option(
        "--fly", "N",
        "render a flight of N >= 2 frames, one image each (OUT_0000.png ...; likewise --exr and --timings):\n"
        "      the camera moves --fly-step metres forward (horizontally, along its yaw) each frame, and each frame\n"
        "      keeps the texels the last one evaluated that it still sees (incremental cascades; the GL backend\n"
        "      keeps them on the GPU); prints each frame's stage times\n"
        "      (default 0: one image, no flight)",
        a.flyFrames);
    p.option("--verify-error", "N",
             "check N hits (spread over the picture) against the exact surface there and print the largest,\n"
             "99th-percentile and median error beside the frame's bound (and in --timings' JSON); the cells\n"
             "around the points are read from the grid (default 0: none)",
             a.verifyHits);
    p.option("--fly-step", "M", "metres the camera moves forward per --fly frame (default 10)", a.flyStepM);
    p.flag("--fly-fresh", "with --fly: evaluate every frame from scratch (no texels kept), to compare", a.flyFresh);
    p.flag("--fly-last-image",
           "with --fly: write the last frame's image alone (and its --exr, --timings); the GL backend\n"
           "      leaves the frames before it on the GPU, unread, back to back as the viewer draws them (for timing: "
           "nothing\n"
           "      is read back or written between frames, during which the GPU would idle and lower its clock)",
           a.flyLastImage);
    p.option("--video", "OUT.mp4",
             "with --steps or --fly: also an H.264 video of the images through ffmpeg (Debian package ffmpeg)",
             a.video);
    p.option("--fps", "F", "frames (steps) per second of the --video (default 4)", a.fps);
    p.exclusive({"--step", "--steps"});
    p.exclusive({"--steps", "--fly"});
    p.option("--backend", "B",
             "gl (OpenGL 4.3 compute shaders; headless, no display needed), cpu, or auto: gl where an\n"
             "OpenGL 4.3 context on a GPU can be had, else cpu with a note saying why (no 4.3 context, or only\n"
             "software OpenGL such as Mesa's llvmpipe, which is slower than cpu) (default auto). On gl,\n"
             "--threads sizes the CPU's share (texels filled out of core, --color-by and --cells at the hits)",
             backendText);
    if (!p.parse(argc, argv)) return false;
    if (a.out.empty()) throw hc::Error("no output image: give -o OUT.png");
    if (!view.empty() && view != "overview") throw hc::Error("--view " + view + ": the only view is 'overview'");
    a.backend = hc::cli::parseBackend(backendText);
    a.setup.finish();
    if (!stepsText.empty()) {
        const size_t colon = stepsText.find(':');
        if (colon == std::string::npos) throw hc::Error("--steps " + stepsText + ": expected A:B, e.g. 0:23");
        const double v[2] = {hc::cli::parseNumber(stepsText.substr(0, colon), "--steps"),
                             hc::cli::parseNumber(stepsText.substr(colon + 1), "--steps")};
        if (v[0] < 0 || v[1] < v[0] || v[0] != std::floor(v[0]) || v[1] != std::floor(v[1]) || v[1] > 1e6)
            throw hc::Error("--steps " + stepsText + ": expected A:B, whole step numbers with 0 <= A <= B");
        a.sequence = true;
        a.firstStep = unsigned(v[0]), a.lastStep = unsigned(v[1]);
        a.setup.step = a.firstStep;
        if (!a.setup.pyramidPath.empty())
            throw hc::Error(
                "--pyramid names one step's pyramid but --steps renders several: leave it out (each step's own is "
                "used)");
    }
    if (a.flyFrames == 1 || a.flyFrames > 100000)
        throw hc::Error("--fly " + std::to_string(a.flyFrames) + ": a flight has 2 to 100000 frames");
    if (!std::isfinite(a.flyStepM) || std::fabs(a.flyStepM) > 1e6)
        throw hc::Error("--fly-step " + fmt::format("{:g}", a.flyStepM) + ": metres per frame, at most 1e6 either way");
    if (a.flyFresh && !a.flyFrames) throw hc::Error("--fly-fresh needs --fly N");
    if (a.verifyHits && a.flyFrames) throw hc::Error("--verify-error checks one image or each of --steps, not a --fly");
    if (a.verifyHits < 0 || a.verifyHits > 10000000)
        throw hc::Error("--verify-error " + std::to_string(a.verifyHits) + ": a count of hits in 0..1e7");
    if (a.flyLastImage && !a.flyFrames) throw hc::Error("--fly-last-image needs --fly N");
    if (a.flyLastImage && !a.video.empty())
        throw hc::Error("--video needs every frame's image: leave out --fly-last-image");
    if (!a.video.empty() && !a.sequence && !a.flyFrames)
        throw hc::Error("--video needs --steps A:B or --fly N (one image per frame)");
    if (!(a.fps > 0) || a.fps > 240) throw hc::Error("--fps " + fmt::format("{:g}", a.fps) + ": must be in (0, 240]");
    return true;
}

// The backend rule (backend_choice.h) over a headless context, made and dropped again unless cpu was asked for.
hc::cli::BackendDecision chooseBackend(hc::cli::Backend requested) {
    const hc::cli::GlOnHand gl = requested == hc::cli::Backend::Cpu ? hc::cli::GlOnHand{} : hc::cli::probeHeadlessGl();
    return hc::cli::decideBackend(requested, gl);
}

void checkOutputs(const RenderArgs& a) {
    for (const std::string* o : {&a.out, &a.exr, &a.timingsPath, &a.video})
        if (!o->empty()) {
            hc::cli::checkWritable(*o, "output");
            hc::cli::checkNotSame(*o, a.gridPath, "output");
        }
    if (a.sequence) {
        const size_t steps = hc::readGridInfo(a.gridPath).shape.stepCount();
        if (a.lastStep >= std::max<size_t>(1, steps))
            throw hc::Error("--steps " + std::to_string(a.firstStep) + ":" + std::to_string(a.lastStep) + ": " +
                            a.gridPath + " has " + std::to_string(steps) + " water step" + (steps == 1 ? "" : "s"));
    }
}

// Inside the terrain every ray starts in the solid block and sees nothing: say so, before any evaluation.
void refuseCameraBelowTerrain(const hc::render::Scene& scene, const hc::render::Camera& camera) {
    if (const double below = hc::render::cameraBelowTerrainM(scene, camera); below > 0) {
        char b[400];
        std::snprintf(
            b, sizeof b,
            "the camera at %.3f, %.3f, %.3f is %.2f m below the terrain surface (%.2f m there): every ray would "
            "start inside the terrain and see nothing; raise the camera above the surface, or give --near M to start "
            "the rays beyond the terrain in front of it",
            camera.xWorld, camera.yWorld, camera.zWorld, below, camera.zWorld + below);
        throw hc::Error(b);
    }
}

// The backend decision's note (why auto chose as it did), if it has one, on stderr.
void sayNote(const hc::cli::BackendDecision& decision) {
    if (!decision.note.empty()) std::fprintf(stderr, "hc-render: note: %s\n", decision.note.c_str());
}

// What the GL backend reads back for a's outputs: the picture alone unless the EXR layers or the hits are wanted.
hc::render::GlRenderer::ReadBack readBackFor(const RenderArgs& a) {
    return a.exr.empty() && a.verifyHits == 0 ? hc::render::GlRenderer::ReadBack::PictureOnly
                                              : hc::render::GlRenderer::ReadBack::AllLayers;
}

// On the backend `decision` chose, after printing its note: GL on `gl` (a sequence's, kept from step to step), or in a
// headless context of its own where gl is null.
Rendered renderImage(const hc::cli::BackendDecision& decision, const hc::render::Scene& scene,
                     const hc::render::Camera& camera, const hc::render::RenderOptions& options, int verifyHits,
                     hc::render::GlRenderer* gl = nullptr,
                     hc::render::GlRenderer::ReadBack what = hc::render::GlRenderer::ReadBack::AllLayers) {
    sayNote(decision);
    Rendered r;
    if (decision.useGl) {
        std::unique_ptr<hc::render::GlRenderer> own = gl ? nullptr : hc::render::GlRenderer::headless(scene);
        if (own) gl = own.get();
        r.device = gl->deviceName();
        r.frame = gl->render(camera, options, r.timings, what);
    } else {
        r.device = "CPU, " + std::to_string(hc::resolveThreads(options.threads)) + " threads";
        r.frame = hc::render::renderFrame(scene, camera, options, r.timings);
    }
    if (verifyHits > 0)
        r.timings.verified = hc::render::verifyFrameError(scene, camera, r.frame, size_t(verifyHits), options.threads);
    return r;
}

void printSummary(const RenderArgs& a, const hc::cli::BackendDecision& decision, const hc::render::Camera& camera,
                  const Rendered& r) {
    std::printf("hc-render: %s -> %s%s%s\n", a.gridPath.c_str(), a.out.c_str(), a.exr.empty() ? "" : " + ",
                a.exr.c_str());
    std::printf("  backend      %s (%s)\n", decision.useGl ? "gl" : "cpu", r.device.c_str());
    std::printf("  camera       %.3f, %.3f, %.3f  yaw %.2f  pitch %.2f  fov %.1f  %dx%d", camera.xWorld, camera.yWorld,
                camera.zWorld, camera.yawDeg, camera.pitchDeg, camera.fovYDeg, camera.width, camera.height);
    if (camera.rollDeg != 0) std::printf("  roll %.2f", camera.rollDeg);
    if (camera.nearM > 0) std::printf("  near %g m", camera.nearM);
    if (camera.farM > 0) std::printf("  far %g m", camera.farM);
    std::printf("\n");
    // Hits on the terrain block's cut faces (hole and domain edges, its bottom): said, as they are not surface.
    size_t walls = 0;
    for (float w : r.frame.wall) walls += w != 0;
    if (walls)
        std::printf("  walls        %zu of %llu hits on the walls at hole and domain edges (EXR channel wall)\n", walls,
                    (unsigned long long)r.timings.hits);
    std::printf("%s", r.timings.toTable().c_str());
    if (r.timings.verified) {
        const hc::render::ErrorCheck& c = *r.timings.verified;
        std::printf(
            "  verified     %llu hits against the exact surface: largest %.3g m (%.3g px), 99th percentile "
            "%.3g m, median %.3g m; bound %.3g m\n",
            (unsigned long long)c.hits, c.maxM, c.maxPx, c.p99M, c.medianM, r.timings.errorBoundM);
        if (c.water)
            std::printf(
                "  shoreline    %llu of them drawn dry where the ray came down through the exact water, %llu drawn on "
                "water where the exact surface is dry\n",
                (unsigned long long)c.drawnDryOverWater, (unsigned long long)c.drawnWetOverDry);
        if (c.drawnDryOverWater + c.drawnWetOverDry > 0)
            std::printf(
                "               the exact shore at most %.3g m (%.3g px) away from them (bound %.3g m); water drawn "
                "at most %.3g m over the exact ground\n",
                c.shoreDistanceM, c.shoreDistancePx, r.timings.shoreBoundM, c.shoreMaxM);
    }
}

// --fly N: one renderer for the whole flight (GL: one context; out of core the CPU-filled cascades keep their texels
// in it; CPU: a CascadeCache), one image per frame, each frame's stage times printed. The rendering's times exclude
// writing the images; the GL backend's read-back is its own column.
int fly(const RenderArgs& a, const hc::cli::BackendDecision& decision, const hc::render::Scene& scene,
        const hc::render::Camera& start) {
    for (unsigned k = 1; k < a.flyFrames; ++k) {  // every frame's camera checked before any is rendered
        try {
            refuseCameraBelowTerrain(scene, hc::render::flightFrame(start, a.flyStepM, k));
        } catch (const hc::Error& e) {
            throw hc::Error("--fly frame " + std::to_string(k) + ": " + e.what());
        }
    }
    const std::string ffmpeg = a.video.empty() ? "" : onPath("ffmpeg");
    if (!a.video.empty() && ffmpeg.empty())
        throw hc::Error(
            "--video: ffmpeg is not installed (Debian: apt install ffmpeg); the images alone need no --video");
    sayNote(decision);
    std::unique_ptr<hc::render::GlRenderer> gl;
    std::string device = "CPU, " + std::to_string(hc::resolveThreads(a.setup.options.threads)) + " threads";
    if (decision.useGl) {
        gl = hc::render::GlRenderer::headless(scene);
        device = gl->deviceName();
    }
    hc::render::CascadeCache cache;
    std::printf("hc-render: %s, a flight of %u frames, %g m a frame%s -> %s\n", a.gridPath.c_str(), a.flyFrames,
                a.flyStepM, a.flyFresh ? ", every frame from scratch" : "", numbered(a.out, 0).c_str());
    std::printf("  backend      %s (%s)\n", decision.useGl ? "gl" : "cpu", device.c_str());
    std::printf(
        "  frame           x m           y m   approx ms  kept %%     fit ms     mip ms     ray ms   shade ms  render "
        "ms%s\n",
        gl ? "  upload ms     GPU ms  readback ms" : "");
    hc::Stopwatch total;
    std::vector<double> renderMs;
    const std::unique_ptr<hc::render_app::VideoPipe> video = videoFor(a, ffmpeg, start);
    hc::render_app::OutputWriter writer(pathsOf(a), video.get());
    // A frame's row, and its files where it has outputs; in frame order.
    auto report = [&](unsigned k, const hc::render::Camera& camera, Rendered&& r, bool outputs) {
        const hc::render::Timings t = r.timings;
        if (outputs) writer.put(std::move(r), k);
        uint64_t kept = 0, visible = 0;
        for (const auto& c : t.cascades) kept += c.reusedTexels, visible += c.visibleTexels;
        const double ms = t.totalMs - t.readbackMs;
        renderMs.push_back(ms);
        std::printf("  %5u %13.3f %13.3f %11.2f %6.1f %10.2f %10.2f %10.2f %10.2f %10.2f", k, camera.xWorld,
                    camera.yWorld, t.approximationMs, visible ? 100.0 * double(kept) / double(visible) : 0.0,
                    t.fittingMs, t.mipmapMs, t.raycastMs, t.shadingMs, ms);
        if (gl) std::printf(" %10.2f %10.2f %12.2f", t.uploadMs, t.gpuMs, t.readbackMs);
        std::printf("\n");
    };
    // GL pictures alone: frames in flight (GlRenderer::submitPicture), each reported when its picture is collected.
    const bool ring = gl && readBackFor(a) == hc::render::GlRenderer::ReadBack::PictureOnly;
    std::deque<std::pair<unsigned, hc::render::Camera>> inFlight;
    auto collectOne = [&] {
        hc::render::GlRenderer::Picture p = gl->collectPicture();
        report(inFlight.front().first, inFlight.front().second, Rendered{std::move(p.frame), p.timings, device}, true);
        inFlight.pop_front();
    };
    for (unsigned k = 0; k < a.flyFrames; ++k) {
        const hc::render::Camera camera = hc::render::flightFrame(start, a.flyStepM, k);
        if (a.flyFresh) {
            if (gl) gl->forgetCascades();
            cache.clear();
        }
        const bool outputs = !a.flyLastImage || k + 1 == a.flyFrames;
        if (ring && outputs) {
            if (gl->picturesInFlight() == hc::render::GlRenderer::kPicturesInFlight) collectOne();
            gl->submitPicture(camera, a.setup.options);
            inFlight.emplace_back(k, camera);
            continue;
        }
        while (!inFlight.empty()) collectOne();
        Rendered r;
        r.device = device;
        if (gl && !outputs)
            gl->renderToTexture(camera, a.setup.options, r.timings);
        else
            r.frame = gl ? gl->render(camera, a.setup.options, r.timings, readBackFor(a))
                         : hc::render::renderFrame(scene, camera, a.setup.options, r.timings, &cache);
        report(k, camera, std::move(r), outputs);
    }
    while (!inFlight.empty()) collectOne();
    writer.finish();
    if (video) video->finish();
    // The frames after the first (which has nothing to keep): their median and slowest.
    std::vector<double> later(renderMs.begin() + 1, renderMs.end());
    std::sort(later.begin(), later.end());
    std::printf(
        "  frames 1..%u  render median %.2f ms, slowest %.2f ms; frame 0 %.2f ms; total %.3f s with the image%s "
        "(%.1f frames a second)\n",
        a.flyFrames - 1, later[later.size() / 2], later.back(), renderMs[0], total.seconds(),
        a.flyLastImage ? " (the last frame's alone)" : "s", a.flyFrames / total.seconds());
    if (video) {
        std::printf("  video        %s (%g frames per second)\n", a.video.c_str(), a.fps);
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-render", [&] {
        RenderArgs a;
        if (!parseOptions(argc, argv, a)) return 0;
        hc::cli::BackendDecision decision = chooseBackend(a.backend);
        checkOutputs(a);
        // Without a cache either backend reads the grid out of core (the GL one then evaluates the texels a frame newly
        // sees on the CPU and keeps its cascades on the GPU, gl_renderer.h); --color-by needs the grid and its lists in
        // memory (the exact evaluator at every hit, on the CPU for either backend).
        auto loaded = hc::cli::loadScene("hc-render", a.gridPath, a.setup, a.setup.colorBy.empty());
        const hc::render::Camera camera = hc::cli::initialCamera(a.setup, *loaded->scene);
        refuseCameraBelowTerrain(*loaded->scene, camera);
        if (a.flyFrames || a.sequence)
            hc::keepFreedMemory();  // frame after frame: each reuses the last one's pages (core/heap.h)
        if (a.flyFrames) return fly(a, decision, *loaded->scene, camera);
        if (!a.sequence) {
            const Rendered rendered = renderImage(decision, *loaded->scene, camera, a.setup.options, a.verifyHits);
            pathsOf(a).write(rendered, std::nullopt);
            printSummary(a, decision, camera, rendered);
            const hc::Grid& shape = loaded->file ? loaded->file->shape() : loaded->grid;
            if (shape.steps.size() > 1)
                std::printf("  step         %u of %zu, at %.9g s\n", a.setup.step, shape.steps.size(),
                            shape.stepTimeS());
            return 0;
        }
        // A sequence: the same camera, one frame per step; only the water is read again between steps.
        const std::string ffmpeg = a.video.empty() ? "" : onPath("ffmpeg");
        if (!a.video.empty() && ffmpeg.empty())
            throw hc::Error(
                "--video: ffmpeg is not installed (Debian: apt install ffmpeg); the images alone need no --video");
        std::printf("hc-render: %s, steps %u..%u -> %s\n", a.gridPath.c_str(), a.firstStep, a.lastStep,
                    numbered(a.out, a.firstStep).c_str());
        std::printf("  step     time s   wet cells   switch ms    frame ms   image\n");
        hc::Stopwatch total;
        // GL: one context for every step, the next step's scene handed to it (its shaders compiled once).
        std::unique_ptr<hc::render::GlRenderer> gl =
            decision.useGl ? hc::render::GlRenderer::headless(*loaded->scene) : nullptr;
        const std::unique_ptr<hc::render_app::VideoPipe> video = videoFor(a, ffmpeg, camera);
        hc::render_app::OutputWriter writer(pathsOf(a), video.get());
        // A step's row, and its files; in step order.
        struct Step {
            unsigned k;
            double timeS;
            unsigned long long wetCells;
            double switchMs;
        };
        auto report = [&](const Step& s, Rendered&& r) {
            const double frameMs = r.timings.totalMs;
            writer.put(std::move(r), s.k);
            std::printf("  %4u %10.6g %11llu %11.1f %11.1f   %s\n", s.k, s.timeS, s.wetCells, s.switchMs, frameMs,
                        numbered(a.out, s.k).c_str());
        };
        // GL pictures alone: steps in flight (GlRenderer::submitPicture), each reported when its picture is collected.
        const bool ring = gl && readBackFor(a) == hc::render::GlRenderer::ReadBack::PictureOnly;
        std::deque<Step> inFlight;
        auto collectOne = [&] {
            hc::render::GlRenderer::Picture p = gl->collectPicture();
            report(inFlight.front(), Rendered{std::move(p.frame), p.timings, gl->deviceName()});
            inFlight.pop_front();
        };
        for (unsigned k = a.firstStep; k <= a.lastStep; ++k) {
            hc::Stopwatch clock;
            if (k != a.firstStep) {
                hc::cli::switchStep("hc-render", *loaded, a.gridPath, a.setup, k);
                if (gl) gl->setScene(*loaded->scene);
            }
            const hc::Grid& shape = loaded->file ? loaded->file->shape() : loaded->grid;
            const Step step{k, shape.stepTimeS(), shape.steps.empty() ? 0 : shape.steps[k].wetCells, clock.lap() * 1e3};
            if (k != a.firstStep) decision.note.clear();  // said once
            if (ring) {
                if (gl->picturesInFlight() == hc::render::GlRenderer::kPicturesInFlight) collectOne();
                sayNote(decision);
                gl->submitPicture(camera, a.setup.options);
                inFlight.push_back(step);
                continue;
            }
            report(step, renderImage(decision, *loaded->scene, camera, a.setup.options, a.verifyHits, gl.get(),
                                     readBackFor(a)));
        }
        while (!inFlight.empty()) collectOne();
        writer.finish();
        if (video) video->finish();
        std::printf("  total        %.3f s for %u steps (%.1f steps a second)\n", total.seconds(),
                    a.lastStep - a.firstStep + 1, (a.lastStep - a.firstStep + 1) / total.seconds());
        if (video) {
            std::printf("  video        %s (%g steps per second)\n", a.video.c_str(), a.fps);
        }
        return 0;
    });
}
