// apps/view/window.cpp: the GLFW window or the offscreen framebuffer, its context, and the fullscreen triangle (see
// window.h).
#include "view/window.h"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <thread>
#include <vector>

#include "heightcast/core/error.h"

namespace hc::view {
namespace {

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
        throw Error(std::string("the display shader does not compile: ") + log);
    }
    return s;
}

GLFWwindow* openWindow(const std::string& title, int width, int height, int major, int minor) {
    glfwDefaultWindowHints();
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, major);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, minor);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
    glfwWindowHint(GLFW_VISIBLE, GLFW_FALSE);  // shown once the scene is loaded
    return glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
}

// "GL_RENDERER, OpenGL GL_VERSION" of the current context.
std::string currentDevice() {
    return std::string(reinterpret_cast<const char*>(glGetString(GL_RENDERER))) + ", OpenGL " +
           reinterpret_cast<const char*>(glGetString(GL_VERSION));
}

}  // namespace

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

void uploadRgb(GLuint texture, int width, int height, const uint8_t* rgb) {
    glBindTexture(GL_TEXTURE_2D, texture);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGB8, width, height, 0, GL_RGB, GL_UNSIGNED_BYTE, rgb);
}

void uploadRgba(GLuint texture, int width, int height, const uint8_t* rgba) {
    glBindTexture(GL_TEXTURE_2D, texture);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, width, height, 0, GL_RGBA, GL_UNSIGNED_BYTE, rgba);
}

QuadProgram::QuadProgram() {
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
    if (!ok) throw Error("the display shader program does not link");
    flipLoc_ = glGetUniformLocation(prog_, "flipY");
    glGenVertexArrays(1, &vao_);
}

void QuadProgram::draw(GLuint texture, bool flipY) const {
    glUseProgram(prog_);
    glUniform1i(flipLoc_, flipY ? 1 : 0);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, texture);
    glBindVertexArray(vao_);
    glDrawArrays(GL_TRIANGLES, 0, 3);
}

Window::Session::Session() {
    glfwSetErrorCallback(onGlfwError);
    if (!glfwInit()) {
        const char* d = std::getenv("DISPLAY");
        throw Error(std::string("cannot open the display (DISPLAY=") + (d ? d : "") + "): " + glfwMessage);
    }
}

Window::Session::~Session() { glfwTerminate(); }

Window::Window(const std::string& title, int width, int height, bool vsync) {
    session_.emplace();
    window_ = openWindow(title, width, height, 4, 3);
    if (!window_) {
        gl_.unavailable = "no OpenGL 4.3 core context (" + glfwMessage + ")";
        window_ = openWindow(title, width, height, 3, 3);
    }
    if (!window_) throw Error("cannot create an OpenGL 3.3 core window: " + glfwMessage);
    glfwMakeContextCurrent(window_);
    glfwSwapInterval(vsync ? 1 : 0);
    gl_.device = currentDevice();
    quad_.emplace();
}

Window::Window(Offscreen, int width, int height) : headless_(render::gl::HeadlessContext::create()) {
    width_ = width, height_ = height;
    glGenRenderbuffers(1, &colour_);
    glBindRenderbuffer(GL_RENDERBUFFER, colour_);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
    glGenFramebuffers(1, &framebuffer_);
    glBindFramebuffer(GL_FRAMEBUFFER, framebuffer_);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, colour_);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
        throw Error("cannot make an offscreen framebuffer of " + std::to_string(width) + "x" + std::to_string(height) +
                    " pixels");
    gl_.device = currentDevice();
    quad_.emplace();
}

Window::~Window() {
    if (window_) {
        glfwDestroyWindow(window_);
        return;
    }
    glDeleteFramebuffers(1, &framebuffer_);
    glDeleteRenderbuffers(1, &colour_);
}

void Window::show() {
    if (window_) glfwShowWindow(window_);
}
bool Window::shouldClose() const { return window_ ? glfwWindowShouldClose(window_) : closed_; }
void Window::close() {
    if (window_)
        glfwSetWindowShouldClose(window_, 1);
    else
        closed_ = true;
}
double Window::seconds() const {
    if (window_) return glfwGetTime();
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
void Window::swapBuffers() {
    if (window_)
        glfwSwapBuffers(window_);
    else
        glFinish();
}
void Window::pollEvents() {
    if (window_) glfwPollEvents();
}
void Window::waitEvents(double timeoutS) {
    if (window_)
        glfwWaitEventsTimeout(timeoutS);
    else
        std::this_thread::sleep_for(std::chrono::duration<double>(timeoutS));
}

std::pair<int, int> Window::framebufferSize() const {
    if (!window_) return {width_, height_};
    int fw = 0, fh = 0;
    glfwGetFramebufferSize(window_, &fw, &fh);
    return {fw, fh};
}

void Window::clear() {
    const auto [fw, fh] = framebufferSize();
    glBindFramebuffer(GL_FRAMEBUFFER, framebuffer_);  // 0: the window's
    glViewport(0, 0, fw, fh);
    glDisable(GL_BLEND);
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_SCISSOR_TEST);
    glDisable(GL_CULL_FACE);
    glClearColor(0.08f, 0.08f, 0.1f, 1);
    glClear(GL_COLOR_BUFFER_BIT);
}

void Window::drawTexture(GLuint texture, bool flipY, bool blend) const {
    if (blend) {
        glEnable(GL_BLEND);
        glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
    }
    quad_->draw(texture, flipY);
    if (blend) glDisable(GL_BLEND);
}

render::Frame Window::readBackBuffer() const {
    const auto [fw, fh] = framebufferSize();
    render::Frame f;
    f.width = fw, f.height = fh;
    std::vector<uint8_t> up(size_t(fw) * size_t(fh) * 3);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, framebuffer_);
    glReadBuffer(window_ ? GL_BACK : GL_COLOR_ATTACHMENT0);
    glReadPixels(0, 0, fw, fh, GL_RGB, GL_UNSIGNED_BYTE, up.data());
    f.rgb.resize(up.size());
    const size_t row = size_t(fw) * 3;  // GL's row 0 is the bottom one
    for (int y = 0; y < fh; ++y) std::copy_n(&up[size_t(fh - 1 - y) * row], row, &f.rgb[size_t(y) * row]);
    return f;
}

}  // namespace hc::view
