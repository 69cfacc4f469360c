// hc-view: the interactive viewer of a grid's smooth surface (a GLFW window; DESIGN.md sections 5 and 9).
//
// The image comes from a render backend (CPU: renderFrame() on a worker thread, uploaded to a texture; GL:
// GlRenderer::renderToTexture() in the window's context) and is drawn with a fullscreen triangle; a HUD
// (5x7 bitmap font into an RGBA texture) is blended over it. While the camera moves the image is rendered
// at a reduced resolution sized from the last frame's time, and at full resolution once it stands still.
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#define GL_GLEXT_PROTOTYPES
#include <GL/glcorearb.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include "backend_choice.h"
#include "cli.h"
#include "render_setup.h"
#include "view_support.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/influence/surface.h"
#include "heightcast/render/image_io.h"
#include "heightcast/render/gl/gl_renderer.h"
#include "heightcast/render/renderer.h"

namespace {

using hc::render::Camera;
using hc::render::Frame;
using hc::render::RenderOptions;
using hc::render::Timings;
using Clock = std::chrono::steady_clock;

// ------------------------------------------------------------------------------------------------ GL

std::string glfwMessage;  // the last GLFW error, for our own messages
void onGlfwError(int, const char* what) { glfwMessage = what ? what : "unknown GLFW error"; }

GLuint compile(GLenum kind, const char* src) {
    GLuint s = glCreateShader(kind);
    glShaderSource(s, 1, &src, nullptr);
    glCompileShader(s);
    GLint ok = 0;
    glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        char log[2048] = {};
        glGetShaderInfoLog(s, sizeof log, nullptr, log);
        throw hc::Error(std::string("the display shader does not compile: ") + log);
    }
    return s;
}

// A texture drawn over the whole window by one triangle; `flipY` for images with row 0 at the top.
class QuadProgram {
public:
    QuadProgram() {
        const char* vs =
            "#version 330 core\n"
            "uniform int flipY;\n"
            "out vec2 uv;\n"
            "void main() {\n"
            "  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));\n"
            "  uv = vec2(p.x, flipY == 1 ? 1.0 - p.y : p.y);\n"
            "  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);\n"
            "}\n";
        const char* fs =
            "#version 330 core\n"
            "uniform sampler2D tex;\n"
            "in vec2 uv;\n"
            "out vec4 color;\n"
            "void main() { color = texture(tex, uv); }\n";
        GLuint v = compile(GL_VERTEX_SHADER, vs), f = compile(GL_FRAGMENT_SHADER, fs);
        prog_ = glCreateProgram();
        glAttachShader(prog_, v);
        glAttachShader(prog_, f);
        glLinkProgram(prog_);
        glDeleteShader(v);
        glDeleteShader(f);
        GLint ok = 0;
        glGetProgramiv(prog_, GL_LINK_STATUS, &ok);
        if (!ok) throw hc::Error("the display shader program does not link");
        flipLoc_ = glGetUniformLocation(prog_, "flipY");
        glGenVertexArrays(1, &vao_);
    }
    void draw(GLuint texture, bool flipY) const {
        glUseProgram(prog_);
        glUniform1i(flipLoc_, flipY ? 1 : 0);
        glActiveTexture(GL_TEXTURE0);
        glBindTexture(GL_TEXTURE_2D, texture);
        glBindVertexArray(vao_);
        glDrawArrays(GL_TRIANGLES, 0, 3);
    }

private:
    GLuint prog_ = 0, vao_ = 0;
    GLint flipLoc_ = -1;
};

GLuint makeTexture() {
    GLuint t = 0;
    glGenTextures(1, &t);
    glBindTexture(GL_TEXTURE_2D, t);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    return t;
}

// -------------------------------------------------------------------------------------------- backends

// One rendered image, ready to draw.
struct Shown {
    GLuint texture = 0;
    bool flipY = true;             // row 0 at the top (CPU frames) or at the bottom (GL textures)
    int width = 0, height = 0;
    Camera camera;
    bool full = false;             // rendered at the window's full resolution
    Timings timings;
    float centreDistanceM = INFINITY;  // along the centre pixel's ray; +inf on a miss or when unknown
};

// What the viewer asks of a backend: start a frame (possibly asynchronously), and collect the finished one.
class ViewBackend {
public:
    virtual ~ViewBackend() = default;
    virtual bool busy() const = 0;
    virtual void submit(const Camera& c, const RenderOptions& o, bool full, bool cascadeTint) = 0;
    // True when a frame finished since the last call; `shown` then describes it. Throws the render's error.
    virtual bool collect(Shown& shown) = 0;
    virtual std::string name() const = 0;
    virtual std::string device() const = 0;
    virtual bool cascadeTintSupported() const = 0;
};

// Tints each pixel by the cascade that gave its hit (the Frame's cascade index): near red, then green,
// blue, yellow.
void tintCascades(Frame& f) {
    static const float kTint[4][3] = {{1.0f, 0.35f, 0.3f}, {0.35f, 1.0f, 0.4f}, {0.35f, 0.55f, 1.0f}, {1.0f, 0.9f, 0.3f}};
    const size_t n = size_t(f.width) * size_t(f.height);
    for (size_t i = 0; i < n && i < f.cascade.size(); ++i) {
        const int c = int(f.cascade[i]);
        if (c < 0 || c > 3) continue;
        for (int k = 0; k < 3; ++k) {
            const float v = f.rgb[i * 3 + k] * (0.45f + 0.55f * kTint[c][k]);
            f.rgb[i * 3 + k] = uint8_t(std::min(255.0f, v));
        }
    }
}

// The CPU backend on a worker thread, so the window stays responsive while a frame takes 0.5 s.
class CpuBackend final : public ViewBackend {
public:
    CpuBackend(const hc::render::Scene& scene, unsigned threads)
        : scene_(scene), threads_(threads), texture_(makeTexture()), worker_([this] { loop(); }) {}
    ~CpuBackend() override {
        {
            std::lock_guard<std::mutex> l(m_);
            stop_ = true;
        }
        cv_.notify_all();
        worker_.join();
    }
    bool busy() const override {
        std::lock_guard<std::mutex> l(m_);
        return job_.has_value() || running_;
    }
    void submit(const Camera& c, const RenderOptions& o, bool full, bool cascadeTint) override {
        {
            std::lock_guard<std::mutex> l(m_);
            job_ = Job{c, o, full, cascadeTint};
        }
        cv_.notify_all();
    }
    bool collect(Shown& shown) override {
        std::unique_lock<std::mutex> l(m_);
        if (!error_.empty()) throw hc::Error(error_);
        if (!result_) return false;
        Result r = std::move(*result_);
        result_.reset();
        l.unlock();
        glBindTexture(GL_TEXTURE_2D, texture_);
        glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
        glTexImage2D(GL_TEXTURE_2D, 0, GL_RGB8, r.frame.width, r.frame.height, 0, GL_RGB, GL_UNSIGNED_BYTE, r.frame.rgb.data());
        shown.texture = texture_;
        shown.flipY = true;
        shown.width = r.frame.width, shown.height = r.frame.height;
        shown.camera = r.job.camera;
        shown.full = r.job.full;
        shown.timings = r.timings;
        const size_t centre = size_t(r.frame.height / 2) * size_t(r.frame.width) + size_t(r.frame.width / 2);
        shown.centreDistanceM = centre < r.frame.distanceM.size() ? r.frame.distanceM[centre] : INFINITY;
        return true;
    }
    // Waits for the frame in flight (scripted runs).
    void wait() {
        std::unique_lock<std::mutex> l(m_);
        done_.wait(l, [&] { return (!job_ && !running_) || !error_.empty(); });
    }
    std::string name() const override { return "CPU"; }
    std::string device() const override { return "CPU, " + std::to_string(hc::resolveThreads(threads_)) + " threads"; }
    bool cascadeTintSupported() const override { return true; }

private:
    struct Job {
        Camera camera;
        RenderOptions options;
        bool full, tint;
    };
    struct Result {
        Job job;
        Frame frame;
        Timings timings;
    };
    void loop() {
        std::unique_lock<std::mutex> l(m_);
        for (;;) {
            cv_.wait(l, [&] { return stop_ || job_.has_value(); });
            if (stop_) return;
            Job job = *job_;
            job_.reset();
            running_ = true;
            l.unlock();
            Result r{job, {}, {}};
            std::string error;
            try {
                r.frame = hc::render::renderFrame(scene_, job.camera, job.options, r.timings, &cascades_);
                if (job.tint) tintCascades(r.frame);
            } catch (const std::exception& e) {
                error = e.what();
            }
            l.lock();
            running_ = false;
            if (!error.empty()) error_ = error;
            else result_ = std::move(r);
            done_.notify_all();
        }
    }
    const hc::render::Scene& scene_;
    hc::render::CascadeCache cascades_;  // the worker's last textures: a moving camera evaluates only new texels
    unsigned threads_;
    GLuint texture_;
    mutable std::mutex m_;
    std::condition_variable cv_, done_;
    std::optional<Job> job_;
    std::optional<Result> result_;
    std::string error_;
    bool running_ = false, stop_ = false;
    std::thread worker_;
};

// The GL compute backend in the window's own context: the image stays on the GPU (renderToTexture) and is
// drawn from there. Cascade colouring needs the per-pixel cascade index, which only the read-back Frame
// (render()) carries: with K on, frames take that path and are tinted and uploaded like CPU frames.
class GlBackend final : public ViewBackend {
public:
    explicit GlBackend(std::unique_ptr<hc::render::GlRenderer> r) : r_(std::move(r)), tintTexture_(makeTexture()) {}
    bool busy() const override { return false; }
    void submit(const Camera& c, const RenderOptions& o, bool full, bool cascadeTint) override {
        Shown s;
        s.camera = c, s.full = full, s.width = c.width, s.height = c.height;
        if (cascadeTint) {
            Frame f = r_->render(c, o, s.timings);
            tintCascades(f);
            glBindTexture(GL_TEXTURE_2D, tintTexture_);
            glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
            glTexImage2D(GL_TEXTURE_2D, 0, GL_RGB8, f.width, f.height, 0, GL_RGB, GL_UNSIGNED_BYTE, f.rgb.data());
            s.texture = tintTexture_, s.flipY = true;
            const size_t centre = size_t(f.height / 2) * size_t(f.width) + size_t(f.width / 2);
            s.centreDistanceM = centre < f.distanceM.size() ? f.distanceM[centre] : INFINITY;
        } else {
            s.texture = r_->renderToTexture(c, o, s.timings);
            s.flipY = false;  // GL's convention: row 0 at the bottom
            glMemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT);
            glBindTexture(GL_TEXTURE_2D, s.texture);
            glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
            glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
        }
        next_ = s;
    }
    bool collect(Shown& shown) override {
        if (!next_) return false;
        shown = *next_;
        next_.reset();
        return true;
    }
    std::string name() const override { return "GL"; }
    std::string device() const override { return r_->deviceName(); }
    bool cascadeTintSupported() const override { return true; }

private:
    std::unique_ptr<hc::render::GlRenderer> r_;
    GLuint tintTexture_;
    std::optional<Shown> next_;
};

// The GL backend in the window's context, or why not (no 4.3 compute shaders, a driver failure).
std::unique_ptr<ViewBackend> makeGlBackend(const hc::render::Scene& scene, std::string& whyNot) {
    try {
        return std::make_unique<GlBackend>(hc::render::GlRenderer::inCurrentContext(scene));
    } catch (const hc::Error& e) {
        whyNot = e.what();
        return nullptr;
    }
}

// ------------------------------------------------------------------------------------------------ viewer

struct Toggles {
    bool water = true, cells = false, cascadeTint = false, help = false, hud = true;
};

std::string fmt(const char* f, ...) __attribute__((format(printf, 1, 2)));
std::string fmt(const char* f, ...) {
    char buf[1024];
    va_list ap;
    va_start(ap, f);
    std::vsnprintf(buf, sizeof buf, f, ap);
    va_end(ap);
    return buf;
}

const char* kHelp =
    "hc-view controls\n"
    "\n"
    "W A S D / arrows   fly forward, left, back, right\n"
    "Q E                down, up\n"
    "Shift (held)       4x faster\n"
    "right drag         look around\n"
    "left drag          orbit around the point under the centre\n"
    "scroll             move forward / back (zoom)\n"
    "F                  water on/off\n"
    "C                  cell outlines on/off\n"
    "K                  cascade colouring on/off\n"
    "P                  screenshot (PNG beside the grid)\n"
    "1-9                go to bookmark\n"
    "Shift+1-9          save bookmark\n"
    "R                  back to the first view\n"
    "U                  HUD on/off\n"
    "H                  this help\n"
    "Esc                quit";

class Viewer {
public:
    Viewer(GLFWwindow* window, const hc::cli::LoadedScene& loaded, const hc::cli::RenderSetup& setup, std::string gridPath,
           std::unique_ptr<ViewBackend> backend, std::string backendNote, std::string contextInfo)
        : window_(window), loaded_(loaded), scene_(*loaded.scene), evaluator_(loaded.grid, loaded.lists),
          elevation_(hc::influence::Layer::byName(loaded.grid, "elevation")), options_(setup.options),
          gridPath_(std::move(gridPath)), backend_(std::move(backend)), backendNote_(std::move(backendNote)),
          contextInfo_(std::move(contextInfo)), hudTexture_(makeTexture()) {
        toggles_.cells = options_.cellOutlines;
        baseWaterMinDepthM_ = options_.waterMinDepthM;
        int fw = 0, fh = 0;
        glfwGetFramebufferSize(window_, &fw, &fh);
        camera_ = hc::cli::initialCamera(setup, scene_);
        camera_.width = std::max(1, fw), camera_.height = std::max(1, fh);
        home_ = camera_;
        bookmarksPath_ = hc::view::bookmarksPath(gridPath_);
        try {
            bookmarks_ = hc::view::readBookmarks(bookmarksPath_);
        } catch (const hc::Error& e) {
            std::fprintf(stderr, "hc-view: warning: %s (bookmarks start empty; saving one replaces the file)\n", e.what());
            flash("warning: " + bookmarksPath_ + " is broken: bookmarks start empty");
        }
        glfwSetWindowUserPointer(window_, this);
        glfwSetKeyCallback(window_, [](GLFWwindow* w, int key, int, int action, int mods) {
            static_cast<Viewer*>(glfwGetWindowUserPointer(w))->onKey(key, action, mods);
        });
        glfwSetScrollCallback(window_, [](GLFWwindow* w, double, double dy) { static_cast<Viewer*>(glfwGetWindowUserPointer(w))->onScroll(dy); });
        glfwSetMouseButtonCallback(window_, [](GLFWwindow* w, int button, int action, int) {
            static_cast<Viewer*>(glfwGetWindowUserPointer(w))->onButton(button, action);
        });
        glfwSetFramebufferSizeCallback(window_, [](GLFWwindow* w, int width, int height) {
            static_cast<Viewer*>(glfwGetWindowUserPointer(w))->onResize(width, height);
        });
    }

    const Camera& camera() const { return camera_; }
    const Timings& lastTimings() const { return shown_.timings; }  // of the frame on screen

    // Interactive: until the window closes or Esc.
    void run() {
        double last = glfwGetTime();
        while (!glfwWindowShouldClose(window_)) {
            const double now = glfwGetTime();
            const double dt = std::min(0.25, now - last);
            last = now;
            pollMotion(dt);
            schedule(false);
            if (backend_->collect(shown_)) frameDone();
            draw();
            glfwSwapBuffers(window_);
            // Wait in the event queue, never spin: the CPU backend needs the cores. Input wakes it at once;
            // otherwise ~60 Hz while frames are coming or keys are held, 2 Hz when all is still.
            if (backend_->busy() || moving() || !shownCurrent()) glfwWaitEventsTimeout(1.0 / 60);
            else glfwWaitEventsTimeout(0.5);
        }
    }

    // Scripted: `frames` frames of a small motion that ends at the initial camera (rendered at full
    // resolution), then the window's contents as a PNG.
    void runScripted(int frames, const std::string& screenshot) {
        const Camera end = camera_;
        for (int i = 0; i < frames && !glfwWindowShouldClose(window_); ++i) {
            const int left = frames - 1 - i;
            camera_ = end;
            if (left > 0) {  // approach the final view: turned a little and further back
                hc::view::look(camera_, -0.4 * left, 0.0);
                hc::view::fly(camera_, -0.01 * left * heightAboveGroundOr(100.0), 0, 0);
                lastChange_ = Clock::now();
            } else {
                lastChange_ = Clock::now() - std::chrono::seconds(10);
            }
            schedule(true);
            if (auto* cpu = dynamic_cast<CpuBackend*>(backend_.get())) cpu->wait();
            if (backend_->collect(shown_)) frameDone();
            draw();
            if (i == frames - 1 && !screenshot.empty()) saveScreenshot(screenshot);
            glfwSwapBuffers(window_);
            glfwPollEvents();
        }
    }

private:
    // ------------------------------------------------------------------------------------ input
    void onKey(int key, int action, int mods) {
        if (action != GLFW_PRESS) return;
        switch (key) {
            case GLFW_KEY_ESCAPE: glfwSetWindowShouldClose(window_, 1); break;
            case GLFW_KEY_F: toggles_.water = !toggles_.water, changed(), flash(toggles_.water ? "water on" : "water off"); break;
            case GLFW_KEY_C: toggles_.cells = !toggles_.cells, changed(), flash(toggles_.cells ? "cell outlines on" : "cell outlines off"); break;
            case GLFW_KEY_K:
                toggles_.cascadeTint = !toggles_.cascadeTint, changed();
                flash(!backend_->cascadeTintSupported() ? "cascade colouring: not offered by the " + backend_->name() + " backend"
                      : toggles_.cascadeTint        ? "cascade colouring on (near red, then green, blue, yellow)"
                                                    : "cascade colouring off");
                break;
            case GLFW_KEY_H: toggles_.help = !toggles_.help; break;
            case GLFW_KEY_U: toggles_.hud = !toggles_.hud; break;
            case GLFW_KEY_R: camera_ = withSize(home_), changed(), flash("first view"); break;
            case GLFW_KEY_P: {
                const std::string path = nextScreenshotPath();
                try {
                    saveScreenshot(path);
                    flash("screenshot -> " + path);
                } catch (const hc::Error& e) {
                    flash(std::string("screenshot failed: ") + e.what());
                }
                break;
            }
            default:
                if (key >= GLFW_KEY_1 && key <= GLFW_KEY_9) bookmark(key - GLFW_KEY_0, (mods & GLFW_MOD_SHIFT) != 0);
        }
    }
    void bookmark(int slot, bool save) {
        if (save) {
            bookmarks_[slot] = hc::view::toBookmark(camera_);
            try {
                hc::view::writeBookmarks(bookmarksPath_, bookmarks_);
                flash(fmt("bookmark %d saved -> %s", slot, bookmarksPath_.c_str()));
            } catch (const hc::Error& e) {
                flash(fmt("bookmark %d kept for this session only: %s", slot, e.what()));
            }
        } else if (bookmarks_[slot]) {
            hc::view::applyBookmark(*bookmarks_[slot], camera_);
            changed();
            flash(fmt("bookmark %d", slot));
        } else {
            flash(fmt("no bookmark %d (Shift+%d saves one)", slot, slot));
        }
    }
    void onScroll(double dy) {
        const double d = pivotDistance();
        hc::view::fly(camera_, dy * 0.1 * d, 0, 0);
        changed();
    }
    void onButton(int button, int action) {
        if (action == GLFW_PRESS) {
            glfwGetCursorPos(window_, &mouseX_, &mouseY_);
            if (button == GLFW_MOUSE_BUTTON_LEFT) pivot_ = pickCentre();
        }
    }
    void onResize(int w, int h) {
        if (w <= 0 || h <= 0) return;  // minimised
        camera_.width = w, camera_.height = h;
        changed();
    }
    void pollMotion(double dt) {
        auto down = [&](int k) { return glfwGetKey(window_, k) == GLFW_PRESS; };
        const bool fast = down(GLFW_KEY_LEFT_SHIFT) || down(GLFW_KEY_RIGHT_SHIFT);
        const double fwd = (down(GLFW_KEY_W) || down(GLFW_KEY_UP) ? 1 : 0) - (down(GLFW_KEY_S) || down(GLFW_KEY_DOWN) ? 1 : 0);
        const double right = (down(GLFW_KEY_D) || down(GLFW_KEY_RIGHT) ? 1 : 0) - (down(GLFW_KEY_A) || down(GLFW_KEY_LEFT) ? 1 : 0);
        const double up = (down(GLFW_KEY_E) ? 1 : 0) - (down(GLFW_KEY_Q) ? 1 : 0);
        if (fwd != 0 || right != 0 || up != 0) {
            const double step = speed() * (fast ? 4 : 1) * dt;
            hc::view::fly(camera_, fwd * step, right * step, up * step);
            changed();
        }
        double mx = 0, my = 0;
        glfwGetCursorPos(window_, &mx, &my);
        const double dx = mx - mouseX_, dy = my - mouseY_;
        mouseX_ = mx, mouseY_ = my;
        if (dx == 0 && dy == 0) return;
        if (glfwGetMouseButton(window_, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS) {
            hc::view::look(camera_, dx * 0.15, -dy * 0.15);
            changed();
        } else if (glfwGetMouseButton(window_, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS && pivot_) {
            hc::view::orbit(camera_, *pivot_, dx * 0.25, -dy * 0.25);
            changed();
        }
    }

    // --------------------------------------------------------------------------------- ground
    std::optional<double> groundAt(double xWorld, double yWorld) const {
        return evaluator_.value(xWorld - loaded_.grid.originWorldX, yWorld - loaded_.grid.originWorldY, elevation_);
    }
    std::optional<double> heightAboveGround() const {
        auto g = groundAt(camera_.xWorld, camera_.yWorld);
        return g ? std::optional<double>(camera_.zWorld - *g) : std::nullopt;
    }
    double heightAboveGroundOr(double fallback) const {
        auto h = heightAboveGround();
        return h ? std::max(std::abs(*h), 1.0) : fallback;
    }
    // Flying speed [m/s]: the height above ground per second, so low flights are slow and high ones fast.
    double speed() const {
        auto h = heightAboveGround();
        const double height = h ? std::abs(*h) : camera_.zWorld - scene_.zMax;
        return std::max({0.5 * height, 4 * loaded_.grid.finestCellM, 1.0});
    }
    // The surface point under the screen centre: from the last frame's centre depth when it shows this
    // camera, otherwise by marching the exact surface along the view ray.
    std::optional<std::array<double, 3>> pickCentre() const {
        const hc::render::CameraBasis b = hc::render::basisOf(camera_);
        const auto& f = b.forward;
        const Camera& sc = shown_.camera;
        if (std::isfinite(shown_.centreDistanceM) && sc.xWorld == camera_.xWorld && sc.yWorld == camera_.yWorld &&
            sc.zWorld == camera_.zWorld && sc.yawDeg == camera_.yawDeg && sc.pitchDeg == camera_.pitchDeg) {
            const double t = shown_.centreDistanceM;
            return std::array<double, 3>{camera_.xWorld + f[0] * t, camera_.yWorld + f[1] * t, camera_.zWorld + f[2] * t};
        }
        const double diag = std::hypot(scene_.xMax - scene_.xMin, scene_.yMax - scene_.yMin, scene_.zMax - scene_.zMin);
        const double reach = diag + std::hypot(camera_.zWorld - scene_.zMin, 1.0) * 4;
        const double step = std::max(reach / 2000, loaded_.grid.finestCellM * 0.5);
        double prevT = 0;
        for (double t = step; t < reach; t += step) {
            const double x = camera_.xWorld + f[0] * t, y = camera_.yWorld + f[1] * t, z = camera_.zWorld + f[2] * t;
            auto g = groundAt(x, y);
            if (g && z <= *g) {
                double lo = prevT, hi = t;  // bisect the crossing
                for (int k = 0; k < 20; ++k) {
                    const double m = 0.5 * (lo + hi);
                    auto gm = groundAt(camera_.xWorld + f[0] * m, camera_.yWorld + f[1] * m);
                    if (gm && camera_.zWorld + f[2] * m <= *gm) hi = m;
                    else lo = m;
                }
                return std::array<double, 3>{camera_.xWorld + f[0] * hi, camera_.yWorld + f[1] * hi, camera_.zWorld + f[2] * hi};
            }
            prevT = t;
        }
        // No hit: orbit around a point in front, at the distance of the scene's centre.
        const double cx = loaded_.grid.originWorldX + 0.5 * (scene_.xMin + scene_.xMax);
        const double cy = loaded_.grid.originWorldY + 0.5 * (scene_.yMin + scene_.yMax);
        const double d = std::max(std::hypot(cx - camera_.xWorld, cy - camera_.yWorld), 1.0);
        return std::array<double, 3>{camera_.xWorld + f[0] * d, camera_.yWorld + f[1] * d, camera_.zWorld + f[2] * d};
    }
    double pivotDistance() const {
        auto p = pickCentre();
        if (!p) return speed();
        return std::max(std::hypot((*p)[0] - camera_.xWorld, (*p)[1] - camera_.yWorld, (*p)[2] - camera_.zWorld), 1.0);
    }

    // ------------------------------------------------------------------------------ rendering
    void changed() { lastChange_ = Clock::now(); }
    bool moving() const { return Clock::now() - lastChange_ < std::chrono::milliseconds(250); }
    Camera withSize(Camera c) const {
        c.width = camera_.width, c.height = camera_.height;
        return c;
    }
    RenderOptions currentOptions() const {
        RenderOptions o = options_;
        o.cellOutlines = toggles_.cells;
        // Water off: no depth is deep enough to be drawn.
        o.waterMinDepthM = toggles_.water ? baseWaterMinDepthM_ : HUGE_VAL;
        // The tint would colour the legend too, and the legend's colours no longer hold.
        if (toggles_.cascadeTint) o.legend = false;
        return o;
    }
    static bool sameView(const Camera& a, const Camera& b) {
        return a.xWorld == b.xWorld && a.yWorld == b.yWorld && a.zWorld == b.zWorld && a.yawDeg == b.yawDeg &&
               a.pitchDeg == b.pitchDeg && a.fovYDeg == b.fovYDeg && a.width == b.width && a.height == b.height;
    }
    // Whether what is (being) rendered at full resolution is the current view with the current options.
    bool shownCurrent() const {
        return submitted_ && submittedFull_ && sameView(submittedCamera_, camera_) && submittedToggles_ == togglesKey();
    }
    int togglesKey() const { return (toggles_.water ? 1 : 0) | (toggles_.cells ? 2 : 0) | (toggles_.cascadeTint ? 4 : 0); }

    // Starts a frame when the backend is free and the view changed: reduced resolution while moving,
    // full when still. The reduced size aims at ~60 ms from the last frame's time per pixel.
    void schedule(bool force) {
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
            // A power of two, so that consecutive moving frames share the texture side and the CPU worker's
            // CascadeCache can keep their texels (it needs the same side and texel size).
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
    void frameDone() {
        ++framesShown_;
        const double pixels = double(shown_.width) * shown_.height;
        if (shown_.timings.totalMs > 0 && pixels > 0) msPerPixel_ = shown_.timings.totalMs / pixels;
        // Frame rate: frames finished over the last second.
        const auto now = Clock::now();
        frameTimes_.push_back(now);
        while (!frameTimes_.empty() && now - frameTimes_.front() > std::chrono::seconds(2)) frameTimes_.erase(frameTimes_.begin());
    }
    // Frames finished per second over the last two seconds while frames keep coming; otherwise what the last
    // frame's time allows.
    double framesPerSecond() const {
        if (frameTimes_.size() >= 3) {
            const double s = std::chrono::duration<double>(frameTimes_.back() - frameTimes_.front()).count();
            if (s > 0) return double(frameTimes_.size() - 1) / s;
        }
        return shown_.timings.totalMs > 0 ? 1000.0 / shown_.timings.totalMs : 0.0;
    }

    // ----------------------------------------------------------------------------------- drawing
    void draw() {
        int fw = 0, fh = 0;
        glfwGetFramebufferSize(window_, &fw, &fh);
        // The GL backend leaves its own state behind: back to the window's framebuffer and plain drawing.
        glBindFramebuffer(GL_FRAMEBUFFER, 0);
        glViewport(0, 0, fw, fh);
        glDisable(GL_BLEND);
        glDisable(GL_DEPTH_TEST);
        glDisable(GL_SCISSOR_TEST);
        glDisable(GL_CULL_FACE);
        glClearColor(0.08f, 0.08f, 0.1f, 1);
        glClear(GL_COLOR_BUFFER_BIT);
        if (shown_.texture) quad_.draw(shown_.texture, shown_.flipY);
        if (!toggles_.hud && !toggles_.help) return;
        if (drawHud(fw, fh)) {  // upload only what changed
            glBindTexture(GL_TEXTURE_2D, hudTexture_);
            glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
            glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, hud_.width, hud_.height, 0, GL_RGBA, GL_UNSIGNED_BYTE, hud_.rgba.data());
        }
        glEnable(GL_BLEND);
        glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
        quad_.draw(hudTexture_, true);
        glDisable(GL_BLEND);
    }
    // Rasterises the HUD (and the help) into hud_; false when it would be the same as last time.
    bool drawHud(int fw, int fh) {
        const int scale = fw >= 1200 ? 2 : 1;
        const int lineH = hc::view::kGlyphH * scale, pad = 4 * scale;
        const uint32_t kText = 0xF0F0F0FF, kDim = 0xB8C4D0FF, kWarn = 0xFFC850FF, kBox = 0x000000A0;
        std::vector<std::pair<std::string, uint32_t>> lines;
        if (toggles_.hud) {
            lines.push_back({fmt("hc-view  %s   backend %s (%s)", gridPath_.c_str(), backend_->name().c_str(), backend_->device().c_str()), kText});
            if (!backendNote_.empty()) lines.push_back({backendNote_, kWarn});
            if (backend_->device() != contextInfo_) lines.push_back({"display: " + contextInfo_, kDim});
            const Timings& t = shown_.timings;
            lines.push_back({fmt("%.1f fps   frame %dx%d%s   total %.1f ms", framesPerSecond(), shown_.width, shown_.height,
                                 shown_.full ? "" : " (moving: reduced)", t.totalMs),
                             kText});
            lines.push_back({fmt("fitting %.1f  approximation %.1f  mipmaps %.1f  ray casting %.1f  shading %.1f ms", t.fittingMs,
                                 t.approximationMs, t.mipmapMs, t.raycastMs, t.shadingMs),
                             kText});
            lines.push_back({fmt("camera %.1f, %.1f, %.1f m  yaw %.1f  pitch %.1f  fov %.1f deg", camera_.xWorld, camera_.yWorld,
                                 camera_.zWorld, camera_.yawDeg, camera_.pitchDeg, camera_.fovYDeg),
                             kText});
            auto h = heightAboveGround();
            lines.push_back({(h ? fmt("height above ground %.1f m", *h)
                                : fmt("outside the grid, %.1f m above its highest point", camera_.zWorld - scene_.zMax)) +
                                 fmt("   speed %.0f m/s", speed()),
                             kText});
            std::string tint = !toggles_.cascadeTint                    ? "off"
                               : backend_->cascadeTintSupported()       ? "on"
                                                                        : "not offered by this backend";
            lines.push_back({fmt("water %s (F)  cells %s (C)  cascades %s (K)  H help", toggles_.water ? "on" : "off",
                                 toggles_.cells ? "on" : "off", tint.c_str()),
                             kDim});
            if (Clock::now() < flashUntil_) lines.push_back({flash_, kWarn});
        }
        std::string key = fmt("%dx%d %d|", fw, fh, toggles_.help ? 1 : 0);
        for (const auto& l : lines) key += l.first + "\n";
        if (key == hudKey_) return false;
        hudKey_ = key;
        if (hud_.width != fw || hud_.height != fh) hud_.resize(fw, fh);
        else hud_.clear();
        int widest = 0;
        for (const auto& l : lines) widest = std::max(widest, int(l.first.size()));
        if (!lines.empty()) {
            hud_.fillRect(0, 0, widest * hc::view::kGlyphW * scale + 2 * pad, int(lines.size()) * lineH + 2 * pad, kBox);
            int y = pad;
            for (const auto& [text, colour] : lines) hc::view::drawText(hud_, pad, y, text, colour, scale), y += lineH;
        }
        if (toggles_.help) {
            int rows = 1, cols = 0, c = 0;
            for (const char* p = kHelp; *p; ++p)
                if (*p == '\n') ++rows, c = 0;
                else cols = std::max(cols, ++c);
            const int w = cols * hc::view::kGlyphW * scale + 4 * pad, h = rows * lineH + 4 * pad;
            const int x = (fw - w) / 2, y = (fh - h) / 2;
            hud_.fillRect(x, y, w, h, 0x000000C8);
            hc::view::drawText(hud_, x + 2 * pad, y + 2 * pad, kHelp, kText, scale);
        }
        return true;
    }

    void flash(const std::string& text) {
        flash_ = text;
        flashUntil_ = Clock::now() + std::chrono::seconds(4);
    }
    std::string nextScreenshotPath() const {
        std::string base = gridPath_;
        if (base.size() > 4 && base.compare(base.size() - 4, 4, ".hcg") == 0) base.resize(base.size() - 4);
        for (int i = 1;; ++i) {
            std::string p = fmt("%s.view%03d.png", base.c_str(), i);
            if (std::FILE* f = std::fopen(p.c_str(), "rb")) std::fclose(f);
            else return p;
        }
    }
    // The window's contents (image and HUD, as drawn) as an sRGB PNG.
    void saveScreenshot(const std::string& path) {
        int fw = 0, fh = 0;
        glfwGetFramebufferSize(window_, &fw, &fh);
        Frame f;
        f.width = fw, f.height = fh;
        std::vector<uint8_t> up(size_t(fw) * size_t(fh) * 3);
        glPixelStorei(GL_PACK_ALIGNMENT, 1);
        glReadBuffer(GL_BACK);
        glReadPixels(0, 0, fw, fh, GL_RGB, GL_UNSIGNED_BYTE, up.data());
        f.rgb.resize(up.size());
        const size_t row = size_t(fw) * 3;
        for (int y = 0; y < fh; ++y) std::copy_n(&up[size_t(fh - 1 - y) * row], row, &f.rgb[size_t(y) * row]);
        hc::render::writePng(f, path);
    }

    GLFWwindow* window_;
    const hc::cli::LoadedScene& loaded_;
    const hc::render::Scene& scene_;
    hc::influence::SurfaceEvaluator evaluator_;
    hc::influence::Layer elevation_;
    RenderOptions options_;
    double baseWaterMinDepthM_ = 0.01;
    std::string gridPath_;
    std::unique_ptr<ViewBackend> backend_;
    std::string backendNote_, contextInfo_;
    QuadProgram quad_;
    GLuint hudTexture_;
    hc::view::Overlay hud_;
    std::string hudKey_;  // the text hud_ holds, to skip identical redraws
    Toggles toggles_;
    Camera camera_, home_, submittedCamera_;
    bool submitted_ = false, submittedFull_ = false;
    int submittedToggles_ = 0;
    Shown shown_;
    double msPerPixel_ = 0;
    Clock::time_point lastChange_ = Clock::now() - std::chrono::seconds(10);
    std::vector<Clock::time_point> frameTimes_;
    long framesShown_ = 0;
    double mouseX_ = 0, mouseY_ = 0;
    std::optional<std::array<double, 3>> pivot_;
    std::string bookmarksPath_;
    hc::view::Bookmarks bookmarks_;
    std::string flash_;
    Clock::time_point flashUntil_{};
};

struct GlfwSession {
    GlfwSession() {
        glfwSetErrorCallback(onGlfwError);
        if (!glfwInit()) {
            const char* d = std::getenv("DISPLAY");
            throw hc::Error(std::string("cannot open the display (DISPLAY=") + (d ? d : "") + "): " + glfwMessage);
        }
    }
    ~GlfwSession() { glfwTerminate(); }
};

GLFWwindow* openWindow(const std::string& title, int width, int height, int major, int minor, bool visible) {
    glfwDefaultWindowHints();
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, major);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, minor);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
    glfwWindowHint(GLFW_VISIBLE, visible ? GLFW_TRUE : GLFW_FALSE);
    return glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
}

}  // namespace

int main(int argc, char** argv) {
    return hc::cli::run("hc-view", [&] {
        std::string gridPath, backendName = "auto", screenshot;
        int frames = 0, bookmarkSlot = 0;
        hc::cli::RenderSetup setup("1280x720");
        hc::cli::Parser p("hc-view", "GRID.hcg [--camera X,Y,Z,YAW,PITCH,FOV[,ROLL] | --look-at EX,EY,EZ,TX,TY,TZ[,FOV]] [--backend gl|cpu|auto] [options]",
                          "Opens a window on the smooth surface of a grid (terrain, and water where the grid has water_depth)\n"
                          "and lets you fly over it (press H in the window for the controls); a HUD shows per-stage timings,\n"
                          "the camera and the height above ground. Coordinates in the grid's CRS [m]; angles in degrees:\n"
                          "yaw 0 looks north, 90 east; pitch negative looks down. Without a camera option: hc-render's\n"
                          "overview. Bookmarks (Shift+1-9 saves, 1-9 loads) live in GRID.bookmarks.json beside the grid.\n"
                          "Needs a display (DISPLAY); without one: xvfb-run -a hc-view GRID.hcg --frames 30 --screenshot OUT.png");
        p.positional("GRID.hcg", "grid file", gridPath);
        setup.addCameraOptions(p, "--bookmark");
        p.option("--bookmark", "N", "first view: bookmark N (1..9) of GRID.bookmarks.json (default: none)", bookmarkSlot);
        p.option("--backend", "gl|cpu|auto", "renderer: the OpenGL 4.3 compute backend, the CPU one, or GL when it runs on a GPU (CPU where\n"
                 "OpenGL 4.3 is missing or only software rendering such as llvmpipe) (default auto)", backendName);
        setup.addRenderOptions(p);
        p.option("--frames", "N", "render N frames of a short scripted camera motion ending at the given view, then exit (default 0 = interactive)", frames);
        p.option("--screenshot", "OUT.png", "with --frames: write the window's last frame (image and HUD) as a PNG", screenshot);
        if (!p.parse(argc, argv)) return 0;
        setup.finish();
        const hc::cli::Backend choice = hc::cli::parseBackend(backendName);
        if (frames < 0 || frames > 100000) throw hc::Error("--frames " + std::to_string(frames) + " is outside 0..100000");
        if (!screenshot.empty()) {
            if (frames == 0) throw hc::Error("--screenshot needs --frames N (the number of frames to render first)");
            hc::cli::checkWritable(screenshot, "screenshot");
            hc::cli::checkNotSame(screenshot, gridPath, "screenshot");
        }
        if (p.given("--bookmark")) {  // before any work: the file and the slot must be there
            if (bookmarkSlot < 1 || bookmarkSlot > 9) throw hc::Error("--bookmark " + std::to_string(bookmarkSlot) + " is outside 1..9");
            const std::string path = hc::view::bookmarksPath(gridPath);
            const hc::view::Bookmarks marks = hc::view::readBookmarks(path);
            if (!marks[bookmarkSlot]) throw hc::Error(path + ": no bookmark " + std::to_string(bookmarkSlot));
            hc::render::Camera c;
            c.width = setup.width, c.height = setup.height;
            hc::view::applyBookmark(*marks[bookmarkSlot], c);
            setup.camera = c;
        }
        const char* display = std::getenv("DISPLAY");
        const char* wayland = std::getenv("WAYLAND_DISPLAY");
        if ((!display || !*display) && (!wayland || !*wayland))
            throw hc::Error("no display: DISPLAY is not set (hc-view needs an X display; without one, run it under "
                            "xvfb-run -a, or render images with hc-render)");

        GlfwSession glfw;
        const std::string title = "hc-view: " + gridPath;
        // A 4.3 core context (what the GL compute backend needs); if there is none, 3.3 core and the CPU backend.
        // The window opens hidden and shows once the scene is loaded; --backend gl fails here, before any work.
        GLFWwindow* window = openWindow(title, setup.width, setup.height, 4, 3, false);
        const bool have43 = window != nullptr;
        const std::string why43 = have43 ? "" : "no OpenGL 4.3 core context (" + glfwMessage + ")";
        if (!have43 && choice == hc::cli::Backend::Gl) throw hc::Error("--backend gl: " + why43);
        if (!window) window = openWindow(title, setup.width, setup.height, 3, 3, false);
        if (!window) throw hc::Error("cannot create an OpenGL 3.3 core window: " + glfwMessage);
        glfwMakeContextCurrent(window);
        glfwSwapInterval(frames > 0 ? 0 : 1);
        const std::string contextInfo = std::string(reinterpret_cast<const char*>(glGetString(GL_RENDERER))) + ", OpenGL " +
                                        reinterpret_cast<const char*>(glGetString(GL_VERSION));

        auto loaded = hc::cli::loadScene("hc-view", gridPath, setup);
        std::unique_ptr<ViewBackend> backend;
        std::string note;
        // auto takes GL on a GPU only: on software OpenGL (llvmpipe) the CPU backend is about twice as fast.
        const bool softwareGl = hc::render::isSoftwareRenderer(contextInfo);
        if (choice == hc::cli::Backend::Auto && have43 && softwareGl) {
            note = "software OpenGL (" + contextInfo.substr(0, contextInfo.find(", OpenGL")) +
                   "): rendering on the CPU, which is faster (--backend gl forces it)";
        } else if (choice != hc::cli::Backend::Cpu) {
            std::string why;
            if (have43) backend = makeGlBackend(*loaded->scene, why);
            else why = why43;
            if (!backend && choice == hc::cli::Backend::Gl) {
                glfwDestroyWindow(window);
                throw hc::Error("--backend gl: " + why);
            }
            if (!backend) note = "GL backend unavailable (" + why + "): rendering on the CPU";
        }
        if (!backend) backend = std::make_unique<CpuBackend>(*loaded->scene, setup.options.threads);
        else if (hc::render::isSoftwareRenderer(backend->device()))
            // DESIGN.md section 9: without a GPU the CPU backend is the fast one (about twice as fast per frame: BENCHMARKS.md).
            note = "software OpenGL: --backend cpu is about twice as fast on this machine";
        if (!note.empty()) std::fprintf(stderr, "hc-view: %s\n", note.c_str());
        std::fprintf(stderr, "hc-view: backend %s (%s)\n", backend->name().c_str(), backend->device().c_str());
        int status = 0;
        glfwShowWindow(window);
        {
            Viewer viewer(window, *loaded, setup, gridPath, std::move(backend), note, contextInfo);
            if (frames > 0) {
                viewer.runScripted(frames, screenshot);
                if (!screenshot.empty()) std::printf("hc-view: %s -> %s (%d frames)\n", gridPath.c_str(), screenshot.c_str(), frames);
                const Camera& c = viewer.camera();
                std::printf("  camera       %.3f, %.3f, %.3f  yaw %.2f  pitch %.2f  fov %.1f  %dx%d\n", c.xWorld, c.yWorld, c.zWorld,
                            c.yawDeg, c.pitchDeg, c.fovYDeg, c.width, c.height);
                std::printf("%s", viewer.lastTimings().toTable().c_str());
            } else {
                viewer.run();
            }
        }
        glfwDestroyWindow(window);
        return status;
    });
}
