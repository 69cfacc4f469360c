// render/gl/src/context.h: OpenGL contexts for the GL backend.
#pragma once

#include <memory>
#include <string>

namespace hc::render::gl {

// A headless OpenGL 4.3+ core context (EGL: a GPU device first, else Mesa's surfaceless platform; no display,
// no window).
class HeadlessContext {
public:
    // Throws hc::Error saying which step failed when no such context can be had.
    static std::unique_ptr<HeadlessContext> create();
    ~HeadlessContext();
    // Makes the context current on the calling thread (a context is current on one thread at a time).
    void makeCurrent() const;

private:
    HeadlessContext() = default;
    void* display_ = nullptr;  // EGLDisplay
    void* context_ = nullptr;  // EGLContext
};

// Throws hc::Error unless a context is current on this thread and offers OpenGL 4.3 (compute shaders).
void requireGl43(const char* who);
// "llvmpipe (LLVM 15.0.6, 256 bits), OpenGL 4.5 (Core Profile) Mesa 22.3.6" for the current context.
std::string currentDeviceName();

}  // namespace hc::render::gl
