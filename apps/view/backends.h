// apps/view/backends.h: what renders hc-view's image. A ViewBackend takes a camera and options and hands back a
// texture to draw: the CPU backend renders on a worker thread and uploads the frame; the GL backend renders
// into a texture in the window's own context. Both need the window's context current.
#pragma once

#include <cmath>
#include <memory>
#include <string>

#include "view/window.h"
#include "heightcast/render/camera.h"
#include "heightcast/render/renderer.h"

namespace hc::view {

// One rendered image, ready to draw.
struct Shown {
    GLuint texture = 0;
    bool flipY = true;          // row 0 at the top (CPU frames) or at the bottom (GL textures)
    int width = 0, height = 0;  // [pixels]
    render::Camera camera;
    bool full = false;  // rendered at the window's full resolution
    render::Timings timings;
    float centreDistanceM = INFINITY;  // along the centre pixel's ray; +inf on a miss or when unknown
};

// What the viewer asks of a backend: start a frame (possibly asynchronously), and collect the finished one.
// `cascadeTint` colours each pixel by the cascade that gave its hit (near red, then green, blue, yellow).
class ViewBackend {
public:
    virtual ~ViewBackend() = default;
    virtual bool busy() const = 0;
    virtual void submit(const render::Camera& c, const render::RenderOptions& o, bool full, bool cascadeTint) = 0;
    // True when a frame finished since the last call; `shown` then describes it. Throws the render's error.
    virtual bool collect(Shown& shown) = 0;
    // Returns once no frame is in flight (scripted runs, which show every frame they ask for).
    virtual void wait() = 0;
    virtual std::string name() const = 0;    // "CPU" | "GL"
    virtual std::string device() const = 0;  // "CPU, 16 threads" | the GL renderer and version
    // Whether it can outline the cells (the GL backend out of core has no cells on the GPU).
    // Renders `scene` from now on (a water step switched), when it can keep its state for it (the GL backend: its
    // compiled shaders, GlRenderer::setScene); false: make a new backend. No frame may be in flight (wait()).
    virtual bool setScene(const render::Scene&) { return false; }
};

// The CPU backend (renderFrame) with `threads` workers (0: all cores) on a thread of its own, so the window
// stays responsive while a frame renders. `scene` must outlive it.
std::unique_ptr<ViewBackend> makeCpuBackend(const render::Scene& scene, unsigned threads);
// The GL compute backend in the window's current context; throws hc::Error saying why not (no 4.3 compute
// shaders, a driver failure). `scene` must outlive it.
std::unique_ptr<ViewBackend> makeGlBackend(const render::Scene& scene);

}  // namespace hc::view
