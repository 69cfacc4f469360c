// apps/view/input.cpp: the Viewer's input (see viewer.h and the help in hud.cpp): keys for the switches,
// bookmarks, screenshots and quitting; held keys fly; the right mouse button looks around, the left one orbits
// around the surface point under the centre; the wheel moves forward and back.
#include <algorithm>

#include <fmt/format.h>

#include "heightcast/core/error.h"
#include "view/viewer.h"

namespace hc::view {
namespace {
Viewer* viewerOf(GLFWwindow* w) { return static_cast<Viewer*>(glfwGetWindowUserPointer(w)); }
}  // namespace

void Viewer::installCallbacks() {
    GLFWwindow* w = window_.handle();
    if (!w) return;  // offscreen: no input but --keys
    glfwSetWindowUserPointer(w, this);
    glfwSetKeyCallback(
        w, [](GLFWwindow* win, int key, int, int action, int mods) { viewerOf(win)->onKey(key, action, mods); });
    glfwSetScrollCallback(w, [](GLFWwindow* win, double, double dy) { viewerOf(win)->onScroll(dy); });
    glfwSetMouseButtonCallback(
        w, [](GLFWwindow* win, int button, int action, int) { viewerOf(win)->onButton(button, action); });
    glfwSetFramebufferSizeCallback(
        w, [](GLFWwindow* win, int width, int height) { viewerOf(win)->onResize(width, height); });
}

// The window outlives the viewer: no callback may reach it afterwards.
Viewer::~Viewer() {
    GLFWwindow* w = window_.handle();
    if (!w) return;
    glfwSetKeyCallback(w, nullptr);
    glfwSetScrollCallback(w, nullptr);
    glfwSetMouseButtonCallback(w, nullptr);
    glfwSetFramebufferSizeCallback(w, nullptr);
    glfwSetWindowUserPointer(w, nullptr);
}

void Viewer::onKey(int key, int action, int mods) {
    if (action != GLFW_PRESS) return;
    switch (key) {
        case GLFW_KEY_ESCAPE:
            window_.close();
            break;
        case GLFW_KEY_F:
            toggles_.water = !toggles_.water, changed(), flash(toggles_.water ? "water on" : "water off");
            break;
        case GLFW_KEY_C:
            toggles_.cells = !toggles_.cells, changed(),
            flash(toggles_.cells ? "cell outlines on" : "cell outlines off");
            break;
        case GLFW_KEY_K:
            toggles_.cascadeTint = !toggles_.cascadeTint, changed();
            flash(toggles_.cascadeTint ? "cascade colouring on (near red, then green, blue, yellow)"
                                       : "cascade colouring off");
            break;
        case GLFW_KEY_H:
            toggles_.help = !toggles_.help;
            break;
        case GLFW_KEY_RIGHT_BRACKET:
        case GLFW_KEY_LEFT_BRACKET:
            if (stepCount_ > 1) {
                playing_ = false;
                const size_t next =
                    key == GLFW_KEY_RIGHT_BRACKET ? (step_ + 1) % stepCount_ : (step_ + stepCount_ - 1) % stepCount_;
                try {
                    showStep(next);
                } catch (const Error& e) {
                    flash(std::string("step failed: ") + e.what());
                }
            }
            break;
        case GLFW_KEY_SPACE:
            if (stepCount_ > 1)
                playing_ = !playing_, stepShownAt_ = Clock::now(), flash(playing_ ? "playing" : "paused");
            break;
        case GLFW_KEY_EQUAL:
        case GLFW_KEY_KP_ADD:
            stepsPerSecond_ = std::min(30.0, stepsPerSecond_ * 2),
            flash(fmt::format("{:g} steps per second", stepsPerSecond_));
            break;
        case GLFW_KEY_MINUS:
        case GLFW_KEY_KP_SUBTRACT:
            stepsPerSecond_ = std::max(0.125, stepsPerSecond_ / 2),
            flash(fmt::format("{:g} steps per second", stepsPerSecond_));
            break;
        case GLFW_KEY_B:  // the error budget in pixels: tighter, looser, off (RenderOptions::maxErrorPx)
        case GLFW_KEY_N:
            options_.maxErrorPx = options_.maxErrorPx == 0 ? 1.0
                                  : key == GLFW_KEY_B      ? std::max(1.0 / 64, options_.maxErrorPx / 2)
                                                           : std::min(64.0, options_.maxErrorPx * 2);
            changed(), flash(fmt::format("error budget {:g} px", options_.maxErrorPx));
            break;
        case GLFW_KEY_M:
            options_.maxErrorPx = 0, changed(), flash("no error budget in pixels: texel sizes from --texels");
            break;
        case GLFW_KEY_U:
            toggles_.hud = !toggles_.hud;
            break;
        case GLFW_KEY_R:
            camera_ = withSize(home_), changed(), flash("first view");
            break;
        case GLFW_KEY_P: {
            const std::string path = nextScreenshotPath(gridPath_);
            try {
                saveScreenshot(window_, path);
                flash("screenshot -> " + path);
            } catch (const Error& e) {
                flash(std::string("screenshot failed: ") + e.what());
            }
            break;
        }
        default:
            if (key >= GLFW_KEY_1 && key <= GLFW_KEY_9) bookmark(key - GLFW_KEY_0, (mods & GLFW_MOD_SHIFT) != 0);
    }
}

void Viewer::bookmark(int slot, bool save) {
    if (save) {
        bookmarks_[slot] = toBookmark(camera_);
        try {
            writeBookmarks(bookmarksPath_, bookmarks_);
            flash(fmt::format("bookmark {} saved -> {}", slot, bookmarksPath_));
        } catch (const Error& e) {
            flash(fmt::format("bookmark {} kept for this session only: {}", slot, e.what()));
        }
    } else if (bookmarks_[slot]) {
        applyBookmark(*bookmarks_[slot], camera_);
        changed();
        flash(fmt::format("bookmark {}", slot));
    } else {
        flash(fmt::format("no bookmark {} (Shift+{} saves one)", slot, slot));
    }
}

void Viewer::onScroll(double dy) {
    fly(camera_, dy * 0.1 * ground_.pivotDistance(camera_, centreDistanceM()), 0, 0);
    changed();
}

void Viewer::onButton(int button, int action) {
    if (action != GLFW_PRESS) return;
    glfwGetCursorPos(window_.handle(), &mouseX_, &mouseY_);
    if (button == GLFW_MOUSE_BUTTON_LEFT) pivot_ = ground_.pickCentre(camera_, centreDistanceM());
}

void Viewer::onResize(int w, int h) {
    if (w <= 0 || h <= 0) return;  // minimised
    camera_.width = w, camera_.height = h;
    changed();
}

// Held keys fly `dt` seconds' worth at the ground-dependent speed; a drag since the last call turns the camera.
void Viewer::pollMotion(double dt) {
    GLFWwindow* w = window_.handle();
    auto down = [&](int k) { return glfwGetKey(w, k) == GLFW_PRESS; };
    const bool fast = down(GLFW_KEY_LEFT_SHIFT) || down(GLFW_KEY_RIGHT_SHIFT);
    const double fwd =
        (down(GLFW_KEY_W) || down(GLFW_KEY_UP) ? 1 : 0) - (down(GLFW_KEY_S) || down(GLFW_KEY_DOWN) ? 1 : 0);
    const double right =
        (down(GLFW_KEY_D) || down(GLFW_KEY_RIGHT) ? 1 : 0) - (down(GLFW_KEY_A) || down(GLFW_KEY_LEFT) ? 1 : 0);
    const double up = (down(GLFW_KEY_E) ? 1 : 0) - (down(GLFW_KEY_Q) ? 1 : 0);
    if (fwd != 0 || right != 0 || up != 0) {
        const double step = ground_.speed(camera_) * (fast ? 4 : 1) * dt;
        fly(camera_, fwd * step, right * step, up * step);
        changed();
    }
    double mx = 0, my = 0;
    glfwGetCursorPos(w, &mx, &my);
    const double dx = mx - mouseX_, dy = my - mouseY_;
    mouseX_ = mx, mouseY_ = my;
    if (dx == 0 && dy == 0) return;
    if (glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS) {
        look(camera_, dx * 0.15, -dy * 0.15);
        changed();
    } else if (glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS && pivot_) {
        orbit(camera_, *pivot_, dx * 0.25, -dy * 0.25);
        changed();
    }
}

}  // namespace hc::view
