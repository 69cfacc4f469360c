// EGL headless contexts (docs/testing.md: Mesa's surfaceless platform gives llvmpipe OpenGL 4.5
// core with no display; a GPU comes through EGL's device platform) and checks of the current context.
#include "context.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>

#include <cstdio>
#include <cstring>
#include <vector>

#include "gl.h"
#include "heightcast/core/error.h"

namespace hc::render::gl {
namespace {

std::string eglErrorText() {
    char b[32];
    std::snprintf(b, sizeof b, "EGL error 0x%04x", static_cast<unsigned>(eglGetError()));
    return b;
}

// EGL displays to try, best first. A GPU exposed as an EGL device (EGL_EXT_platform_device: NVIDIA's driver,
// Mesa's hardware drivers) comes before Mesa's surfaceless platform, which on a machine with NVIDIA's driver
// and Mesa both installed gives Mesa's software renderer; Mesa's software device (EGL_MESA_device_software)
// comes last.
std::vector<EGLDisplay> candidateDisplays(std::string& tried) {
    auto getPlatformDisplay =
        reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
    if (!getPlatformDisplay)
        throw Error("no headless OpenGL 4.3 context: EGL lacks eglGetPlatformDisplayEXT (EGL_EXT_platform_base)");
    std::vector<EGLDisplay> hardware, software;
    auto queryDevices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
    auto queryDeviceString =
        reinterpret_cast<PFNEGLQUERYDEVICESTRINGEXTPROC>(eglGetProcAddress("eglQueryDeviceStringEXT"));
    EGLint count = 0;
    if (queryDevices && queryDeviceString && queryDevices(0, nullptr, &count) && count > 0) {
        std::vector<EGLDeviceEXT> devices(static_cast<size_t>(count));
        queryDevices(count, devices.data(), &count);
        for (EGLint i = 0; i < count; ++i) {
            const char* extensions = queryDeviceString(devices[static_cast<size_t>(i)], EGL_EXTENSIONS);
            const bool isSoftware = extensions && std::strstr(extensions, "EGL_MESA_device_software");
            EGLDisplay d = getPlatformDisplay(EGL_PLATFORM_DEVICE_EXT, devices[static_cast<size_t>(i)], nullptr);
            if (d != EGL_NO_DISPLAY) (isSoftware ? software : hardware).push_back(d);
        }
        tried += std::to_string(count) + " EGL device(s), ";
    } else {
        tried += "no EGL devices (EGL_EXT_device_enumeration), ";
    }
    std::vector<EGLDisplay> all = hardware;
    EGLDisplay surfaceless = getPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    if (surfaceless != EGL_NO_DISPLAY)
        all.push_back(surfaceless);
    else
        tried += "no surfaceless platform, ";
    all.insert(all.end(), software.begin(), software.end());
    return all;
}

}  // namespace

std::unique_ptr<HeadlessContext> HeadlessContext::create() {
    std::string tried;
    const std::vector<EGLDisplay> displays = candidateDisplays(tried);
    std::string failures;
    for (EGLDisplay display : displays) {
        EGLint major = 0, minor = 0;
        if (!eglInitialize(display, &major, &minor)) {
            failures += "eglInitialize failed (" + eglErrorText() + "); ";
            continue;
        }
        if (!eglBindAPI(EGL_OPENGL_API)) {
            failures += "no desktop OpenGL API (" + eglErrorText() + "); ";
            continue;
        }
        const EGLint attributes[] = {
            EGL_CONTEXT_MAJOR_VERSION,           4,       EGL_CONTEXT_MINOR_VERSION, 3, EGL_CONTEXT_OPENGL_PROFILE_MASK,
            EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
        EGLContext context = eglCreateContext(display, EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, attributes);
        if (context == EGL_NO_CONTEXT) {
            failures += "eglCreateContext for OpenGL 4.3 core failed (" + eglErrorText() + "); ";
            continue;
        }
        std::unique_ptr<HeadlessContext> c(new HeadlessContext);
        c->display_ = display;
        c->context_ = context;
        c->makeCurrent();
        requireGl43("the headless context");
        return c;
    }
    if (failures.size() >= 2) failures.resize(failures.size() - 2);
    throw Error("no headless OpenGL 4.3 context: " + tried + (displays.empty() ? "no EGL display" : failures));
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
