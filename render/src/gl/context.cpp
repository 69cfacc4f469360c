// EGL headless contexts (DESIGN.md section 9: Mesa's surfaceless platform gives llvmpipe OpenGL 4.5
// core with no display) and checks of the current context.
#include "gl/context.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>

#include <cstdio>

#include "gl/gl.h"
#include "heightcast/grid/error.h"

namespace hc::render::gl {
namespace {

std::string eglErrorText() {
    char b[32];
    std::snprintf(b, sizeof b, "EGL error 0x%04x", static_cast<unsigned>(eglGetError()));
    return b;
}

}  // namespace

std::unique_ptr<HeadlessContext> HeadlessContext::create() {
    const std::string why = "no headless OpenGL 4.3 context: ";
    // eglGetPlatformDisplayEXT comes through eglGetProcAddress: EGL 1.4 headers do not declare it.
    auto getPlatformDisplay = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
    if (!getPlatformDisplay) throw Error(why + "EGL lacks eglGetPlatformDisplayEXT (EGL_EXT_platform_base)");
    EGLDisplay display = getPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    if (display == EGL_NO_DISPLAY) throw Error(why + "no EGL display for the surfaceless platform (" + eglErrorText() + ")");
    EGLint major = 0, minor = 0;
    if (!eglInitialize(display, &major, &minor)) throw Error(why + "eglInitialize failed (" + eglErrorText() + ")");
    if (!eglBindAPI(EGL_OPENGL_API)) throw Error(why + "EGL cannot bind the desktop OpenGL API (" + eglErrorText() + ")");
    const EGLint attributes[] = {EGL_CONTEXT_MAJOR_VERSION, 4, EGL_CONTEXT_MINOR_VERSION, 3,
                                 EGL_CONTEXT_OPENGL_PROFILE_MASK, EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
    EGLContext context = eglCreateContext(display, EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, attributes);
    if (context == EGL_NO_CONTEXT) throw Error(why + "eglCreateContext for OpenGL 4.3 core failed (" + eglErrorText() + ")");
    std::unique_ptr<HeadlessContext> c(new HeadlessContext);
    c->display_ = display;
    c->context_ = context;
    c->makeCurrent();
    requireGl43("the headless context");
    return c;
}

HeadlessContext::~HeadlessContext() {
    // The display is not terminated: other contexts of this process may live on it.
    if (eglGetCurrentContext() == context_) eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(display_, context_);
}

void HeadlessContext::makeCurrent() const {
    if (eglGetCurrentContext() == context_) return;
    if (!eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, context_))
        throw Error("cannot make the headless OpenGL context current (" + eglErrorText() + ")");
}

void requireGl43(const char* who) {
    // With no current context glvnd's dispatch returns null here.
    const auto* version = reinterpret_cast<const char*>(glGetString(GL_VERSION));
    if (!version) throw Error(std::string(who) + ": no OpenGL context is current");
    GLint major = 0, minor = 0;
    glGetIntegerv(GL_MAJOR_VERSION, &major);
    glGetIntegerv(GL_MINOR_VERSION, &minor);
    GLint profile = 0;
    glGetIntegerv(GL_CONTEXT_PROFILE_MASK, &profile);
    if (major < 4 || (major == 4 && minor < 3))
        throw Error(std::string(who) + ": OpenGL " + version + " lacks compute shaders (the GL backend needs 4.3)");
}

std::string currentDeviceName() {
    const auto* renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
    const auto* version = reinterpret_cast<const char*>(glGetString(GL_VERSION));
    return std::string(renderer ? renderer : "?") + ", OpenGL " + (version ? version : "?");
}

}  // namespace hc::render::gl
