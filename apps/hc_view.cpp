// hc-view: the interactive viewer of a grid's smooth surface (a GLFW window; DESIGN.md sections 5 and 9).
//
// The image comes from a render backend (view/backends.h: the CPU one on a worker thread, or the GL one in the
// window's context), chosen by the rule hc-render follows (backend_choice.h) from what the window's context
// offers; the Viewer (view/viewer.h) draws it with a HUD over it and flies the camera.
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include "backend_choice.h"
#include "cli.h"
#include "render_setup.h"
#include "view/backends.h"
#include "view/viewer.h"
#include "view/window.h"
#include "view_support.h"
#include "heightcast/core/error.h"

namespace {

struct ViewArgs {
    std::string gridPath, screenshot;
    hc::cli::Backend backend = hc::cli::Backend::Auto;
    int frames = 0;  // 0: interactive
    hc::cli::RenderSetup setup{"1280x720"};
};

// The options, validated, with a --bookmark's view as the setup's camera; false after --help.
bool parseOptions(int argc, char** argv, ViewArgs& a) {
    int bookmarkSlot = 0;
    std::string backendText = "auto";
    hc::cli::Parser p("hc-view", "GRID.hcg [--camera X,Y,Z,YAW,PITCH,FOV[,ROLL] | --look-at EX,EY,EZ,TX,TY,TZ[,FOV]] [--backend gl|cpu|auto] [options]",
                      "Opens a window on the smooth surface of a grid (terrain, and water where the grid has water_depth)\n"
                      "and lets you fly over it (press H in the window for the controls); a HUD shows per-stage timings,\n"
                      "the camera and the height above ground. Coordinates in the grid's CRS [m]; angles in degrees:\n"
                      "yaw 0 looks north, 90 east; pitch negative looks down. Without a camera option: hc-render's\n"
                      "overview. Bookmarks (Shift+1-9 saves, 1-9 loads) live in GRID.bookmarks.json beside the grid.\n"
                      "Needs a display (DISPLAY); without one: xvfb-run -a hc-view GRID.hcg --frames 30 --screenshot OUT.png");
    p.positional("GRID.hcg", "grid file", a.gridPath);
    a.setup.addCameraOptions(p, "--bookmark");
    p.option("--bookmark", "N", "first view: bookmark N (1..9) of GRID.bookmarks.json (default: none)", bookmarkSlot);
    p.option("--backend", "gl|cpu|auto", "renderer: the OpenGL 4.3 compute backend, the CPU one, or GL when it runs on a GPU (CPU where\n"
             "OpenGL 4.3 is missing or only software rendering such as llvmpipe) (default auto)", backendText);
    a.setup.addRenderOptions(p);
    p.option("--frames", "N", "render N frames of a short scripted camera motion ending at the given view, then exit (default 0 = interactive)", a.frames);
    p.option("--screenshot", "OUT.png", "with --frames: write the window's last frame (image and HUD) as a PNG", a.screenshot);
    if (!p.parse(argc, argv)) return false;
    a.setup.finish();
    a.backend = hc::cli::parseBackend(backendText);
    if (a.frames < 0 || a.frames > 100000) throw hc::Error("--frames " + std::to_string(a.frames) + " is outside 0..100000");
    if (!a.screenshot.empty()) {
        if (a.frames == 0) throw hc::Error("--screenshot needs --frames N (the number of frames to render first)");
        hc::cli::checkWritable(a.screenshot, "screenshot");
        hc::cli::checkNotSame(a.screenshot, a.gridPath, "screenshot");
    }
    if (p.given("--bookmark")) {  // before any work: the file and the slot must be there
        if (bookmarkSlot < 1 || bookmarkSlot > 9) throw hc::Error("--bookmark " + std::to_string(bookmarkSlot) + " is outside 1..9");
        const std::string path = hc::view::bookmarksPath(a.gridPath);
        const hc::view::Bookmarks marks = hc::view::readBookmarks(path);
        if (!marks[bookmarkSlot]) throw hc::Error(path + ": no bookmark " + std::to_string(bookmarkSlot));
        hc::render::Camera c;
        c.width = a.setup.width, c.height = a.setup.height;
        hc::view::applyBookmark(*marks[bookmarkSlot], c);
        a.setup.camera = c;
    }
    return true;
}

void requireDisplay() {
    const char* display = std::getenv("DISPLAY");
    const char* wayland = std::getenv("WAYLAND_DISPLAY");
    if ((!display || !*display) && (!wayland || !*wayland))
        throw hc::Error("no display: DISPLAY is not set (hc-view needs an X display; without one, run it under "
                        "xvfb-run -a, or render images with hc-render)");
}

// The backend `decision` gave, made in the window's context (`gl`). Where the GL backend cannot be made there
// after all, the choice is made again with its reason: --backend gl fails with it, auto renders on the CPU and
// says why. Prints the note and the backend on stderr; `note` is the note ("" when none).
std::unique_ptr<hc::view::ViewBackend> makeBackend(hc::cli::Backend requested, hc::cli::BackendDecision decision, hc::cli::GlOnHand gl,
                                                   const hc::cli::LoadedScene& loaded, unsigned threads, std::string& note) {
    std::unique_ptr<hc::view::ViewBackend> backend;
    if (decision.useGl) {
        try {
            backend = hc::view::makeGlBackend(*loaded.scene);
        } catch (const hc::Error& e) {
            gl.unavailable = e.what();
            decision = hc::cli::decideBackend(requested, gl);
        }
    }
    if (!backend) backend = hc::view::makeCpuBackend(*loaded.scene, threads);
    note = decision.note;
    if (!note.empty()) std::fprintf(stderr, "hc-view: note: %s\n", note.c_str());
    std::fprintf(stderr, "hc-view: backend %s (%s)\n", backend->name().c_str(), backend->device().c_str());
    return backend;
}

// The last camera and the last frame's stage times, after a scripted run.
void printSummary(const ViewArgs& a, const hc::view::Viewer& viewer) {
    if (!a.screenshot.empty()) std::printf("hc-view: %s -> %s (%d frames)\n", a.gridPath.c_str(), a.screenshot.c_str(), a.frames);
    const hc::render::Camera& c = viewer.camera();
    std::printf("  camera       %.3f, %.3f, %.3f  yaw %.2f  pitch %.2f  fov %.1f  %dx%d\n", c.xWorld, c.yWorld, c.zWorld, c.yawDeg,
                c.pitchDeg, c.fovYDeg, c.width, c.height);
    std::printf("%s", viewer.lastTimings().toTable().c_str());
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-view", [&] {
        ViewArgs a;
        if (!parseOptions(argc, argv, a)) return 0;
        requireDisplay();
        hc::view::Window window("hc-view: " + a.gridPath, a.setup.width, a.setup.height, a.frames == 0);
        // --backend gl without a 4.3 context fails here, before any work.
        const hc::cli::BackendDecision decision = hc::cli::decideBackend(a.backend, window.gl());
        auto loaded = hc::cli::loadScene("hc-view", a.gridPath, a.setup);
        std::string note;
        auto backend = makeBackend(a.backend, decision, window.gl(), *loaded, a.setup.options.threads, note);
        window.show();
        hc::view::Viewer viewer(window, *loaded, a.setup, a.gridPath, std::move(backend), note);
        if (a.frames == 0) {
            viewer.run();
            return 0;
        }
        viewer.runScripted(a.frames, a.screenshot);
        printSummary(a, viewer);
        return 0;
    });
}
