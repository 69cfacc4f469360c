// apps/view/window.h: hc-view's window: the GLFW session and one window with its OpenGL context (or an offscreen
// framebuffer in a headless context), textures, and the fullscreen triangle that draws a texture over the window.
// GLFW and OpenGL are called here and, beside it, only in backends.cpp (the GL backend's texture) and input.cpp
// (GLFW's keys and mouse).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <utility>

#define GL_GLEXT_PROTOTYPES
#include <GL/glcorearb.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include "heightcast/support/backend_choice.h"
#include "heightcast/render/gl/headless_context.h"
#include "heightcast/render/renderer.h"

namespace hc::view {

// A texture with linear filtering and clamped edges.
GLuint makeTexture();
// Replaces the texture's image: RGB8 rows of `width` pixels without padding, or RGBA8.
void uploadRgb(GLuint texture, int width, int height, const uint8_t* rgb);
void uploadRgba(GLuint texture, int width, int height, const uint8_t* rgba);

// A texture drawn over the whole window by one triangle; `flipY` for images with row 0 at the top.
class QuadProgram {
public:
    QuadProgram();  // in the current context; throws hc::Error when the shaders do not build
    void draw(GLuint texture, bool flipY) const;

private:
    GLuint prog_ = 0, vao_ = 0;
    GLint flipLoc_ = -1;
};

// Where hc-view draws: a GLFW window with its core context made current, OpenGL 4.3 (what the GL compute backend
// needs) or, where there is none, 3.3 (enough to show CPU frames); or, offscreen, a framebuffer object of a fixed
// size in a headless EGL context (a GPU without a display, or Mesa's llvmpipe), for scripted frames. Owns both: the
// destructor closes the window and ends GLFW.
class Window {
public:
    // A hidden window, shown by show(). Throws hc::Error when the display cannot be opened or not even a 3.3
    // context can be had. `vsync` off for scripted runs, which should not wait for the screen.
    Window(const std::string& title, int width, int height, bool vsync);
    struct Offscreen {};
    // No window: a width x height RGBA8 framebuffer in a headless OpenGL 4.3 context. Throws hc::Error (EGL's
    // reason) when no such context can be had.
    Window(Offscreen, int width, int height);
    ~Window();
    Window(const Window&) = delete;
    Window& operator=(const Window&) = delete;

    // The context as the backend choice sees it: unavailable = "no OpenGL 4.3 core context (GLFW's reason)"
    // when only 3.3 could be had; device = "GL_RENDERER, OpenGL GL_VERSION".
    const cli::GlOnHand& gl() const { return gl_; }
    bool offscreen() const { return window_ == nullptr; }
    GLFWwindow* handle() const { return window_; }  // null offscreen: no input

    void show();
    bool shouldClose() const;
    void close();
    std::pair<int, int> framebufferSize() const;  // [pixels]
    double seconds() const;                       // for frame steps
    // Shows the back buffer; offscreen, waits until the frame is drawn (glFinish): what a swap would show.
    void swapBuffers();
    void pollEvents();
    void waitEvents(double timeoutS);

    // Back to the window's framebuffer and plain drawing (the GL backend leaves its state behind), cleared.
    void clear();
    // The texture over the whole window, blended by its alpha when `blend`.
    void drawTexture(GLuint texture, bool flipY, bool blend) const;
    // What the back buffer holds, as an 8-bit RGB frame with row 0 at the top (distance and other layers empty).
    render::Frame readBackBuffer() const;

private:
    struct Session {  // glfwInit .. glfwTerminate, which also closes a window left open by a failing constructor
        Session();
        ~Session();
    };
    std::optional<Session> session_;  // none offscreen
    GLFWwindow* window_ = nullptr;
    std::unique_ptr<render::gl::HeadlessContext> headless_;  // offscreen: the context, its framebuffer and size
    GLuint framebuffer_ = 0, colour_ = 0;
    int width_ = 0, height_ = 0;
    bool closed_ = false;
    cli::GlOnHand gl_;
    std::optional<QuadProgram> quad_;  // made once the context is current
};

}  // namespace hc::view
