// heightcast/render/gl/headless_context.h: a headless OpenGL 4.3+ core context, for the GL backend's own renders
// (GlRenderer::headless) and for a program that draws without a window (hc-view's offscreen frames).
//
// EGL: a GPU exposed as an EGL device first, else Mesa's surfaceless platform (llvmpipe); no display, no window, no
// default framebuffer (draw into a framebuffer object). A build without OpenGL (-DHC_WITH_GL=OFF) has this API too:
// create() throws hc::Error saying the backend was built out.
#pragma once

#include <memory>

namespace hc::render::gl {

class HeadlessContext {
public:
    // Made current on the calling thread. Throws hc::Error saying which step failed when no such context can be had.
    static std::unique_ptr<HeadlessContext> create();
    ~HeadlessContext();
    HeadlessContext(const HeadlessContext&) = delete;
    HeadlessContext& operator=(const HeadlessContext&) = delete;
    // Makes the context current on the calling thread (a context is current on one thread at a time).
    void makeCurrent() const;

private:
    HeadlessContext() = default;
    void* display_ = nullptr;  // EGLDisplay
    void* context_ = nullptr;  // EGLContext
};

}  // namespace hc::render::gl
