// hc-view: the interactive viewer of a grid's smooth surface (a GLFW window; docs/design.md sections 5 and 9).
//
// The image comes from a render backend (view/backends.h: the CPU one on a worker thread, or the GL one in the
// window's context), chosen by the rule hc-render follows (backend_choice.h) from what the window's context
// offers; the Viewer (view/viewer.h) draws it with a HUD over it and flies the camera.
#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include "heightcast/core/quantile.h"
#include "heightcast/support/backend_choice.h"
#include "heightcast/support/cli.h"
#include "heightcast/support/render_setup.h"
#include "view/backends.h"
#include "view/viewer.h"
#include "view/window.h"
#include "heightcast/support/view_support.h"
#include "heightcast/core/error.h"
#include "heightcast/core/heap.h"

namespace {

struct ViewArgs {
    std::string gridPath, screenshot;
    hc::cli::Backend backend = hc::cli::Backend::Auto;
    int frames = 0;          // 0: interactive
    std::string keys;        // --keys: pressed one before each scripted frame
    bool play = false;       // --play: scripted frames step through the water steps
    bool offscreen = false;  // --offscreen, or scripted frames without a display
    hc::cli::RenderSetup setup{"1280x720"};
};

// The options, validated, with a --bookmark's view as the setup's camera; false after --help.
bool parseOptions(int argc, char** argv, ViewArgs& a) {
    int bookmarkSlot = 0;
    std::string backendText = "auto";
    hc::cli::Parser p(
        "hc-view",
        "GRID.hcg [--camera X,Y,Z,YAW,PITCH,FOV[,ROLL] | --look-at EX,EY,EZ,TX,TY,TZ[,FOV]] [--backend gl|cpu|auto] "
        "[options]",
        "Opens a window on the smooth surface of a grid (terrain, and water where the grid has water_depth)\n"
        "and lets you fly over it (press H in the window for the controls); a HUD shows per-stage timings,\n"
        "the camera and the height above ground. Coordinates in the grid's CRS [m]; angles in degrees:\n"
        "yaw 0 looks north, 90 east; pitch negative looks down. Without a camera option: hc-render's\n"
        "overview. Bookmarks (Shift+1-9 saves, 1-9 loads) live in GRID.bookmarks.json beside the grid.\n"
        "Needs a display (DISPLAY) for a window; without one, --frames N renders its frames offscreen.");
    p.positional("GRID.hcg", "grid file", a.gridPath);
    a.setup.addCameraOptions(p, "--bookmark");
    p.option("--bookmark", "N", "first view: bookmark N (1..9) of GRID.bookmarks.json (default: none)", bookmarkSlot);
    p.option("--backend", "gl|cpu|auto",
             "renderer: the OpenGL 4.3 compute backend, the CPU one, or GL when it runs on a GPU (CPU where\n"
             "OpenGL 4.3 is missing or only software rendering such as llvmpipe) (default auto)",
             backendText);
    a.setup.addRenderOptions(p);
    p.option("--frames", "N",
             "render N frames of a short scripted camera motion ending at the given view, then exit (default 0 = "
             "interactive)",
             a.frames);
    p.option("--screenshot", "OUT.png", "with --frames: write the window's last frame (image and HUD) as a PNG",
             a.screenshot);
    p.flag("--play",
           "with --frames: each frame after the first shows the next water step (playback, wrapping around); the last\n"
           "      frame's switch time is printed",
           a.play);
    p.flag("--offscreen",
           "with --frames: no window; the frames render into a framebuffer of --size in a headless OpenGL context\n"
           "      (EGL: a GPU without a display, else Mesa's llvmpipe) (default: only where there is no display)",
           a.offscreen);
    p.option("--keys", "KEYS",
             "with --frames: press these keys in turn, one before each frame, as in the window (letters, digits,\n"
             "      space; e.g. NBB sets an error budget of 1 px and halves it twice) (default none)",
             a.keys);
    if (!p.parse(argc, argv)) return false;
    a.setup.finish();
    a.backend = hc::cli::parseBackend(backendText);
    if (a.frames < 0 || a.frames > 100000)
        throw hc::Error("--frames " + std::to_string(a.frames) + " is outside 0..100000");
    if (a.play && a.frames == 0) throw hc::Error("--play needs --frames N (interactively, Space plays the steps)");
    if (a.offscreen && a.frames == 0) throw hc::Error("--offscreen needs --frames N (a window is needed to fly)");
    if (!a.keys.empty() && a.frames == 0) throw hc::Error("--keys needs --frames N (interactively, press them)");
    for (const char c : a.keys)
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != ' ')
            throw hc::Error(std::string("--keys: '") + c + "' is not a letter, a digit or a space");
    if (a.keys.size() > size_t(a.frames))
        throw hc::Error("--keys: " + std::to_string(a.keys.size()) + " keys for " + std::to_string(a.frames) +
                        " frames (one a frame)");
    if (!a.screenshot.empty()) {
        if (a.frames == 0) throw hc::Error("--screenshot needs --frames N (the number of frames to render first)");
        hc::cli::checkWritable(a.screenshot, "screenshot");
        hc::cli::checkNotSame(a.screenshot, a.gridPath, "screenshot");
    }
    if (p.given("--bookmark")) {  // before any work: the file and the slot must be there
        if (bookmarkSlot < 1 || bookmarkSlot > 9)
            throw hc::Error("--bookmark " + std::to_string(bookmarkSlot) + " is outside 1..9");
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

// Whether there is a display to open a window on; without one, scripted frames go offscreen (saying so) and an
// interactive run is refused.
void chooseDisplay(ViewArgs& a) {
    const char* display = std::getenv("DISPLAY");
    const char* wayland = std::getenv("WAYLAND_DISPLAY");
    if ((display && *display) || (wayland && *wayland) || a.offscreen) return;
    if (a.frames == 0)
        throw hc::Error(
            "no display: DISPLAY is not set (hc-view needs an X display for its window; without one, --frames N "
            "renders scripted frames offscreen, or run it under xvfb-run -a, or render images with hc-render)");
    a.offscreen = true;
    std::fprintf(stderr,
                 "hc-view: note: no display (DISPLAY is not set): the %d frames render offscreen, in a headless "
                 "OpenGL context (--offscreen)\n",
                 a.frames);
}

// The backend `decision` gave, made in the window's context (`gl`). Where the GL backend cannot be made there
// after all, the choice is made again with its reason: --backend gl fails with it, auto renders on the CPU and
// says why. The first time, prints the note and the backend on stderr; `note` is the note ("" when none). Later
// calls (a new water step's scene) use the backend chosen the first time.
class BackendMaker {
public:
    BackendMaker(hc::cli::Backend requested, hc::cli::BackendDecision decision, hc::cli::GlOnHand gl, unsigned threads)
        : requested_(requested), decision_(std::move(decision)), gl_(std::move(gl)), threads_(threads) {}
    std::unique_ptr<hc::view::ViewBackend> operator()(const hc::render::Scene& scene) {
        std::unique_ptr<hc::view::ViewBackend> backend;
        if (decision_.useGl) {
            try {
                backend = hc::view::makeGlBackend(scene);
            } catch (const hc::Error& e) {
                if (made_) throw;
                gl_.unavailable = e.what();
                decision_ = hc::cli::decideBackend(requested_, gl_);
            }
        }
        if (!backend) backend = hc::view::makeCpuBackend(scene, threads_);
        if (!made_) {
            if (!decision_.note.empty()) std::fprintf(stderr, "hc-view: note: %s\n", decision_.note.c_str());
            std::fprintf(stderr, "hc-view: backend %s (%s)\n", backend->name().c_str(), backend->device().c_str());
        }
        made_ = true;
        return backend;
    }
    const std::string& note() const { return decision_.note; }

private:
    hc::cli::Backend requested_;
    hc::cli::BackendDecision decision_;
    hc::cli::GlOnHand gl_;
    unsigned threads_;
    bool made_ = false;
};

// The last camera and the last frame's stage times, after a scripted run.
void printSummary(const ViewArgs& a, const hc::view::Viewer& viewer) {
    if (!a.screenshot.empty())
        std::printf("hc-view: %s -> %s (%d frames)\n", a.gridPath.c_str(), a.screenshot.c_str(), a.frames);
    const hc::render::Camera& c = viewer.camera();
    std::printf("  camera       %.3f, %.3f, %.3f  yaw %.2f  pitch %.2f  fov %.1f  %dx%d\n", c.xWorld, c.yWorld,
                c.zWorld, c.yawDeg, c.pitchDeg, c.fovYDeg, c.width, c.height);
    if (viewer.stepCount() > 1)
        std::printf(
            "  step         %zu of %zu (last switch %.1f ms: the step's water, its pyramid, a new scene and backend)\n",
            viewer.step(), viewer.stepCount(), viewer.lastSwitchMs());
    std::printf("%s", viewer.lastTimings().toTable().c_str());
    // The frame rate over the whole script: what a person flying would see, not the last frame's stages.
    const std::vector<double>& ms = viewer.scriptedFrameMs();
    double sum = 0;
    for (const double m : ms) sum += m;
    if (!ms.empty() && sum > 0)
        std::printf(
            "frames: %zu in %.2f s, %.1f a second; a frame median %.1f ms, 99th percentile %.1f ms, slowest "
            "%.1f ms (scheduled, rendered, drawn and shown; vsync off)\n",
            ms.size(), sum / 1e3, 1e3 * double(ms.size()) / sum, hc::quantile(ms, 0.5), hc::quantile(ms, 0.99),
            *std::max_element(ms.begin(), ms.end()));
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-view", [&] {
        ViewArgs a;
        if (!parseOptions(argc, argv, a)) return 0;
        chooseDisplay(a);
        hc::keepFreedMemory();  // frame after frame: each reuses the last one's pages (core/heap.h)
        auto window = a.offscreen ? std::make_unique<hc::view::Window>(hc::view::Window::Offscreen{}, a.setup.width,
                                                                       a.setup.height)
                                  : std::make_unique<hc::view::Window>("hc-view: " + a.gridPath, a.setup.width,
                                                                       a.setup.height, a.frames == 0);
        // --backend gl without a 4.3 context fails here, before any work.
        const hc::cli::BackendDecision decision = hc::cli::decideBackend(a.backend, window->gl());
        auto loaded = hc::cli::loadScene("hc-view", a.gridPath, a.setup, a.setup.colorBy.empty());
        auto maker = std::make_shared<BackendMaker>(a.backend, decision, window->gl(), a.setup.options.threads);
        auto backend = (*maker)(*loaded->scene);  // the first one; a new water step's scene gets a new one from `maker`
        window->show();
        hc::view::Viewer viewer(
            *window, *loaded, a.setup, a.gridPath, std::move(backend),
            [maker](const hc::render::Scene& scene) { return (*maker)(scene); }, maker->note());
        if (a.frames == 0) {
            viewer.run();
            return 0;
        }
        viewer.runScripted(a.frames, a.screenshot, a.play, a.keys);
        printSummary(a, viewer);
        return 0;
    });
}
