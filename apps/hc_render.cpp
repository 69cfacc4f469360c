// hc-render: a picture (PNG, and EXR layers) of the smooth surface of a grid from a camera.
#include <cstdio>
#include <string>

#include "backend_choice.h"
#include "cli.h"
#include "render_setup.h"
#include "heightcast/core/atomic_file.h"
#include "heightcast/core/error.h"
#include "heightcast/grid/grid_file.h"
#include "heightcast/core/parallel.h"
#include "heightcast/render/gl/gl_renderer.h"
#include "heightcast/render/image_io.h"
#include "heightcast/render/renderer.h"

namespace {

struct RenderArgs {
    std::string gridPath, out, exr, timingsPath;
    hc::cli::Backend backend = hc::cli::Backend::Auto;
    hc::cli::RenderSetup setup{"1280x720"};
};

// The options, validated with the camera's numbers before any expensive work; false after --help.
bool parseOptions(int argc, char** argv, RenderArgs& a) {
    std::string view, backendText = "auto";
    hc::cli::Parser p("hc-render", "GRID.hcg -o OUT.png [--camera X,Y,Z,YAW,PITCH,FOV[,ROLL] | --look-at EX,EY,EZ,TX,TY,TZ[,FOV] | --view overview] [options]",
                      "Ray-casts the smooth surface of a grid (terrain, and water where the grid has water_depth) into a PNG\n"
                      "and optionally EXR layers, and prints per-stage timings. Coordinates in the grid's CRS [m]; angles in\n"
                      "degrees: yaw 0 looks north, 90 east; pitch negative looks down. The terrain is drawn as a solid block:\n"
                      "where its surface ends (holes, the domain's edge) a brown wall goes down to the lowest elevation.\n"
                      "A camera below the terrain surface is refused (every ray would start inside it and see nothing), unless\n"
                      "--near starts the rays farther out.");
    p.positional("GRID.hcg", "grid file", a.gridPath);
    p.option("-o", "OUT.png", "colour image, 8-bit sRGB PNG (required)", a.out);
    a.setup.addCameraOptions(p, "--view");
    p.option("--view", "overview", "a camera framing the whole grid obliquely from the south-south-west (the default)", view);
    a.setup.addRenderOptions(p);
    p.option("--exr", "OUT.exr", "also write float layers: Z, P.X/Y/Z, N.X/Y/Z, cascade, water_depth, wall (1 on hits on\n"
             "the walls drawn at hole and domain edges, 0 elsewhere)", a.exr);
    p.option("--timings", "OUT.json", "also write the per-stage timings as JSON", a.timingsPath);
    p.option("--backend", "B", "gl (OpenGL 4.3 compute shaders; headless, no display needed), cpu, or auto: gl where an\n"
             "OpenGL 4.3 context on a GPU can be had, else cpu with a note saying why (no 4.3 context, or only\n"
             "software OpenGL such as Mesa's llvmpipe, which is slower than cpu) (default auto). --threads\n"
             "applies to cpu only", backendText);
    if (!p.parse(argc, argv)) return false;
    if (a.out.empty()) throw hc::Error("no output image: give -o OUT.png");
    if (!view.empty() && view != "overview") throw hc::Error("--view " + view + ": the only view is 'overview'");
    a.backend = hc::cli::parseBackend(backendText);
    a.setup.finish();
    return true;
}

// The backend rule (backend_choice.h) over a headless context, made and dropped again unless cpu was asked for.
hc::cli::BackendDecision chooseBackend(hc::cli::Backend requested) {
    const hc::cli::GlOnHand gl = requested == hc::cli::Backend::Cpu ? hc::cli::GlOnHand{} : hc::cli::probeHeadlessGl();
    return hc::cli::decideBackend(requested, gl);
}

void checkOutputs(const RenderArgs& a) {
    for (const std::string* o : {&a.out, &a.exr, &a.timingsPath})
        if (!o->empty()) {
            hc::cli::checkWritable(*o, "output");
            hc::cli::checkNotSame(*o, a.gridPath, "output");
        }
}

// Inside the terrain every ray starts in the solid block and sees nothing: say so, before any evaluation.
void refuseCameraBelowTerrain(const hc::render::Scene& scene, const hc::render::Camera& camera) {
    if (const double below = hc::render::cameraBelowTerrainM(scene, camera); below > 0) {
        char b[400];
        std::snprintf(b, sizeof b,
                      "the camera at %.3f, %.3f, %.3f is %.2f m below the terrain surface (%.2f m there): every ray would "
                      "start inside the terrain and see nothing; raise the camera above the surface, or give --near M to start "
                      "the rays beyond the terrain in front of it",
                      camera.xWorld, camera.yWorld, camera.zWorld, below, camera.zWorld + below);
        throw hc::Error(b);
    }
}

struct Rendered {
    hc::render::Frame frame;
    hc::render::Timings timings;
    std::string device;  // what rendered it: "CPU, N threads" or the GL renderer and version
};

// On the backend `decision` chose (GL in a headless context of its own), after printing its note.
Rendered renderImage(const hc::cli::BackendDecision& decision, const hc::render::Scene& scene, const hc::render::Camera& camera,
                     const hc::render::RenderOptions& options) {
    if (!decision.note.empty()) std::fprintf(stderr, "hc-render: note: %s\n", decision.note.c_str());
    Rendered r;
    if (decision.useGl) {
        auto gl = hc::render::GlRenderer::headless(scene);
        r.device = gl->deviceName();
        r.frame = gl->render(camera, options, r.timings);
    } else {
        r.device = "CPU, " + std::to_string(hc::resolveThreads(options.threads)) + " threads";
        r.frame = hc::render::renderFrame(scene, camera, options, r.timings);
    }
    return r;
}

void writeOutputs(const RenderArgs& a, const Rendered& r) {
    hc::render::writePng(r.frame, a.out);
    if (!a.exr.empty()) hc::render::writeFrameExr(r.frame, a.exr);
    if (!a.timingsPath.empty()) {
        hc::AtomicFileWriter tw(a.timingsPath);
        const std::string j = r.timings.toJson();
        tw.write(std::as_bytes(std::span(j)));
        tw.commit();
    }
}

void printSummary(const RenderArgs& a, const hc::cli::BackendDecision& decision, const hc::render::Camera& camera, const Rendered& r) {
    std::printf("hc-render: %s -> %s%s%s\n", a.gridPath.c_str(), a.out.c_str(), a.exr.empty() ? "" : " + ", a.exr.c_str());
    std::printf("  backend      %s (%s)\n", decision.useGl ? "gl" : "cpu", r.device.c_str());
    std::printf("  camera       %.3f, %.3f, %.3f  yaw %.2f  pitch %.2f  fov %.1f  %dx%d", camera.xWorld, camera.yWorld, camera.zWorld,
                camera.yawDeg, camera.pitchDeg, camera.fovYDeg, camera.width, camera.height);
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
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-render", [&] {
        RenderArgs a;
        if (!parseOptions(argc, argv, a)) return 0;
        hc::cli::BackendDecision decision = chooseBackend(a.backend);
        checkOutputs(a);
        // Without a cache the CPU backend reads the grid out of core; the GL one needs the grid and a cache in memory.
        auto loaded = hc::cli::loadScene("hc-render", a.gridPath, a.setup, !decision.useGl);
        if (loaded->scene->outOfCore() && decision.useGl && a.backend == hc::cli::Backend::Auto) {
            decision.useGl = false;
            decision.note = "--out-of-core: the GL backend needs the whole grid and an influence cache: rendering on the CPU";
        }
        const hc::render::Camera camera = hc::cli::initialCamera(a.setup, *loaded->scene);
        refuseCameraBelowTerrain(*loaded->scene, camera);
        const Rendered rendered = renderImage(decision, *loaded->scene, camera, a.setup.options);
        writeOutputs(a, rendered);
        printSummary(a, decision, camera, rendered);
        return 0;
    });
}
