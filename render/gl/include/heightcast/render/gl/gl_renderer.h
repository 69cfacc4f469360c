// heightcast/render/gl/gl_renderer.h: the OpenGL 4.3 compute backend (docs/design.md section 5).
//
// The same stages as the CPU backend (renderer.h): cascade fitting (on the CPU, shared code), then
// approximation into the cascade textures (visible texels only; those the last frame saw too are kept on the GPU),
// max mipmaps, ray casting with exact ray/bilinear-patch intersection and cascade blending, and shading, as compute
// shaders. It fills the same Frame and Timings as renderFrame(); GPU stage times come from GL timer queries.
//
// Out of core (Scene::outOfCore(): the grid read a region at a time, no cells or lists in memory, 100 M cells and
// more) nothing of the grid goes to the GPU: the cascades stay on the GPU from one frame to the next, and the texels a
// frame newly sees are evaluated on the CPU exactly as renderFrame() evaluates them (copies and interpolations from the
// surface pyramid, kernel sums from the cells around the rest) and uploaded; a compute shader places them beside the
// texels kept from the last frame, and the mipmaps, ray casting and shading follow. Cell outlines
// (RenderOptions::cellOutlines) are looked up on the CPU there, as a colour layer's values are on either path
// (backend_overlay.cpp): the rays are read back after the ray casting and shade.comp gets a value a pixel.
//
// No GL type appears here: the GL state lives behind the pimpl in render/gl/src/. A build without OpenGL
// (-DHC_WITH_GL=OFF) has this API too, from src/unavailable.cpp: headlessGlUnavailable() says the backend was
// built out, and making a renderer throws hc::Error saying so; no GL, EGL or GLFW library is linked.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "heightcast/render/renderer.h"

namespace hc::render {

// Why no headless OpenGL 4.3 context can be had on this machine, or "" when one can (it makes one and
// drops it again): lets a tool refuse --backend gl before loading a scene. Where one can, *device gets
// its renderer and version (as GlRenderer::deviceName()).
std::string headlessGlUnavailable(std::string* device = nullptr);
// Whether a GL_RENDERER string names a software rasteriser (Mesa's llvmpipe, softpipe, swrast).
bool isSoftwareRenderer(const std::string& device);

class GlRenderer {
public:
    // Uses the GL context current on the calling thread (a GLFW window's, say). Throws hc::Error when
    // there is none or it lacks OpenGL 4.3 compute shaders. The scene must outlive the renderer.
    static std::unique_ptr<GlRenderer> inCurrentContext(const Scene& scene);
    // Creates and owns a headless context (EGL: a GPU device, else Mesa's surfaceless platform; no display
    // needed). Throws hc::Error saying why when no OpenGL 4.3 core context can be had.
    static std::unique_ptr<GlRenderer> headless(const Scene& scene);
    ~GlRenderer();

    // What render() reads back: every layer of the Frame, or the picture alone (Frame::rgb, the other layers left
    // empty): what images of a sequence need, 3 bytes a pixel instead of the rays' 48 and their spreading over layers.
    enum class ReadBack { AllLayers, PictureOnly };
    // One frame, read back into `frame` (the same content and layout as renderFrame(); with PictureOnly its rgb only).
    // Throws hc::Error for bad camera/options, shader or driver failures (with the driver's log).
    Frame render(const Camera& camera, const RenderOptions& options, Timings& timings,
                 ReadBack what = ReadBack::AllLayers);
    // Frames in flight, for batch output (sequences, flights, videos): submitPicture() renders a frame and starts
    // copying its picture into the next of a ring of kPicturesInFlight pixel buffers, without waiting for the copy;
    // collectPicture() returns the oldest frame submitted, waiting for its copy alone: its picture (Frame::rgb, the
    // same bytes as render(..., PictureOnly)) and its timings (readbackMs: that wait and the conversion). Meanwhile the
    // CPU fits the next frame or encodes the last. submitPicture() with the ring full throws hc::Error, as does
    // collectPicture() with none in flight; render(), renderToTexture() and setScene() may come between the two.
    static constexpr size_t kPicturesInFlight = 3;
    struct Picture {
        Frame frame;
        Timings timings;
    };
    void submitPicture(const Camera& camera, const RenderOptions& options);
    size_t picturesInFlight() const;
    Picture collectPicture();
    // One frame left on the GPU: returns the name of an RGBA8 texture of camera.width x camera.height
    // (row 0 at the bottom, GL's convention) holding the shaded image, for a viewer to draw. Valid until
    // the next call.
    unsigned renderToTexture(const Camera& camera, const RenderOptions& options, Timings& timings);
    // The renderer keeps each frame's cascade texels on the GPU for the next (a moving camera evaluates only what it
    // newly sees, as CascadeCache does for renderFrame()); after this call the next frame evaluates every texel afresh
    // (benchmarks of from-scratch frames).
    void forgetCascades();
    // Renders `scene` from now on (another water step of the same grid, say), keeping the context and the compiled
    // shaders: the cells (in memory) go up again and nothing is kept from the last scene (cascades, pyramid tiles).
    // The scene must be of the same kind (in memory or out of core) and outlive the renderer; throws hc::Error if not.
    void setScene(const Scene& scene);
    // "llvmpipe (LLVM 15.0.6, 256 bits), OpenGL 4.5 (Core Profile) Mesa 22.3.6", say.
    std::string deviceName() const;

    // ---- test hooks (tests/render_gl_test.cpp); they use this renderer's context ----
    // Splits the influence lists of renderers made after this call into chunks of at most `entries`
    // entries (0: as large as the driver allows), so that tests exercise the chunked lists on small grids.
    static void limitIndexChunksForTest(uint64_t entries);
    // Holds the pyramid tiles of renderers made after this call (out of core) in atlases of at most `tiles` slots (0:
    // as many as their storage allows), so that tests exercise eviction and a frame that needs more tiles than fit.
    static void limitAtlasForTest(uint32_t tiles);
    // Takes `bytes` as the driver's largest storage buffer in renderers made after this call (0: the driver's own), so
    // that tests exercise the textures held to it out of core.
    static void limitStorageBlockForTest(uint64_t bytes);
    // Compiles and links `source` as a compute shader named `name` and deletes it again. Throws
    // hc::Error with the name and the driver's info log when it fails.
    void compileForTest(const std::string& name, const std::string& source) const;
    // The driver's layout of a buffer variable ("cells[0].level") in embedded program `program`
    // ("approximate", "mipmap", "raycast", "shade"): GL_OFFSET and GL_TOP_LEVEL_ARRAY_STRIDE, -1
    // where the program has no such variable.
    struct VariableLayout {
        long offset = -1, topLevelArrayStride = -1;
    };
    VariableLayout bufferVariableLayout(const std::string& program, const std::string& variable) const;
    // GL_BUFFER_DATA_SIZE of a shader storage block ("FrameBlock"), -1 where absent.
    long bufferBlockSize(const std::string& program, const std::string& block) const;
    // The last frame's cascade textures as the GPU holds them, n x n texels each (water and depth empty without water;
    // n = 0 for an empty cascade).
    struct CascadeTexels {
        int n = 0;
        std::vector<float> terrain, water, depth;
    };
    std::vector<CascadeTexels> cascadeTexturesForTest() const;

    struct Impl;

private:
    explicit GlRenderer(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hc::render
