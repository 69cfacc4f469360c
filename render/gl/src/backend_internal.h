// render/gl/src/backend_internal.h: the GL backend's renderer (GlRenderer::Impl: its programs, buffers and the state
// it keeps from frame to frame) and the buffers it holds (Buffer, TileAtlas), shared by the files that define its
// parts: backend.cpp (set-up, uploads, the frame, read-back), backend_cpu_fill.cpp (stage 2 from the CPU),
// backend_atlas.cpp (the pyramid's tiles on the GPU), backend_overlay.cpp (what shading needs from the CPU at the
// hits), backend_pictures.cpp (the pictures in flight) and backend_dispatch.cpp (the dispatches). backend.cpp's first
// comment describes the backend as a whole. Private to render/gl/src/.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include <glm/vec3.hpp>

#include "context.h"
#include "gl.h"
#include "heightcast/core/timer.h"
#include "heightcast/render/detail/frame.h"
#include "heightcast/render/gl/gl_renderer.h"
#include "heightcast/render/gpu_layout.h"

namespace hc::render {
namespace gl {

// A buffer that grows (never shrinks) to the size a frame needs.
struct Buffer {
    GLuint name = 0;
    size_t bytes = 0;
    GLenum usage = GL_DYNAMIC_DRAW;  // the driver's hint; GL_STREAM_READ for the read-back staging buffer
    void reserve(size_t need) {
        if (name && bytes >= need) return;
        if (!name) glGenBuffers(1, &name);
        glBindBuffer(GL_SHADER_STORAGE_BUFFER, name);
        glBufferData(GL_SHADER_STORAGE_BUFFER, GLsizeiptr(std::max<size_t>(need, 16)), nullptr, usage);
        bytes = std::max<size_t>(need, 16);
    }
    void upload(const void* data, size_t size, size_t offset = 0) const {
        glBindBuffer(GL_SHADER_STORAGE_BUFFER, name);
        glBufferSubData(GL_SHADER_STORAGE_BUFFER, GLintptr(offset), GLsizeiptr(size), data);
    }
    void bind(GLuint binding) const { glBindBufferBase(GL_SHADER_STORAGE_BUFFER, binding, name); }
    void release() {
        if (name) glDeleteBuffers(1, &name);
        name = 0;
        bytes = 0;
    }
};

// Pyramid tiles resident on the GPU from frame to frame (docs/design.md section 4: the atlas), in slots of `planes`
// channels of gpu::kAtlasPlane floats: out of core the texels a frame copies from the pyramid are copied there
// (atlas.comp) instead of on the CPU, and only tiles not yet resident go up. A tile is known by its first sample's
// address in the pyramid (a mapped file, or the water pyramid's). Slots are taken in turn, skipping those this frame
// uses, so the tile placed longest ago is the first dropped (a clock without reference bits: a flight's tiles come and
// go together).
struct TileAtlas {
    static constexpr uint32_t kNone = ~uint32_t{0};
    Buffer buffer;
    size_t planes = 1;
    uint32_t capacity = 0;  // slots
    uint32_t limit = 0;     // at most this many (GlRenderer::limitAtlasForTest), 0: as many as fit
    std::unordered_map<const float*, uint32_t> slotOf;
    std::vector<const float*> tileIn;  // per slot (nullptr: free)
    std::vector<uint64_t> usedIn;      // per slot: the frame that used it last
    // Per slot: bit c of row r set where the tile's sample (c, r) of its first channel is a number (not NaN: outside
    // every cell), so that the copied texels of a tile are counted without reading the tile again (validIn).
    std::vector<std::array<uint16_t, 16>> validRows;
    static_assert(gpu::kAtlasPlane <= 16 * 16, "validRows holds a tile of at most 16 x 16 samples");
    uint32_t hand = 0, usedNow = 0;
    uint64_t frame = 0;
    uint64_t uploadedTiles = 0, uploadedBytes = 0;  // this frame's
    std::vector<float> staging;                     // this frame's new tiles, in the order of stagedSlots
    std::vector<uint32_t> stagedSlots;

    // Sized once, at the first frame that copies from it: `bytes` of storage (the buffer is never grown: that would
    // lose the tiles in it).
    void open(size_t bytes, size_t channelPlanes);
    void beginFrame() {
        ++frame, usedNow = 0, uploadedTiles = 0, uploadedBytes = 0, staging.clear(), stagedSlots.clear();
    }
    // The slot holding `tile` (its planes of `plane` floats each, `plane` apart) this frame, staged for upload if it
    // was not resident; kNone when this frame already uses every slot.
    uint32_t slot(const float* tile, size_t plane);
    // A tile's side for a plane of `plane` samples (a power of four up to gpu::kAtlasPlane).
    static size_t sideOf(size_t plane) { return size_t{1} << (std::countr_zero(plane) / 2); }
    // The samples of the tile in `slot` marked in `rows` (a bit per sample, as validRows) that are numbers.
    int validIn(uint32_t s, const uint16_t* rows, size_t side) const {
        int valid = 0;
        for (size_t r = 0; r < side; ++r) valid += std::popcount(unsigned(validRows[s][r] & rows[r]));
        return valid;
    }
    // The staged tiles into their slots, at once (a tile is never said resident without being there, whatever fails
    // later in the frame): one upload per run of consecutive slots.
    void upload();
    void release();
};

// A picture read from the colour texture as RGBA (`rgba`, W x H, row 0 at the bottom: GL's) into a Frame's RGB (row 0
// at the top), on every core (backend_pictures.cpp).
void rgbFromTexture(const uint8_t* rgba, int W, int H, std::vector<uint8_t>& rgb);

}  // namespace gl

struct GlRenderer::Impl {
    using Buffer = gl::Buffer;
    using TileAtlas = gl::TileAtlas;

    const Scene* scene;                             // setScene() points it at another of the same kind
    std::unique_ptr<gl::HeadlessContext> headless;  // null when rendering into the caller's context
    GLuint approximate = 0, assemble = 0, atlas = 0, interpolate = 0, beams = 0, shore = 0, mipmap = 0, raycast = 0,
           shade = 0;
    Buffer frameBuf, cellsBuf, keysBuf, visibleBuf, heightsBuf, pixelsBuf, countersBuf;
    Buffer beamsBuf;  // beams.comp's start depths, beamSlots of them this frame (0: no beams)
    size_t beamSlots = 0, outerBeamSlots = 0;
    // Out of core (backend.cpp's first comment): the last frame's heights buffer, and what the CPU evaluated this
    // frame.
    Buffer lastHeightsBuf, fillRowsBuf, fillTexelsBuf;
    // The rays are copied here on the GPU and read from here. Mapping pixelsBuf itself for reading made NVIDIA's
    // driver move it to host memory: every later frame's ray casting then wrote its rays over PCIe (H100: 1.2 ms
    // in the first frame, 12.5-14.5 ms in each after it; docs/benchmarks.md).
    Buffer readbackBuf{0, 0, GL_STREAM_READ};
    std::array<Buffer, gpu::kIndexChunks> indexBufs;  // the lists' entries, in chunks of 2^indexChunkShift
    uint32_t indexChunkShift = 31;
    GLuint colorTex = 0;
    int texWidth = 0, texHeight = 0;
    static constexpr int kStamps = 4 + gpu::kMaxCascades + 1;
    std::array<GLuint, kStamps> stamps{};
    // Software OpenGL (llvmpipe) stamps its timer queries when it flushes, not when the dispatches before them
    // end, which misattributed the stages (in a GLX window: approximation and shading 0 ms). There each stamp
    // waits for the work before it (glFinish: llvmpipe runs dispatches on the CPU anyway) and reads the clock.
    bool software = false;
    std::array<double, kStamps> cpuStamps{};
    GLint64 maxStorageBlock = 0;
    std::string device;
    detail::FrameSetup setup;  // of the last frame, for readback
    // Out of core: the cascades' new texels are evaluated on the CPU (backend.cpp's first comment). The cache holds the
    // last frame's cascades (their shapes: the texels are on the GPU), lastCascades their places in lastHeightsBuf, and
    // lastAssembled whether that frame got as far as building them (if not, nothing is kept).
    const bool cpuCascades;
    CascadeCache cascadeCache;
    std::array<gpu::GpuCascade, gpu::kMaxCascades> lastCascades{};
    size_t lastCascadeCount = 0;
    bool lastAssembled = false;
    struct Assembly {                   // a cascade of this frame for assemble.comp
        int rowBase = 0;                // its first row in fillRowsBuf
        int from = -1, di = 0, dj = 0;  // detail::CascadeFill
        int widest[2] = {0, 0};         // in memory: the most texels of a row's first and second span to evaluate
    };
    std::array<Assembly, gpu::kMaxCascades> assembly{};
    uint32_t fillPlane = 0;  // packed texels a channel
    // What goes into fillRowsBuf and fillTexelsBuf (terrain, water, depth), kept from frame to frame (no new pages).
    std::vector<int32_t> fillRows;
    std::array<std::vector<float>, 3> fillTexels;
    // Out of core with a pyramid: its tiles on the GPU (elevations; water levels and wet shares), this frame's tiles to
    // copy texels from (atlas.comp), 4 uints a tile, and its blocks of texels to interpolate from level 0's tiles
    // (interpolate.comp), gpu::kAtlasBlockUints a block.
    TileAtlas terrainAtlas, waterAtlas;
    Buffer atlasTilesBuf, atlasBlocksBuf;
    std::vector<uint32_t> atlasTiles, atlasBlocks;
    uint64_t atlasTexels = 0, atlasInterpolated = 0;  // this frame's

    // backend.cpp: set-up and release, the scene's and the frame's uploads, the frame's stages in turn, the read-back.
    Impl(const Scene& s, std::unique_ptr<gl::HeadlessContext> context);
    ~Impl();
    void release();
    void checkBlock(size_t bytes, const char* what) const;
    void uploadScene();
    void fillFrame(gpu::GpuFrame& f, const CascadeFit& fit, const Camera& camera, const RenderOptions& options) const;
    size_t layOutCascades(gpu::FrameBlock& block, const CascadeFit& fit, Timings& timings, size_t& visibleWords) const;
    uint64_t cascadeBytes(const CascadeFit& fit) const;
    void uploadFrame(gpu::FrameBlock& block, const CascadeFit& fit, const Camera& camera, const RenderOptions& options,
                     Timings& timings);
    CascadeFit runFrame(const Camera& camera, const RenderOptions& options, Timings& timings);
    GLuint program(const std::string& name) const;
    Frame readBack(const Camera& camera, Timings& timings, ReadBack what);

    // backend_overlay.cpp: what the CPU computes from the hits for shade.comp (GpuFrame::overlay): the colour layer's
    // values and, out of core, the cell outlines' factors; the layer's values kept for readBack
    // (Frame::colorLayerValue).
    Buffer overlayBuf;
    std::vector<float> layerValues;
    std::string layerName;
    int overlayBits(const RenderOptions& options) const;  // GpuFrame::overlay's bits for these options
    // The rays copied on the GPU into readbackBuf (once a frame: raysCopied) and mapped for reading (bound as
    // GL_SHADER_STORAGE_BUFFER): unmap after reading.
    const gpu::GpuPixel* mapRays(size_t pixels);
    bool raysCopied = false;  // this frame's rays are in readbackBuf
    // A hit's local position as the Frame holds it: the camera-relative offset added to the eye in double, then float
    // (what readBack() and fillOverlay() both give: the overlay's values are taken where the frame says the hit is).
    glm::vec3 hitLocal(const gpu::GpuPixel& p) const {
        return {float(setup.eyeLocal.x + double(p.relX)), float(setup.eyeLocal.y + double(p.relY)),
                float(setup.eyeLocal.z + double(p.relZ))};
    }
    void fillOverlay(const Camera& camera, const RenderOptions& options, int bits);

    // backend_cpu_fill.cpp: stage 2's plan on the CPU (in memory), or its texels evaluated there (out of core), with
    // each cascade's rows into fillRowsBuf and fillTexelsBuf for assemble.comp.
    size_t addRows(size_t k, const detail::CascadeFill& fill, size_t packed);
    size_t uploadRows();
    void approximateOnCpu(const CascadeFit& fit, const gpu::FrameBlock& block, const RenderOptions& options,
                          Timings& timings, bool keep);
    void planOnGpu(const CascadeFit& fit, const gpu::FrameBlock& block, const RenderOptions& options, Timings& timings,
                   bool keep);

    // backend_atlas.cpp: out of core with a pyramid, the tiles and blocks a frame copies and interpolates on the GPU,
    // placed in the atlases.
    uint64_t placeTiles(size_t k, detail::CascadeTextures& tex, detail::CascadeFill& fill, float minDepth, int& rowLo,
                        int& rowHi);
    void openAtlases();
    void placeBlocks(size_t k, const Cascade& c, detail::CascadeTextures& tex, detail::CascadeFill& fill,
                     double waterMinDepthM, int& rowLo, int& rowHi);

    // backend_pictures.cpp: the pictures in flight (GlRenderer::submitPicture), a ring of pixel buffers, each with the
    // fence after its copy and the frame it holds (its size, its world origin and its timings, taken when it was
    // submitted: a sequence may hand the renderer another scene before the picture is collected).
    struct PictureSlot {
        GLuint buffer = 0;
        size_t bytes = 0;
        GLsync fence = nullptr;
        Frame frame;  // size and origin only
        Timings timings;
    };
    std::array<PictureSlot, GlRenderer::kPicturesInFlight> pictures{};
    size_t picturesFirst = 0, picturesCount = 0;
    void startPictureCopy(const Camera& camera, const Timings& timings);
    GlRenderer::Picture finishPictureCopy();
    void releasePictures();

    // backend_dispatch.cpp: the bindings, the compute dispatches of each stage, the time stamps and counters.
    // assemble.comp's texels an invocation (kRun) and invocations a work group (local_size_x).
    static constexpr GLuint kAssembleRun = 16, kAssembleGroup = 64;
    // Work groups covering `size` invocations along one axis.
    static GLuint groups(int size) { return GLuint((size + HC_GROUP_2D - 1) / HC_GROUP_2D); }
    void timeStamp(int i, const Stopwatch& frameClock);
    void bindFrame() const;
    void dispatchAtlas();
    void dispatchAssembly(const CascadeFit& fit);
    void dispatchApproximation(const CascadeFit& fit, const Stopwatch& frameClock, int& stamp);
    void dispatchMipmaps(const CascadeFit& fit, const gpu::FrameBlock& block);
    void dispatchPerPixel(GLuint program, const Camera& camera) const;
    void readStageTimes(int stampCount, size_t cascadeCount, Timings& timings);
    void readCounters(size_t cascadeCount, Timings& timings) const;
    // Without a surface pyramid's bound, the frame's is estimated from the texels (mipmap.comp, CascadeStats).
    bool estimatesError() const { return scene->boundFromTexels(); }
    void throwOnGlError() const;
};

}  // namespace hc::render
