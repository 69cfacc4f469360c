// apps/view/viewer.h: hc-view's loop. The Viewer owns the camera and the switches, asks its backend for frames
// (reduced resolution while the camera moves, sized from the last frame's time; full resolution once it stands
// still), and draws the latest frame with the HUD over it. Its input handlers live in input.cpp.
#pragma once

#include <array>
#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "heightcast/support/render_setup.h"
#include "view/backends.h"
#include "view/ground.h"
#include "view/hud.h"
#include "view/window.h"
#include "heightcast/support/view_support.h"

namespace hc::view {

// Makes the viewer's backend over a scene, in the window's context (again after each change of water step).
using BackendFactory = std::function<std::unique_ptr<ViewBackend>(const render::Scene&)>;

class Viewer {
public:
    // `window` and `loaded` serve the viewer's whole life; `backend` (made in the window's context) renders until the
    // water step changes, when `makeBackend` makes one over the new scene; `backendNote` is the backend choice's
    // note ("" when none), shown on the HUD. Reads the grid's bookmarks (a broken file: a warning on stderr and none).
    Viewer(Window& window, cli::LoadedScene& loaded, const cli::RenderSetup& setup, std::string gridPath,
           std::unique_ptr<ViewBackend> backend, BackendFactory makeBackend, std::string backendNote);
    ~Viewer();

    const render::Camera& camera() const { return camera_; }
    const render::Timings& lastTimings() const { return shown_.timings; }  // of the frame on screen

    // Interactive: until the window closes or Esc.
    void run();
    // Scripted: `frames` frames of a small motion that ends at the initial camera (rendered at full
    // resolution), then, unless `screenshot` is "", the window's contents as a PNG there. `play`: each frame after
    // the first shows the next water step (wrapping around), as playback does.
    // `keys`: pressed in turn, one before each frame ('A'..'Z', '0'..'9', ' ': the window's keys, without modifiers).
    void runScripted(int frames, const std::string& screenshot, bool play = false, const std::string& keys = "");
    // Each scripted frame's wall time [ms]: scheduled, rendered, drawn with the HUD and swapped (vsync off).
    const std::vector<double>& scriptedFrameMs() const { return scriptedFrameMs_; }

    // Water steps (docs/design.md section 6): the one shown, how many, and how long the last switch took [ms] (reading
    // the step, its pyramid, the new scene and backend; the frame after it is timed as any frame).
    size_t step() const { return step_; }
    size_t stepCount() const { return stepCount_; }
    double lastSwitchMs() const { return lastSwitchMs_; }

private:
    using Clock = std::chrono::steady_clock;

    // input.cpp: GLFW's callbacks, keys, mouse, scroll and held-key motion.
    void installCallbacks();
    void onKey(int key, int action, int mods);
    void bookmark(int slot, bool save);
    void onScroll(double dy);
    void onButton(int button, int action);
    void onResize(int w, int h);
    void pollMotion(double dt);

    // viewer.cpp: frames and drawing.
    void changed() { lastChange_ = Clock::now(); }
    bool moving() const;
    render::Camera withSize(render::Camera c) const;
    render::RenderOptions currentOptions() const;
    bool shownCurrent() const;
    int togglesKey() const;
    double centreDistanceM() const;
    void schedule(bool force);
    void frameDone();
    double framesPerSecond() const;
    void showStep(size_t step);  // switches the water step (waits for the frame in flight)
    void advancePlayback();      // playing: the next step once the current one is on screen and its time is up
    std::string stepLine() const;
    void draw();
    void flash(const std::string& text) { hud_.flash(text); }

    Window& window_;
    cli::LoadedScene& loaded_;
    cli::RenderSetup setup_;
    BackendFactory makeBackend_;
    Ground ground_;
    render::RenderOptions options_;
    double baseWaterMinDepthM_ = 0.01;
    std::string gridPath_;
    std::unique_ptr<ViewBackend> backend_;
    std::string backendNote_;
    GLuint hudTexture_;
    Hud hud_;
    Toggles toggles_;
    render::Camera camera_, home_, submittedCamera_;
    bool submitted_ = false, submittedFull_ = false;
    int submittedToggles_ = 0;
    Shown shown_;
    double msPerPixel_ = 0;
    Clock::time_point lastChange_ = Clock::now() - std::chrono::seconds(10);
    std::vector<Clock::time_point> frameTimes_;
    double mouseX_ = 0, mouseY_ = 0;
    std::optional<std::array<double, 3>> pivot_;  // of the left drag under way
    std::string bookmarksPath_;
    Bookmarks bookmarks_;
    size_t step_ = 0, stepCount_ = 0;
    std::vector<double> stepTimesS_;  // of every step (empty without steps)
    bool playing_ = false;
    double stepsPerSecond_ = 2;
    double lastSwitchMs_ = 0;
    std::vector<double> scriptedFrameMs_;
    Clock::time_point stepShownAt_ = Clock::now();
};

}  // namespace hc::view
