// apps/view/viewer.cpp: the Viewer's frames and drawing (see viewer.h; input in input.cpp).
#include "view/viewer.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>

#include <fmt/format.h>

#include "heightcast/core/error.h"
#include "heightcast/core/timer.h"

namespace hc::view {

using render::Camera;
using render::RenderOptions;

Viewer::Viewer(Window& window, cli::LoadedScene& loaded, const cli::RenderSetup& setup, std::string gridPath,
               std::unique_ptr<ViewBackend> backend, BackendFactory makeBackend, std::string backendNote)
    : window_(window),
      loaded_(loaded),
      setup_(setup),
      makeBackend_(std::move(makeBackend)),
      ground_(loaded),
      options_(setup.options),
      gridPath_(std::move(gridPath)),
      backend_(std::move(backend)),
      backendNote_(std::move(backendNote)),
      hudTexture_(makeTexture()) {
    const Grid& shape = loaded_.file ? loaded_.file->shape() : loaded_.grid;
    step_ = shape.step;
    stepCount_ = shape.stepCount();
    for (const StepInfo& s : shape.steps) stepTimesS_.push_back(s.timeS);
    toggles_.cells = options_.cellOutlines;
    baseWaterMinDepthM_ = options_.waterMinDepthM;
    const auto [fw, fh] = window_.framebufferSize();
    camera_ = cli::initialCamera(setup, *loaded_.scene);
    camera_.width = std::max(1, fw), camera_.height = std::max(1, fh);
    home_ = camera_;
    bookmarksPath_ = bookmarksPath(gridPath_);
    try {
        bookmarks_ = readBookmarks(bookmarksPath_);
    } catch (const Error& e) {
        std::fprintf(stderr, "hc-view: warning: %s (bookmarks start empty; saving one replaces the file)\n", e.what());
        flash("warning: " + bookmarksPath_ + " is broken: bookmarks start empty");
    }
    installCallbacks();
}

void Viewer::run() {
    double last = window_.seconds();
    while (!window_.shouldClose()) {
        const double now = window_.seconds();
        const double dt = std::min(0.25, now - last);
        last = now;
        pollMotion(dt);
        advancePlayback();
        schedule(false);
        if (backend_->collect(shown_)) frameDone();
        draw();
        window_.swapBuffers();
        // Wait in the event queue, never spin: the CPU backend needs the cores. Input wakes it at once;
        // otherwise ~60 Hz while frames are coming or keys are held, 2 Hz when all is still.
        if (backend_->busy() || moving() || !shownCurrent())
            window_.waitEvents(1.0 / 60);
        else
            window_.waitEvents(0.5);
    }
}

void Viewer::runScripted(int frames, const std::string& screenshot, bool play, const std::string& keys) {
    const Camera end = camera_;
    scriptedFrameMs_.clear();
    for (int i = 0; i < frames && !window_.shouldClose(); ++i) {
        const Stopwatch frame;
        const int left = frames - 1 - i;
        if (size_t(i) < keys.size())  // GLFW's codes of letters, digits and space are their upper-case ASCII codes
            onKey(std::toupper(static_cast<unsigned char>(keys[size_t(i)])), GLFW_PRESS, 0);
        if (play && i > 0 && stepCount_ > 1) showStep((step_ + 1) % stepCount_);
        camera_ = end;
        if (left > 0) {  // approach the final view: turned a little and further back
            look(camera_, -0.4 * left, 0.0);
            fly(camera_, -0.01 * left * ground_.heightAboveGroundOr(camera_, 100.0), 0, 0);
            lastChange_ = Clock::now();
        } else {
            lastChange_ = Clock::now() - std::chrono::seconds(10);
        }
        schedule(true);
        backend_->wait();
        if (backend_->collect(shown_)) frameDone();
        draw();
        if (i == frames - 1 && !screenshot.empty()) saveScreenshot(window_, screenshot);
        window_.swapBuffers();
        window_.pollEvents();
        scriptedFrameMs_.push_back(frame.milliseconds());
    }
}

void Viewer::showStep(size_t step) {
    if (step == step_ || step >= std::max<size_t>(1, stepCount_)) return;
    const Stopwatch clock;
    backend_->wait();  // idle from here: it refers to the scene replaced below and renders nothing until it is set
    cli::switchStep("hc-view", loaded_, gridPath_, setup_, step);
    // The GL backend is handed the new scene (its shaders compiled once); the CPU one is made again.
    if (!backend_->setScene(*loaded_.scene)) backend_ = makeBackend_(*loaded_.scene);
    step_ = step;
    lastSwitchMs_ = clock.milliseconds();
    stepShownAt_ = Clock::now();
    submitted_ = false;  // the frame on screen shows the old water: render the view again
}

void Viewer::advancePlayback() {
    if (!playing_ || stepCount_ < 2 || !shownCurrent() || backend_->busy()) return;
    if (Clock::now() - stepShownAt_ < std::chrono::duration<double>(1.0 / stepsPerSecond_)) return;
    try {
        showStep((step_ + 1) % stepCount_);
    } catch (const Error& e) {
        playing_ = false;
        flash(std::string("playback stopped: ") + e.what());
    }
}

// "step 3/24  t 1:00:00 (3600 s)  playing 2/s  switch 12 ms", or "" without steps.
std::string Viewer::stepLine() const {
    if (stepCount_ < 2) return "";
    const double t = step_ < stepTimesS_.size() ? stepTimesS_[step_] : 0.0;
    const long whole = std::lround(std::floor(std::abs(t)));
    const std::string clock =
        fmt::format("{}{}:{:02}:{:02}", t < 0 ? "-" : "", whole / 3600, (whole / 60) % 60, whole % 60);
    return fmt::format("step {}/{}  t {} ({:g} s)  {}  switch {:.0f} ms   [ ] step  Space play/pause  - + speed", step_,
                       stepCount_ - 1, clock, t,
                       playing_ ? fmt::format("playing {:g}/s", stepsPerSecond_) : std::string("paused"),
                       lastSwitchMs_);
}

bool Viewer::moving() const { return Clock::now() - lastChange_ < std::chrono::milliseconds(250); }

Camera Viewer::withSize(Camera c) const {
    c.width = camera_.width, c.height = camera_.height;
    return c;
}

RenderOptions Viewer::currentOptions() const {
    RenderOptions o = options_;
    o.cellOutlines = toggles_.cells;
    // Water off: no depth is deep enough to be drawn.
    o.waterMinDepthM = toggles_.water ? baseWaterMinDepthM_ : HUGE_VAL;
    // The tint would colour the legend too, and the legend's colours no longer hold.
    if (toggles_.cascadeTint) o.legend = false;
    return o;
}

namespace {
bool sameView(const Camera& a, const Camera& b) {
    return a.xWorld == b.xWorld && a.yWorld == b.yWorld && a.zWorld == b.zWorld && a.yawDeg == b.yawDeg &&
           a.pitchDeg == b.pitchDeg && a.fovYDeg == b.fovYDeg && a.width == b.width && a.height == b.height;
}
}  // namespace

// Whether what is (being) rendered at full resolution is the current view with the current options.
bool Viewer::shownCurrent() const {
    return submitted_ && submittedFull_ && sameView(submittedCamera_, camera_) && submittedToggles_ == togglesKey();
}

int Viewer::togglesKey() const {
    return (toggles_.water ? 1 : 0) | (toggles_.cells ? 2 : 0) | (toggles_.cascadeTint ? 4 : 0);
}

// The frame on screen's distance along the centre ray when it was rendered from this camera's position and
// direction; +inf otherwise (Ground::pickCentre then marches the surface).
double Viewer::centreDistanceM() const {
    const Camera& sc = shown_.camera;
    const bool same = sc.xWorld == camera_.xWorld && sc.yWorld == camera_.yWorld && sc.zWorld == camera_.zWorld &&
                      sc.yawDeg == camera_.yawDeg && sc.pitchDeg == camera_.pitchDeg;
    return same ? shown_.centreDistanceM : INFINITY;
}

// Starts a frame when the backend is free and the view changed: reduced resolution while moving,
// full when still. The reduced size aims at ~60 ms from the last frame's time per pixel.
void Viewer::schedule(bool force) {
    if (backend_->busy()) return;
    const bool still = !moving();
    if (!force && submitted_ && sameView(submittedCamera_, camera_) && submittedToggles_ == togglesKey() &&
        (submittedFull_ || !still))
        return;
    Camera c = camera_;
    bool full = still;
    if (!full && msPerPixel_ > 0) {
        const double pixels = double(camera_.width) * camera_.height;
        const double scale = std::clamp(std::sqrt(60.0 / (msPerPixel_ * pixels)), 0.15, 1.0);
        if (scale < 0.95) {
            c.width = std::max(8, int(camera_.width * scale));
            c.height = std::max(8, int(camera_.height * scale));
        } else {
            full = true;
        }
    } else if (!full) {
        c.width = std::max(8, camera_.width / 3), c.height = std::max(8, camera_.height / 3);
    }
    RenderOptions o = currentOptions();
    if (c.width != camera_.width) {  // a moving frame: coarser cascades too (the approximation's cost is per texel)
        // A power of two, so that consecutive moving frames share the texture side, and so the texel sizes the CPU
        // worker's CascadeCache needs to keep their texels.
        const double scale = double(c.width) / camera_.width;
        int side = std::min(128, o.texelsPerSide);
        while (side * 2 <= int(o.texelsPerSide * scale)) side *= 2;
        o.texelsPerSide = side;
    }
    backend_->submit(c, o, full || (c.width == camera_.width && c.height == camera_.height), toggles_.cascadeTint);
    submitted_ = true;
    submittedFull_ = full;
    submittedCamera_ = camera_;
    submittedToggles_ = togglesKey();
}

void Viewer::frameDone() {
    const double pixels = double(shown_.width) * shown_.height;
    if (shown_.timings.totalMs > 0 && pixels > 0) msPerPixel_ = shown_.timings.totalMs / pixels;
    const auto now = Clock::now();
    frameTimes_.push_back(now);
    while (!frameTimes_.empty() && now - frameTimes_.front() > std::chrono::seconds(2))
        frameTimes_.erase(frameTimes_.begin());
}

// Frames finished per second over the last two seconds while frames keep coming; otherwise what the last
// frame's time allows.
double Viewer::framesPerSecond() const {
    if (frameTimes_.size() >= 3) {
        const double s = std::chrono::duration<double>(frameTimes_.back() - frameTimes_.front()).count();
        if (s > 0) return double(frameTimes_.size() - 1) / s;
    }
    return shown_.timings.totalMs > 0 ? 1000.0 / shown_.timings.totalMs : 0.0;
}

void Viewer::draw() {
    window_.clear();
    if (shown_.texture) window_.drawTexture(shown_.texture, shown_.flipY, false);
    if (!toggles_.hud && !toggles_.help) return;
    HudStatus s;
    s.gridPath = gridPath_;
    s.backendName = backend_->name(), s.backendDevice = backend_->device();
    s.backendNote = backendNote_;
    s.contextInfo = window_.gl().device;
    s.framesPerSecond = framesPerSecond();
    s.frameWidth = shown_.width, s.frameHeight = shown_.height, s.frameFull = shown_.full;
    s.timings = shown_.timings;
    s.camera = camera_;
    s.heightAboveGroundM = ground_.heightAboveGround(camera_);
    s.aboveHighestM = ground_.aboveHighestM(camera_);
    s.speedMps = ground_.speed(camera_);
    s.toggles = toggles_;
    s.stepLine = stepLine();
    const auto [fw, fh] = window_.framebufferSize();
    if (hud_.compose(s, fw, fh)) {  // upload only what changed
        const Overlay& o = hud_.overlay();
        uploadRgba(hudTexture_, o.width, o.height, o.rgba.data());
    }
    window_.drawTexture(hudTexture_, true, true);
}

}  // namespace hc::view
