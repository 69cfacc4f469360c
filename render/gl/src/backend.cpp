// The OpenGL 4.3 compute backend (DESIGN.md sections 5 and 9): GlRenderer.
//
// Per frame: cascade fitting on the CPU (fitCascades, shared with renderFrame()), then four compute
// stages, each mirroring a CPU function: approximate.comp (detail::approximate), mipmap.comp
// (Heightfield::buildMip), raycast.comp (detail::castRay) and shade.comp (renderFrame's shading and
// drawLegend). The scene (cells, sorted Morton keys, influence lists) is uploaded once; per frame only
// the FrameBlock (gpu_layout.h) and the cascades' visible row spans go up. GPU stage times come from
// GL_TIMESTAMP queries between the dispatches.
//
// The cascades stay on the GPU from one frame to the next (two heights buffers, swapped each frame): assemble.comp
// starts each frame's textures from the last frame's texels that the frame still sees (the incremental cascades of
// DESIGN.md section 6, planned on the CPU as renderFrame() plans them), and only the others are evaluated. In memory
// approximate.comp sums those (detail::planCascades gives the spans).
//
// Out of core (a Scene over a GridRegionReader: no cells or lists in memory, the grid may hold 100 M cells) the
// cascades stay on the GPU from one frame to the next, and the CPU evaluates only the texels a frame newly sees, as
// renderFrame() evaluates them (from the surface pyramid and the cells around the texels it does not hold:
// detail::approximateOnCpu). With a surface pyramid the texels it holds are copied on the GPU from its tiles resident
// there (the atlas: atlas.comp), and those finer than its finest level interpolated there from level 0's tiles where
// those are all stored and alike (interpolate.comp); the CPU lists which. The rest go up packed with each cascade's
// rows, and assemble.comp builds the frame's textures from them and the last frame's, which the GPU kept (two heights
// buffers, swapped each frame): a moving camera uploads kilobytes, not the cascades. The mipmaps, ray casting and
// shading stay on the GPU. Nothing of the grid is uploaded.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "textures.h"
#include "context.h"
#include "gl.h"
#include "program.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/timer.h"
#include "heightcast/influence/surface.h"
#include "heightcast/render/gl/gl_renderer.h"
#include "heightcast/render/gpu_layout.h"

namespace hc::render {

std::string headlessGlUnavailable(std::string* device) {
    try {
        const auto context = gl::HeadlessContext::create();
        if (device) *device = gl::currentDeviceName();
        return "";
    } catch (const Error& e) {
        return e.what();
    }
}

namespace {

// GlRenderer::limitIndexChunksForTest: the most entries one chunk of the lists may hold.
uint64_t gIndexChunkLimitForTest = uint64_t{1} << 31;
// GlRenderer::limitAtlasForTest: the most pyramid tiles an atlas may hold (0: as many as its storage allows), for the
// renderers made after it.
uint32_t gAtlasTileLimitForTest = 0;

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

// Pyramid tiles resident on the GPU from frame to frame (DESIGN.md section 10: the atlas), in slots of `planes` channels
// of gpu::kAtlasPlane floats: out of core the texels a frame copies from the pyramid are copied there (atlas.comp)
// instead of on the CPU, and only tiles not yet resident go up. A tile is known by its first sample's address in the
// pyramid (a mapped file, or the water pyramid's). Slots are taken in turn, skipping those this frame uses, so the tile
// placed longest ago is the first dropped (a clock without reference bits: a flight's tiles come and go together).
struct TileAtlas {
    static constexpr uint32_t kNone = ~uint32_t{0};
    Buffer buffer;
    size_t planes = 1;
    uint32_t capacity = 0;  // slots
    uint32_t limit = 0;     // at most this many (GlRenderer::limitAtlasForTest), 0: as many as fit
    std::unordered_map<const float*, uint32_t> slotOf;
    std::vector<const float*> tileIn;  // per slot (nullptr: free)
    std::vector<uint64_t> usedIn;      // per slot: the frame that used it last
    // Per slot: bit c of row r set where the tile's sample (c, r) of its first channel is a number (not NaN: outside every
    // cell), so that the copied texels of a tile are counted without reading the tile again (validIn).
    std::vector<std::array<uint16_t, 16>> validRows;
    static_assert(gpu::kAtlasPlane <= 16 * 16, "validRows holds a tile of at most 16 x 16 samples");
    uint32_t hand = 0, usedNow = 0;
    uint64_t frame = 0;
    uint64_t uploadedTiles = 0, uploadedBytes = 0;  // this frame's
    std::vector<float> staging;        // this frame's new tiles, in the order of stagedSlots
    std::vector<uint32_t> stagedSlots;

    // Sized once, at the first frame that copies from it: `bytes` of storage (the buffer is never grown: that would
    // lose the tiles in it).
    void open(size_t bytes, size_t channelPlanes) {
        if (capacity) return;
        planes = channelPlanes;
        const size_t slotBytes = planes * size_t(gpu::kAtlasPlane) * sizeof(float);
        capacity = uint32_t(std::min<size_t>(bytes / slotBytes, size_t{1} << 24));
        if (limit) capacity = std::min(capacity, limit);
        buffer.reserve(size_t(capacity) * slotBytes);
        tileIn.assign(capacity, nullptr), usedIn.assign(capacity, 0), validRows.assign(capacity, {});
    }
    void beginFrame() { ++frame, usedNow = 0, uploadedTiles = 0, uploadedBytes = 0, staging.clear(), stagedSlots.clear(); }
    // The slot holding `tile` (its planes of `plane` floats each, `plane` apart) this frame, staged for upload if it was
    // not resident; kNone when this frame already uses every slot.
    uint32_t slot(const float* tile, size_t plane) {
        if (const auto it = slotOf.find(tile); it != slotOf.end()) {
            if (usedIn[it->second] != frame) usedIn[it->second] = frame, ++usedNow;
            return it->second;
        }
        if (usedNow >= capacity) return kNone;
        while (usedIn[hand] == frame && tileIn[hand]) hand = (hand + 1) % capacity;
        const uint32_t s = hand;
        hand = (hand + 1) % capacity;
        if (tileIn[s]) slotOf.erase(tileIn[s]);
        tileIn[s] = tile, usedIn[s] = frame, ++usedNow;
        slotOf.emplace(tile, s);
        const size_t at = staging.size();
        staging.resize(at + planes * size_t(gpu::kAtlasPlane), 0.0f);
        for (size_t c = 0; c < planes; ++c) std::copy_n(tile + c * plane, plane, &staging[at + c * size_t(gpu::kAtlasPlane)]);
        stagedSlots.push_back(s);
        const size_t side = sideOf(plane);
        validRows[s] = {};
        for (size_t r = 0; r < side; ++r)
            for (size_t c = 0; c < side; ++c) validRows[s][r] |= uint16_t(!std::isnan(tile[r * side + c]) << c);
        return s;
    }
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
    void upload() {
        const size_t slotFloats = planes * size_t(gpu::kAtlasPlane);
        for (size_t a = 0; a < stagedSlots.size();) {
            size_t b = a + 1;
            while (b < stagedSlots.size() && stagedSlots[b] == stagedSlots[b - 1] + 1) ++b;
            buffer.upload(&staging[a * slotFloats], (b - a) * slotFloats * sizeof(float), size_t(stagedSlots[a]) * slotFloats * sizeof(float));
            a = b;
        }
        uploadedTiles += stagedSlots.size(), uploadedBytes += staging.size() * sizeof(float);
        staging.clear(), stagedSlots.clear();
    }
    void release() {
        buffer.release();
        capacity = 0, hand = 0, usedNow = 0;
        slotOf.clear(), tileIn.clear(), usedIn.clear(), validRows.clear();
    }
};

void copyFloats(float* dst, const glm::dvec3& v) {
    for (int i = 0; i < 3; ++i) dst[i] = float(v[i]);
}

}  // namespace

struct GlRenderer::Impl {
    const Scene& scene;
    std::unique_ptr<gl::HeadlessContext> headless;  // null when rendering into the caller's context
    GLuint approximate = 0, assemble = 0, atlas = 0, interpolate = 0, beams = 0, mipmap = 0, raycast = 0, shade = 0;
    Buffer frameBuf, cellsBuf, keysBuf, visibleBuf, heightsBuf, pixelsBuf, countersBuf;
    Buffer beamsBuf;        // beams.comp's start depths, beamSlots of them this frame (0: no beams)
    size_t beamSlots = 0, outerBeamSlots = 0;
    // Out of core (the file comment): the last frame's heights buffer, and what the CPU evaluated this frame.
    Buffer lastHeightsBuf, fillRowsBuf, fillTexelsBuf;
    // The rays are copied here on the GPU and read from here. Mapping pixelsBuf itself for reading made NVIDIA's
    // driver move it to host memory: every later frame's ray casting then wrote its rays over PCIe (H100: 1.2 ms
    // in the first frame, 12.5-14.5 ms in each after it; BENCHMARKS.md).
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
    // Out of core: the cascades' new texels are evaluated on the CPU (the file comment). The cache holds the last frame's
    // cascades (their shapes: the texels are on the GPU), lastCascades their places in lastHeightsBuf, and
    // lastAssembled whether that frame got as far as building them (if not, nothing is kept).
    const bool cpuCascades;
    CascadeCache cascadeCache;
    std::array<gpu::GpuCascade, gpu::kMaxCascades> lastCascades{};
    size_t lastCascadeCount = 0;
    bool lastAssembled = false;
    struct Assembly {  // a cascade of this frame for assemble.comp
        int rowBase = 0;          // its first row in fillRowsBuf
        int from = -1, di = 0, dj = 0;  // detail::CascadeFill
        int widest[2] = {0, 0};   // in memory: the most texels of a row's first and second span to evaluate
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

    Impl(const Scene& s, std::unique_ptr<gl::HeadlessContext> context) : scene(s), headless(std::move(context)), cpuCascades(s.outOfCore()) {
        gl::requireGl43("the GL backend");
        device = gl::currentDeviceName();
        software = isSoftwareRenderer(device);
        glGetInteger64v(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &maxStorageBlock);
        terrainAtlas.limit = waterAtlas.limit = gAtlasTileLimitForTest;
        if (maxStorageBlock <= 0) maxStorageBlock = GLint64{1} << 24;  // OpenGL 4.3's minimum
        glGenQueries(kStamps, stamps.data());
        try {
            approximate = gl::compileEmbedded("approximate");
            assemble = gl::compileEmbedded("assemble");
            atlas = gl::compileEmbedded("atlas");
            interpolate = gl::compileEmbedded("interpolate");
            beams = gl::compileEmbedded("beams");
            mipmap = gl::compileEmbedded("mipmap");
            raycast = gl::compileEmbedded("raycast");
            shade = gl::compileEmbedded("shade");
            uploadScene();
        } catch (...) {
            release();  // a caller's context outlives this failed renderer: leave nothing in it
            throw;
        }
    }

    ~Impl() {
        if (headless) headless->makeCurrent();
        release();
    }

    void release() {
        for (GLuint p : {approximate, assemble, atlas, interpolate, beams, mipmap, raycast, shade})
            if (p) glDeleteProgram(p);
        approximate = assemble = atlas = interpolate = beams = mipmap = raycast = shade = 0;
        for (Buffer* b : {&frameBuf, &cellsBuf, &keysBuf, &visibleBuf, &heightsBuf, &pixelsBuf, &countersBuf, &readbackBuf, &lastHeightsBuf,
                          &fillRowsBuf, &fillTexelsBuf, &beamsBuf, &atlasTilesBuf, &atlasBlocksBuf})
            b->release();
        terrainAtlas.release(), waterAtlas.release();
        for (Buffer& b : indexBufs) b.release();
        if (colorTex) glDeleteTextures(1, &colorTex);
        colorTex = 0;
        if (stamps[0]) glDeleteQueries(kStamps, stamps.data());
        stamps = {};
    }

    void checkBlock(size_t bytes, const char* what) const {
        if (maxStorageBlock > 0 && bytes > size_t(maxStorageBlock))
            throw Error(std::string("the GL backend needs ") + std::to_string(bytes >> 20) + " MiB for " + what +
                        " in one storage buffer; this driver allows " + std::to_string(maxStorageBlock >> 20) + " MiB" +
                        (std::strcmp(what, "the cascade textures") == 0 ? " (use fewer --texels or --cascades)" : ""));
    }

    // Cells (plus a sentinel), their sorted Morton keys and the influence lists: once per renderer. Out of core
    // none: every binding gets a small buffer (the shaders that would read them are not run, and cellCount is 0).
    void uploadScene() {
        GLint bindings = 0;
        glGetIntegerv(GL_MAX_SHADER_STORAGE_BUFFER_BINDINGS, &bindings);
        if (bindings <= HC_BIND_LAST)
            throw Error("the GL backend needs " + std::to_string(HC_BIND_LAST + 1) + " shader storage buffer bindings; " + device + " has " +
                        std::to_string(bindings) + ": use --backend cpu");
        for (Buffer* b : {&lastHeightsBuf, &fillRowsBuf, &fillTexelsBuf, &beamsBuf, &atlasTilesBuf, &atlasBlocksBuf, &terrainAtlas.buffer, &waterAtlas.buffer})
            b->reserve(16);
        frameBuf.reserve(sizeof(gpu::FrameBlock));
        countersBuf.reserve(sizeof(uint32_t) * gpu::kCounterSlots * (gpu::kMaxCascades + 1));
        if (cpuCascades) {
            const gpu::GpuCell sentinel{};
            cellsBuf.reserve(sizeof sentinel);
            cellsBuf.upload(&sentinel, sizeof sentinel);
            keysBuf.reserve(16);
            for (Buffer& b : indexBufs) b.reserve(16);
            return;
        }
        const Grid& g = scene.grid();
        const auto& lists = scene.lists();
        const size_t count = g.cellCount();
        if (lists.entryCount() >= (uint64_t{1} << 32) || count >= (uint64_t{1} << 31))
            throw Error("the GL backend addresses influence lists with 32-bit indices: this grid has " + std::to_string(lists.entryCount()) +
                        " entries");
        std::vector<gpu::GpuCell> cells(count + 1);
        std::vector<uint32_t> keys(2 * count);
        const int water = scene.waterLayer();
        const auto offsets = lists.offsets();
        for (size_t k = 0; k < count; ++k) {
            gpu::GpuCell& c = cells[k];
            const uint64_t code = g.codes[k];
            c.ix = Grid::keyX(code);
            c.iy = Grid::keyY(code);
            c.level = uint32_t(codeLevel(code));
            c.listBegin = uint32_t(offsets[k]);
            c.a = scene.kernels()[k].a;
            c.r2 = scene.kernels()[k].r2;
            c.z = g.values[0][k];
            c.depth = water >= 0 ? g.values[size_t(water)][k] : 0.0f;
            const uint64_t key = codeKey(code);
            keys[2 * k] = uint32_t(key);
            keys[2 * k + 1] = uint32_t(key >> 32);
        }
        cells[count] = gpu::GpuCell{};
        cells[count].listBegin = uint32_t(offsets[count]);
        const size_t cellBytes = cells.size() * sizeof(gpu::GpuCell), keyBytes = keys.size() * 4;
        checkBlock(cellBytes, "the cells");
        cellsBuf.reserve(cellBytes);
        cellsBuf.upload(cells.data(), cellBytes);
        keysBuf.reserve(keyBytes);
        keysBuf.upload(keys.data(), keyBytes);
        // The entries in chunks of a power of two that one storage buffer can hold.
        const auto entries = lists.indices();
        uint64_t chunkEntries = uint64_t{1} << 31;
        while (chunkEntries > 1 && (chunkEntries * 4 > uint64_t(maxStorageBlock) || chunkEntries > gIndexChunkLimitForTest)) chunkEntries >>= 1;
        indexChunkShift = uint32_t(std::countr_zero(chunkEntries));
        const uint64_t chunks = (entries.size() + chunkEntries - 1) / chunkEntries;
        if (chunks > uint64_t(gpu::kIndexChunks))
            throw Error("the GL backend needs " + std::to_string(entries.size_bytes() >> 20) + " MiB for the influence lists; this driver allows " +
                        std::to_string(gpu::kIndexChunks) + " storage buffers of " + std::to_string((chunkEntries * 4) >> 20) + " MiB");
        for (size_t c = 0; c < size_t(gpu::kIndexChunks); ++c) {
            const size_t begin = std::min<size_t>(c * chunkEntries, entries.size());
            const size_t n = std::min<size_t>(entries.size() - begin, chunkEntries);
            indexBufs[c].reserve(n * 4);  // empty chunks get a small buffer: every binding is valid
            if (n) indexBufs[c].upload(entries.data() + begin, n * 4);
        }
    }

    // The frame's constants (GpuFrame) for the shaders.
    void fillFrame(gpu::GpuFrame& f, const CascadeFit& fit, const Camera& camera, const RenderOptions& options) const {
        const Grid& g = scene.grid();
        f.eyeX = setup.eyeLocal.x, f.eyeY = setup.eyeLocal.y;
        f.finestM = g.finestCellM;
        f.domainM = g.domainSizeM();
        f.eyeZ = float(setup.eyeLocal.z);
        f.tanHalfX = float(setup.basis.tanHalfX), f.tanHalfY = float(setup.basis.tanHalfY);
        f.nearM = float(setup.nearM), f.farM = float(setup.farM);
        f.dirX = float(fit.dir.x), f.dirY = float(fit.dir.y);
        f.tail = float(scene.params().tail());
        copyFloats(f.forward, setup.basis.forward);
        copyFloats(f.right, setup.basis.right);
        copyFloats(f.up, setup.basis.up);
        const double sunAz = gpu::kSunAzimuthDeg * M_PI / 180, sunAlt = gpu::kSunAltitudeDeg * M_PI / 180;
        copyFloats(f.sun, {std::sin(sunAz) * std::cos(sunAlt), std::cos(sunAz) * std::cos(sunAlt), std::sin(sunAlt)});
        f.width = camera.width, f.height = camera.height;
        f.cascades = fit.hull.size() < 3 ? 0 : int(fit.cascades.size());  // no hull: every ray misses (as renderFrame)
        f.hasWater = scene.hasWater() ? 1 : 0;
        f.cellCount = cpuCascades ? 0u : uint32_t(g.cellCount());  // out of core no cell is on the GPU
        f.rootLevel = uint32_t(g.rootLevel);
        f.indexChunkShift = indexChunkShift;
        f.minDepthM = float(options.waterMinDepthM);
        f.fogDistM = float(gpu::kFogExtents * std::hypot(scene.xMax - scene.xMin, scene.yMax - scene.yMin));
        f.elevationMin = float(scene.elevationMin);
        f.zRange = float(std::max(scene.elevationMax - scene.elevationMin, 1e-6));
        f.dRange = float(std::max(scene.depthColorMaxM, 1e-6));
        f.pixelAngle = float(2.0 * setup.basis.tanHalfY / camera.height);
        f.colorMode = options.color == ColorMode::WaterDepth ? 1 : 0;
        f.cellOutlines = options.cellOutlines ? 1 : 0;
        const detail::LegendLayout legend = detail::legendLayout(scene, options, camera.width, camera.height);
        if (legend.shown) {
            f.legendRamp = legend.depth ? 1 : 2;
            f.legendX0 = legend.x0, f.legendY0 = legend.y0, f.legendBarW = legend.barW, f.legendBarH = legend.barH;
            f.legendScale = legend.scale;
            f.labelHiLen = int(std::min<size_t>(legend.hi.size(), gpu::kMaxLabelChars));
            f.labelLoLen = int(std::min<size_t>(legend.lo.size(), gpu::kMaxLabelChars));
            for (int i = 0; i < f.labelHiLen; ++i) f.labelHi[i] = gpu::glyphBits(legend.hi[size_t(i)]);
            for (int i = 0; i < f.labelLoLen; ++i) f.labelLo[i] = gpu::glyphBits(legend.lo[size_t(i)]);
        }
        for (int i = 0; i < 5; ++i)
            for (int c = 0; c < 4; ++c) f.elevationRamp[4 * i + c] = float(gpu::kElevationRamp[i][c]);
        for (int i = 0; i < 3; ++i)
            for (int c = 0; c < 4; ++c) f.depthRamp[4 * i + c] = float(gpu::kDepthRamp[i][c]);
        for (int c = 0; c < 3; ++c) {
            f.skyHorizon[c] = float(gpu::kSkyHorizon[c]);
            f.skyZenith[c] = float(gpu::kSkyZenith[c]);
            f.dryColor[c] = float(gpu::kDryColor[c]);
            f.wallColor[c] = float(gpu::kWallColor[c]);
        }
        f.zFloor = float(scene.elevationMin);
        f.beamTile = options.beamTilePx > 1 ? options.beamTilePx : 0;  // beams.comp, raycast.comp

    }

    // Each cascade's places in the heights and visibility buffers (GpuCascade), and its statistics.
    // Returns the floats the heights buffer needs; adds the visible row spans' ints to visibleWords.
    size_t layOutCascades(gpu::FrameBlock& block, const CascadeFit& fit, Timings& timings, size_t& visibleWords) const {
        const bool water = scene.hasWater();
        size_t heightFloats = 0;
        for (size_t k = 0; k < fit.cascades.size(); ++k) {
            const Cascade& c = fit.cascades[k];
            gpu::GpuCascade& gc = block.cascades[k];
            timings.cascades.push_back(detail::statsOf(c));
            gc.splitNear = float(c.splitNear), gc.splitFar = float(c.splitFar), gc.farWithOverlap = float(c.farWithOverlap);
            if (c.empty()) continue;  // n = 0: the shaders skip it
            const size_t n = size_t(c.n), texels = n * n;
            gc.x0 = c.x0, gc.y0 = c.y0, gc.texelM = c.texelM;
            gc.x0Eye = float(c.x0 - setup.eyeLocal.x), gc.y0Eye = float(c.y0 - setup.eyeLocal.y);
            gc.texelF = float(c.texelM);
            gc.n = c.n;
            gc.terrainOffset = uint32_t(heightFloats), heightFloats += texels;
            if (water) {
                gc.waterOffset = uint32_t(heightFloats), heightFloats += texels;
                gc.depthOffset = uint32_t(heightFloats), heightFloats += texels;
            }
            int side = c.n - 1, levels = 0;
            for (;;) {
                if (levels >= gpu::kMaxMipLevels) throw Error("the GL backend's max mipmap has more than 16 levels");
                gc.mipSide[levels] = side;
                gc.terrainMip[levels] = uint32_t(heightFloats), heightFloats += size_t(side) * size_t(side);
                if (water) gc.waterMip[levels] = uint32_t(heightFloats), heightFloats += size_t(side) * size_t(side);
                ++levels;
                if (side <= 1) break;
                side = (side + 1) / 2;
            }
            gc.levels = levels;
            gc.visibleOffset = uint32_t(visibleWords);
            visibleWords += 4 * n;  // two spans a row: the texels to evaluate (planOnGpu)
        }
        return heightFloats;
    }

    // Marks the end of the work submitted so far: a GPU timer query, or on software OpenGL the frame's clock
    // after glFinish.
    void timeStamp(int i, const Stopwatch& frameClock) {
        if (!software) {
            glQueryCounter(stamps[size_t(i)], GL_TIMESTAMP);
            return;
        }
        glFinish();
        cpuStamps[size_t(i)] = frameClock.milliseconds();
    }

    // The frame's constants, the cascades' places in the heights and visibility buffers and their row spans,
    // into the buffers (grown as needed); the counters zeroed; the colour texture at the frame's size.
    void uploadFrame(gpu::FrameBlock& block, const CascadeFit& fit, const Camera& camera, const RenderOptions& options, Timings& timings) {
        fillFrame(block.frame, fit, camera, options);
        size_t visibleWords = 0;
        const size_t heightFloats = layOutCascades(block, fit, timings, visibleWords);
        const int W = camera.width, H = camera.height;
        checkBlock(heightFloats * 4, "the cascade textures");
        heightsBuf.reserve(heightFloats * 4);
        checkBlock(visibleWords * 4, "the row spans to evaluate");
        visibleBuf.reserve(visibleWords * 4);
        frameBuf.upload(&block, sizeof block);
        const size_t pixels = size_t(W) * size_t(H);
        checkBlock(pixels * sizeof(gpu::GpuPixel), "the pixels");
        pixelsBuf.reserve(pixels * sizeof(gpu::GpuPixel));
        beamSlots = outerBeamSlots = 0;
        if (const int T = block.frame.beamTile; T > 1) {
            const size_t across = size_t((W + T - 1) / T), down = size_t((H + T - 1) / T);
            beamSlots = across * down * size_t(gpu::kMaxCascades);  // tiles, then blocks of 4 x 4 tiles (beams.comp)
            outerBeamSlots = ((across + 3) / 4) * ((down + 3) / 4) * size_t(gpu::kMaxCascades);
            checkBlock((beamSlots + outerBeamSlots) * 2 * sizeof(float), "the beams");
            beamsBuf.reserve((beamSlots + outerBeamSlots) * 2 * sizeof(float));
        }
        std::vector<uint32_t> zeros(countersBuf.bytes / 4, 0);
        countersBuf.upload(zeros.data(), countersBuf.bytes);
        if (!colorTex || texWidth != W || texHeight != H) {
            if (colorTex) glDeleteTextures(1, &colorTex);
            glGenTextures(1, &colorTex);
            glBindTexture(GL_TEXTURE_2D, colorTex);
            glTexStorage2D(GL_TEXTURE_2D, 1, GL_RGBA8, W, H);
            glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
            glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
            texWidth = W, texHeight = H;
        }
    }

    // Every buffer and the colour image at the binding points the shaders declare (gpu_layout.h).
    void bindFrame() const {
        frameBuf.bind(HC_BIND_FRAME);
        cellsBuf.bind(HC_BIND_CELLS);
        keysBuf.bind(HC_BIND_KEYS);
        const GLuint indexBindings[gpu::kIndexChunks] = {HC_BIND_INDICES, HC_BIND_INDICES_1, HC_BIND_INDICES_2, HC_BIND_INDICES_3};
        for (size_t c = 0; c < size_t(gpu::kIndexChunks); ++c) indexBufs[c].bind(indexBindings[c]);
        visibleBuf.bind(HC_BIND_VISIBLE);
        heightsBuf.bind(HC_BIND_HEIGHTS);
        pixelsBuf.bind(HC_BIND_PIXELS);
        beamsBuf.bind(HC_BIND_BEAMS);
        countersBuf.bind(HC_BIND_COUNTERS);
        glBindImageTexture(HC_IMAGE_COLOR, colorTex, 0, GL_FALSE, 0, GL_WRITE_ONLY, GL_RGBA8);
    }

    // assemble.comp's texels an invocation (kRun) and invocations a work group (local_size_x).
    static constexpr GLuint kAssembleRun = 16, kAssembleGroup = 64;
    // Work groups covering `size` invocations along one axis.
    static GLuint groups(int size) { return GLuint((size + HC_GROUP_2D - 1) / HC_GROUP_2D); }

    // Stage 2 out of core, on the CPU (the file comment): the texels this frame newly sees, evaluated there and packed
    // with each cascade's rows into fillTexelsBuf and fillRowsBuf for assemble.comp; their statistics and times replace
    // the ones layOutCascades and the time stamps give.
    // Cascade k's rows into fillRows for assemble.comp (RowFill, then where its spans' texels start in the packed planes,
    // counting from `packed`) and its Assembly; returns where the packed texels end.
    size_t addRows(size_t k, const detail::CascadeFill& fill, size_t packed) {
        Assembly& a = assembly[k];
        a.rowBase = int(fillRows.size() / size_t(gpu::kFillRowInts));
        a.from = fill.from, a.di = fill.di, a.dj = fill.dj;
        for (const detail::RowFill& r : fill.rows) {
            const int32_t atA = int32_t(packed);
            packed += size_t(std::max(0, r.a1 - r.a0 + 1));
            const int32_t atB = int32_t(packed);
            packed += size_t(std::max(0, r.b1 - r.b0 + 1));
            fillRows.insert(fillRows.end(), {r.keptFirst, r.keptLast, r.a0, r.a1, r.b0, r.b1, atA, atB});
            a.widest[0] = std::max(a.widest[0], r.a1 - r.a0 + 1), a.widest[1] = std::max(a.widest[1], r.b1 - r.b0 + 1);
        }
        return packed;
    }

    // fillRows into fillRowsBuf; returns the bytes.
    size_t uploadRows() {
        const size_t bytes = fillRows.size() * sizeof(int32_t);
        checkBlock(bytes, "the cascades' rows");
        fillRowsBuf.reserve(bytes);
        if (bytes) fillRowsBuf.upload(fillRows.data(), bytes);
        return bytes;
    }

    // `keep`: the last frame's textures are in lastHeightsBuf (else the cache starts afresh: the GPU does not hold the
    // frame it describes).
    void approximateOnCpu(const CascadeFit& fit, const gpu::FrameBlock& block, const RenderOptions& options, Timings& timings, bool keep) {
        if (!keep) cascadeCache.clear();
        const bool water = scene.hasWater();
        std::array<std::vector<float>, 3>& packed = fillTexels;
        fillRows.clear();
        for (std::vector<float>& p : packed) p.clear();
        assembly = {};
        Timings cpu;
        double packMs = 0;
        // With a pyramid the texels it holds are copied on the GPU, from its tiles resident there (the atlas); only the
        // tiles not yet there go up, with the tiles to copy from (16 bytes a tile) and each row's spans.
        const bool useAtlas = scene.pyramid() != nullptr;
        atlasTiles.clear(), atlasBlocks.clear(), atlasTexels = 0, atlasInterpolated = 0;
        std::vector<int32_t> spans;
        size_t spanBytes = 0;
        if (useAtlas) terrainAtlas.beginFrame(), waterAtlas.beginFrame();
        const float minDepth = float(options.waterMinDepthM);
        detail::approximateOnCpu(scene, fit, options, cascadeCache, cpu, [&](size_t k, detail::CascadeTextures& tex, detail::CascadeFill& fill) {
            const Stopwatch clock;
            if (useAtlas) {  // cpu.cascades: one per cascade of the fit (approximateCascades)
                CascadeStats& stats = cpu.cascades[k];
                // The spans before the copies were taken out, of the rows of the tiles atlas.comp copies from and the
                // blocks interpolate.comp fills (the visible buffer is in-memory's otherwise): a moving frame's few tiles
                // need few rows.
                int lo = fit.cascades[k].n, hi = -1;
                stats.pyramidTexels += placeTiles(k, tex, fill, minDepth, lo, hi);
                if (stats.pyramidTexels) stats.errorBoundM = detail::pyramidCopyBoundM(scene);
                placeBlocks(k, fit.cascades[k], tex, fill, options.waterMinDepthM, lo, hi);
                spans.clear();
                for (int j = lo; j <= hi; ++j) {
                    const detail::RowFill& r = fill.tiles.spans[size_t(j)];
                    spans.insert(spans.end(), {r.a0, r.a1, r.b0, r.b1});
                }
                if (!spans.empty())
                    visibleBuf.upload(spans.data(), spans.size() * sizeof(int32_t), (size_t(block.cascades[k].visibleOffset) + 4 * size_t(lo)) * 4);
                spanBytes += spans.size() * sizeof(int32_t);
            }
            // Each row's place in the packed planes, then the rows copied there on all cores.
            const size_t n = size_t(fit.cascades[k].n), first = packed[0].size(), end = addRows(k, fill, first);
            const size_t channels = water ? 3 : 1;
            for (size_t c = 0; c < channels; ++c) packed[c].resize(end);
            const int32_t* rowInts = &fillRows[size_t(assembly[k].rowBase) * size_t(gpu::kFillRowInts)];
            // On all cores where there is much to copy (a fresh cascade: up to 3 x 16 MB); a moving frame's few texels on this one.
            const unsigned threads = end - first >= (size_t{1} << 16) ? options.threads : 1;
            parallelFor(fill.rows.size(), 64, threads, [&](size_t b, size_t e, unsigned) {
                for (size_t j = b; j < e; ++j) {
                    const detail::RowFill& r = fill.rows[j];
                    for (int span = 0; span < 2; ++span) {
                        const int lo = span == 0 ? r.a0 : r.b0, hi = span == 0 ? r.a1 : r.b1;
                        if (hi < lo) continue;
                        const size_t from = j * n + size_t(lo), count = size_t(hi - lo + 1);
                        const size_t to = size_t(rowInts[j * size_t(gpu::kFillRowInts) + 6 + size_t(span)]);
                        std::memcpy(&packed[0][to], &tex.terrain.h[from], count * sizeof(float));
                        if (water) {
                            std::memcpy(&packed[1][to], &tex.water.h[from], count * sizeof(float));
                            std::memcpy(&packed[2][to], &tex.depth[from], count * sizeof(float));
                        }
                    }
                }
            });
            packMs += clock.milliseconds();
        }, useAtlas);
        const Stopwatch clock;
        const size_t plane = packed[0].size(), planeBytes = plane * sizeof(float), channels = water ? 3 : 1;
        if (plane >= (size_t{1} << 31)) throw Error("the GL backend out of core evaluated more than 2^31 texels in one frame");
        fillPlane = uint32_t(plane);
        checkBlock(planeBytes * channels, "the texels the CPU evaluated");
        const size_t rowBytes = uploadRows();
        fillTexelsBuf.reserve(planeBytes * channels);
        for (size_t c = 0; c < channels && plane; ++c) fillTexelsBuf.upload(packed[c].data(), planeBytes, c * planeBytes);
        size_t atlasBytes = 0;
        if (useAtlas) {
            checkBlock(atlasTiles.size() * sizeof(uint32_t), "the pyramid tiles to copy texels from");
            atlasBytes = terrainAtlas.uploadedBytes + waterAtlas.uploadedBytes + atlasTiles.size() * sizeof(uint32_t) + spanBytes;
            atlasTilesBuf.reserve(atlasTiles.size() * sizeof(uint32_t));
            if (!atlasTiles.empty()) atlasTilesBuf.upload(atlasTiles.data(), atlasTiles.size() * sizeof(uint32_t));
            checkBlock(atlasBlocks.size() * sizeof(uint32_t), "the blocks to interpolate from the pyramid");
            atlasBytes += atlasBlocks.size() * sizeof(uint32_t);
            atlasBlocksBuf.reserve(atlasBlocks.size() * sizeof(uint32_t));
            if (!atlasBlocks.empty()) atlasBlocksBuf.upload(atlasBlocks.data(), atlasBlocks.size() * sizeof(uint32_t));
        }
        timings.cascades = cpu.cascades;
        timings.approximationMs = cpu.approximationMs;
        timings.uploadMs = packMs + clock.milliseconds();
        timings.uploadBytes = rowBytes + planeBytes * channels + atlasBytes;
        timings.atlasTexels = atlasTexels;
        timings.atlasInterpolated = atlasInterpolated;
        timings.atlasTilesUploaded = terrainAtlas.uploadedTiles + waterAtlas.uploadedTiles;
    }

    // Cascade k's tiles to copy texels from (detail::PyramidTiles) as atlas.comp's, uploaded into the atlas where not
    // resident. The texels of a tile that finds no slot (this frame uses every one) are copied here, into `tex`, and
    // their row's RowFill span widened to hold them, so that they go up with the CPU's texels. Returns the texels copied
    // with a surface (approximate() leaves them to be counted here: counting them there read every tile's samples, which
    // the CPU otherwise never touches once the tile is resident; 40 % of copyPyramidTexels on llvmpipe).
    // The rows of the tiles placed widen [rowLo, rowHi] (their spans go up for atlas.comp).
    uint64_t placeTiles(size_t k, detail::CascadeTextures& tex, detail::CascadeFill& fill, float minDepth, int& rowLo, int& rowHi) {
        const detail::PyramidTiles& p = fill.tiles;
        if (p.side == 0) return 0;
        uint64_t copied = 0;
        openAtlases();
        const size_t n = size_t(tex.terrain.n), side = size_t(p.side);
        const int shift = std::countr_zero(side);
        if (n + side >= 32768)  // atlas.comp's tiles hold their first texel's i and j in 16 bits each
            throw Error("the GL backend copies the pyramid's texels into cascades of under 32752 texels a side, not " + std::to_string(n));
        for (size_t e = 0; e < p.tile.size(); ++e) {
            const float* tile = p.tile[e];
            if (!tile) continue;
            const float* water = p.water[e];
            const uint16_t* rows = &p.copied[e * side];
            // The texel of the tile's first sample (it may lie outside the cascade: the tile's samples there are not marked).
            const int64_t i0 = int64_t(e % size_t(p.width)) * int64_t(side) - p.originI, j0 = int64_t(e / size_t(p.width)) * int64_t(side) - p.originJ;
            const uint32_t slot = terrainAtlas.slot(tile, p.plane);
            const uint32_t waterSlot = water && slot != TileAtlas::kNone ? waterAtlas.slot(water, p.plane) : TileAtlas::kNone;
            if (slot != TileAtlas::kNone && (!water || waterSlot != TileAtlas::kNone)) {
                // The first texel's i and j in 16 bits each (offset by 2^15: a tile may begin left of or below texel 0).
                atlasTiles.insert(atlasTiles.end(), {uint32_t(k) | uint32_t(shift) << 4, uint32_t(i0 + 32768) | uint32_t(j0 + 32768) << 16, slot,
                                                     water ? waterSlot : TileAtlas::kNone});
                rowLo = std::min(rowLo, int(std::max<int64_t>(j0, 0))), rowHi = std::max(rowHi, int(std::min(j0 + int64_t(side) - 1, int64_t(n) - 1)));
                for (size_t r = 0; r < side; ++r) atlasTexels += uint64_t(std::popcount(unsigned(rows[r])));
                copied += uint64_t(terrainAtlas.validIn(slot, rows, side));
                continue;
            }
            for (size_t r = 0; r < side; ++r) {
                const size_t j = size_t(j0 + int64_t(r));
                for (unsigned bits = rows[r]; bits;) {  // each run of marked samples, split where it leaves a span
                    const int c0 = std::countr_zero(bits);
                    int c1 = c0 + std::countr_one(bits >> c0) - 1;
                    const int i = int(i0) + c0;
                    const detail::RowFill& s = p.spans[j];
                    const int span = i >= s.a0 && i <= s.a1 ? 0 : 1;
                    c1 = std::min(c1, (span == 0 ? s.a1 : s.b1) - int(i0));
                    bits &= ~((2u << c1) - (1u << c0));
                    const size_t at = j * n + size_t(i), sample = (r << shift) + size_t(c0);
                    const int count = c1 - c0 + 1;
                    copied += uint64_t(detail::copySamples(tile + sample, water ? water + sample : nullptr, p.plane, count, minDepth,
                                                           &tex.terrain.h[at], water ? &tex.depth[at] : nullptr, water ? &tex.water.h[at] : nullptr));
                    detail::widenSpan(fill.rows[j], span, i, i + count - 1);
                }
            }
        }
        terrainAtlas.upload(), waterAtlas.upload();
        return copied;
    }

    // The atlases take their storage at the first frame that copies from the pyramid: up to 96 MiB each.
    void openAtlases() {
        const size_t atlasBytes = std::min<size_t>(size_t(maxStorageBlock), size_t(96) << 20);
        terrainAtlas.open(atlasBytes, 1);
        if (scene.hasWater()) waterAtlas.open(atlasBytes, 2);
    }

    // Cascade k's blocks of texels to interpolate from level 0's tiles (detail::PyramidTiles::Block) as
    // interpolate.comp's, their tiles uploaded into the atlas where not resident; their rows widen [rowLo, rowHi]. A block
    // whose tiles do not all find a slot (this frame uses every one) is interpolated here, into `tex`, and its rows'
    // RowFill spans widened to hold it, so that it goes up with the CPU's texels.
    void placeBlocks(size_t k, const Cascade& c, detail::CascadeTextures& tex, detail::CascadeFill& fill, double waterMinDepthM, int& rowLo, int& rowHi) {
        const detail::PyramidTiles& p = fill.tiles;
        if (p.blocks.empty()) return;
        openAtlases();
        const int n = tex.terrain.n, side = p.levelSide << p.up;
        if (n + side >= 32768)  // interpolate.comp's blocks hold their first texel's i and j in 16 bits each
            throw Error("the GL backend interpolates the pyramid's texels into cascades of under " + std::to_string(32768 - side) +
                        " texels a side, not " + std::to_string(n));
        for (const detail::PyramidTiles::Block& b : p.blocks) {
            std::array<uint32_t, gpu::kAtlasBlockUints> e;
            e[0] = uint32_t(k) | uint32_t(p.up) << 4 | uint32_t(std::countr_zero(unsigned(p.levelSide))) << 8;
            e[1] = uint32_t(b.i0 + 32768) | uint32_t(b.j0 + 32768) << 16;
            bool placed = true;
            for (size_t q = 0; q < 9 && placed; ++q) {
                e[2 + q] = terrainAtlas.slot(b.tile[q], p.levelPlane);
                e[11 + q] = b.water[q] && e[2 + q] != TileAtlas::kNone ? waterAtlas.slot(b.water[q], p.levelPlane) : TileAtlas::kNone;
                placed = e[2 + q] != TileAtlas::kNone && (!b.water[q] || e[11 + q] != TileAtlas::kNone);
            }
            if (!placed) {
                detail::interpolateBlock(scene, c, p, b, waterMinDepthM, tex, fill.rows);
                continue;
            }
            atlasBlocks.insert(atlasBlocks.end(), e.begin(), e.end());
            const int j0 = int(b.j0);
            rowLo = std::min(rowLo, std::max(j0, 0)), rowHi = std::max(rowHi, std::min(j0 + side - 1, n - 1));
            // The texels interpolate.comp writes.
            detail::forEachBlockRun(p, b, n, [&](int, int lo, int hi, int) { atlasInterpolated += uint64_t(hi - lo + 1); });
        }
        terrainAtlas.upload(), waterAtlas.upload();
    }

    // Out of core with a pyramid: the texels copied from its tiles on the GPU and those interpolated from level 0's, after
    // the assembly (a work group a tile, a block); they write disjoint texels.
    void dispatchAtlas(const RenderOptions& options) {
        const size_t tiles = atlasTiles.size() / 4, blocks = atlasBlocks.size() / size_t(gpu::kAtlasBlockUints);
        if (!cpuCascades || tiles + blocks == 0) return;
        terrainAtlas.buffer.bind(HC_BIND_ATLAS_TERRAIN);
        waterAtlas.buffer.bind(HC_BIND_ATLAS_WATER);
        atlasTilesBuf.bind(HC_BIND_ATLAS_TILES);
        atlasBlocksBuf.bind(HC_BIND_ATLAS_BLOCKS);
        for (const auto& [program, count, name] : {std::tuple{atlas, tiles, "uTiles"}, {interpolate, blocks, "uBlocks"}}) {
            if (count == 0) continue;
            glUseProgram(program);
            glUniform1ui(glGetUniformLocation(program, name), GLuint(count));
            glUniform1f(glGetUniformLocation(program, "uMinDepth"), float(options.waterMinDepthM));
            glUniform1f(glGetUniformLocation(program, "uWetShare"), float(influence::kWetShareMin));
            const size_t across = std::min<size_t>(count, 65535);  // GL's least limit a dimension
            glDispatchCompute(GLuint(across), GLuint((count + across - 1) / across), 1);
        }
        glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    }

    // Stage 2 in memory, its plan on the CPU: each cascade's rows (the texels kept from the last frame, the spans to sum)
    // into fillRowsBuf for assemble.comp, and the spans into visibleBuf for approximate.comp, which sums only those.
    void planOnGpu(const CascadeFit& fit, const gpu::FrameBlock& block, const RenderOptions& options, Timings& timings, bool keep) {
        if (!keep) cascadeCache.clear();
        const Stopwatch clock;
        const std::vector<detail::CascadeFill> fills = detail::planCascades(scene, fit, options, cascadeCache, timings);
        fillRows.clear();
        assembly = {};
        std::vector<int32_t> spans;
        size_t spanBytes = 0;
        for (size_t k = 0; k < fit.cascades.size(); ++k) {
            if (fit.cascades[k].empty()) continue;
            addRows(k, fills[k], 0);  // nothing packed: approximate.comp sums the spans (assemble.comp's uPacked 0)
            spans.clear();
            for (const detail::RowFill& r : fills[k].rows) spans.insert(spans.end(), {r.a0, r.a1, r.b0, r.b1});
            visibleBuf.upload(spans.data(), spans.size() * sizeof(int32_t), size_t(block.cascades[k].visibleOffset) * 4);
            spanBytes += spans.size() * sizeof(int32_t);
        }
        const size_t rowBytes = uploadRows();
        fillPlane = 0;
        timings.uploadMs = clock.milliseconds();
        timings.uploadBytes = rowBytes + spanBytes;
    }

    // Stage 2 on the GPU: each cascade's textures written whole by assemble.comp, the texels kept from the last frame's
    // and (out of core) the packed ones placed, "no surface" elsewhere; in memory approximate.comp then sums the spans. Then they are this frame's:
    // the next may keep them.
    void dispatchAssembly(const CascadeFit& fit) {
        lastHeightsBuf.bind(HC_BIND_LAST_HEIGHTS);
        fillRowsBuf.bind(HC_BIND_FILL_ROWS);
        fillTexelsBuf.bind(HC_BIND_FILL_TEXELS);
        glUseProgram(assemble);
        auto uniform = [&](const char* name) { return glGetUniformLocation(assemble, name); };
        for (size_t k = 0; k < fit.cascades.size(); ++k) {
            if (fit.cascades[k].empty()) continue;
            const Assembly& a = assembly[k];
            const bool kept = a.from >= 0;
            if (kept && size_t(a.from) >= lastCascades.size())
                throw Error("the GL backend's cascades kept on the GPU do not match the CPU's (cascade " + std::to_string(k) + "): a bug");
            const gpu::GpuCascade& last = lastCascades[kept ? size_t(a.from) : 0];
            glUniform1i(uniform("uCascade"), int(k));
            glUniform1i(uniform("uRowBase"), a.rowBase);
            glUniform1ui(uniform("uPlane"), fillPlane);
            glUniform1i(uniform("uKept"), kept ? 1 : 0);
            glUniform1i(uniform("uPacked"), cpuCascades ? 1 : 0);
            glUniform1ui(uniform("uLastTerrain"), last.terrainOffset);
            glUniform1ui(uniform("uLastWater"), last.waterOffset);
            glUniform1ui(uniform("uLastDepth"), last.depthOffset);
            glUniform1i(uniform("uDi"), a.di);
            glUniform1i(uniform("uDj"), a.dj);
            glUniform1i(uniform("uLastN"), last.n);
            const GLuint texelsPerGroup = kAssembleRun * kAssembleGroup;  // assemble.comp: kRun texels an invocation, 64 apart
            glDispatchCompute((GLuint(fit.cascades[k].n) + texelsPerGroup - 1) / texelsPerGroup, GLuint(fit.cascades[k].n), 1);
        }
        glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
        lastAssembled = true;
    }

    // Stage 2: the approximation, one dispatch per cascade, each followed by a time stamp (out of core the stamps
    // only). The assembly before it counts in cascade 0's approximation time in memory, and in the frame's GPU span
    // only out of core (where the CPU's times stand for the approximation).
    void dispatchApproximation(const CascadeFit& fit, const Stopwatch& frameClock, int& stamp) {
        glUseProgram(approximate);
        for (size_t k = 0; k < fit.cascades.size(); ++k) {
            for (int span = 0; span < 2 && !fit.cascades[k].empty() && !cpuCascades; ++span) {  // x: along the span, y: rows
                if (assembly[k].widest[span] <= 0) continue;  // no row has such a span (a fresh frame's second ones)
                glUniform1i(glGetUniformLocation(approximate, "uCascade"), int(k));
                glUniform1i(glGetUniformLocation(approximate, "uSpan"), span);
                const bool relative = assembly[k].widest[span] * 4 <= fit.cascades[k].n;  // narrow spans (approximate.comp)
                glUniform1i(glGetUniformLocation(approximate, "uRelative"), relative ? 1 : 0);
                glDispatchCompute(groups(relative ? assembly[k].widest[span] : fit.cascades[k].n), groups(fit.cascades[k].n), 1);
            }
            timeStamp(stamp++, frameClock);
        }
        glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    }

    // Stage 3: the max mipmaps, one dispatch per level of each cascade's terrain (and water).
    void dispatchMipmaps(const CascadeFit& fit, const gpu::FrameBlock& block) {
        glUseProgram(mipmap);
        const GLint uCascade = glGetUniformLocation(mipmap, "uCascade"), uWater = glGetUniformLocation(mipmap, "uWater"),
                    uLevel = glGetUniformLocation(mipmap, "uLevel");
        for (size_t k = 0; k < fit.cascades.size(); ++k) {
            if (fit.cascades[k].empty()) continue;
            glUniform1i(uCascade, int(k));
            for (int w = 0; w < (scene.hasWater() ? 2 : 1); ++w) {
                glUniform1i(uWater, w);
                for (int level = 0; level < block.cascades[k].levels; ++level) {
                    glUniform1i(uLevel, level);
                    const int side = block.cascades[k].mipSide[level];
                    glDispatchCompute(groups(side), groups(side), 1);
                    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
                }
            }
        }
    }

    // Stages 4 and 5: one invocation per pixel each.
    void dispatchPerPixel(GLuint program, const Camera& camera) const {
        glUseProgram(program);
        glDispatchCompute(groups(camera.width), groups(camera.height), 1);
    }

    // The stage times from the time stamps (waiting for the GPU): stamp 0 before the approximation, one after each
    // cascade's, then after the mipmaps, the ray casting and the shading.
    void readStageTimes(int stampCount, size_t cascadeCount, Timings& timings) {
        std::vector<double> ms(size_t(stampCount), 0.0);
        GLuint64 first = 0;
        if (!software) glGetQueryObjectui64v(stamps[0], GL_QUERY_RESULT, &first);
        for (int i = 1; i < stampCount; ++i) {
            if (software) {
                ms[size_t(i)] = cpuStamps[size_t(i)] - cpuStamps[0];
                continue;
            }
            GLuint64 v = 0;
            glGetQueryObjectui64v(stamps[size_t(i)], GL_QUERY_RESULT, &v);
            ms[size_t(i)] = double(v - first) * 1e-6;
        }
        const size_t nc = cascadeCount;
        for (size_t k = 0; k < nc && !cpuCascades; ++k) {  // out of core the CPU's times stand
            timings.cascades[k].approximationMs = ms[k + 1] - ms[k];
            timings.approximationMs += timings.cascades[k].approximationMs;
        }
        timings.mipmapMs = ms[nc + 1] - ms[nc];
        timings.raycastMs = ms[nc + 2] - ms[nc + 1];
        timings.shadingMs = ms[nc + 3] - ms[nc + 2];
        timings.gpuMs = ms[size_t(stampCount - 1)];
    }

    // The shaders' counters: Gaussians per cascade, then hits.
    void readCounters(size_t cascadeCount, Timings& timings) const {
        std::vector<uint32_t> counters(countersBuf.bytes / 4);
        glBindBuffer(GL_SHADER_STORAGE_BUFFER, countersBuf.name);
        glGetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, GLsizeiptr(countersBuf.bytes), counters.data());
        for (size_t k = 0; k < cascadeCount; ++k)
            for (int s = 0; s < gpu::kCounterSlots; ++s) timings.cascades[k].gaussians += counters[k * gpu::kCounterSlots + size_t(s)];
        for (int s = 0; s < gpu::kCounterSlots; ++s) timings.hits += counters[size_t(gpu::kMaxCascades * gpu::kCounterSlots + s)];
    }

    void throwOnGlError() const {
        if (const GLenum e = glGetError(); e != GL_NO_ERROR) {
            char b[64];
            std::snprintf(b, sizeof b, "OpenGL error 0x%04x", unsigned(e));
            throw Error(std::string("the GL backend failed: ") + b + " on " + device);
        }
    }

    // Runs every stage of one frame; leaves the picture in colorTex and the rays in pixelsBuf.
    CascadeFit runFrame(const Camera& camera, const RenderOptions& options, Timings& timings) {
        camera.validate();
        if (std::string why = options.validate(); !why.empty()) throw Error(why);
        if (!options.colorLayer.empty())  // the tools choose the CPU backend for it (backend_choice.h)
            throw Error("colouring by a layer (" + options.colorLayer + ") is the CPU backend's: use --backend cpu");
        if (cpuCascades && options.cellOutlines)
            throw Error("cell outlines with the GL backend need the grid's cells on the GPU; this scene is read out of core (" +
                        scene.file()->path() + "): use --backend cpu, or give the grid an influence cache (hc-influence) to keep it in memory");
        if (headless) headless->makeCurrent();
        const Stopwatch frameClock;
        timings = Timings{};
        setup = detail::setUpFrame(scene, camera);
        // In memory the shaders sum the kernels of every texel: textures of N^2, not the pyramid's ladder (up to 2N a
        // side, renderer.cpp). Out of core the CPU fills them as renderFrame() does, from the pyramid where there is one.
        if (!cpuCascades) setup.view.ladderStepsPerOctave = 8;
        const CascadeFit fit = detail::fitFrame(scene, camera, setup, options, timings);  // stage 1, on the CPU
        gpu::FrameBlock block{};
        // The last frame's textures stay for assemble.comp to read, if that frame built them; from here until this frame
        // has built its own (dispatchAssembly), a failure leaves nothing to keep.
        const bool keep = lastAssembled;
        std::swap(heightsBuf, lastHeightsBuf), lastAssembled = false;
        uploadFrame(block, fit, camera, options, timings);
        if (cpuCascades) approximateOnCpu(fit, block, options, timings, keep);
        else planOnGpu(fit, block, options, timings, keep);
        bindFrame();
        int stamp = 0;
        timeStamp(stamp++, frameClock);
        dispatchAssembly(fit);
        dispatchAtlas(options);
        dispatchApproximation(fit, frameClock, stamp);
        std::copy(std::begin(block.cascades), std::end(block.cascades), lastCascades.begin());  // where this frame's textures lie
        lastCascadeCount = fit.cascades.size();
        dispatchMipmaps(fit, block);
        timeStamp(stamp++, frameClock);
        if (beamSlots > 0) {  // the beams' marches, blocks then tiles, counted in the ray casting's time
            glUseProgram(beams);
            const GLint outer = glGetUniformLocation(beams, "uOuter");
            for (const int pass : {1, 0}) {  // an image of one tile has as many blocks as tiles: told apart by the pass
                glUniform1i(outer, pass);
                const size_t slots = pass ? outerBeamSlots : beamSlots;
                const size_t groups = (slots + 63) / 64, across = std::min<size_t>(groups, 65535);  // GL's least limit a dimension
                glDispatchCompute(GLuint(across), GLuint((groups + across - 1) / across), 1);
                glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
            }
        }
        dispatchPerPixel(raycast, camera);
        glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
        timeStamp(stamp++, frameClock);
        dispatchPerPixel(shade, camera);
        timeStamp(stamp++, frameClock);
        // The picture is read as a texture (a viewer) or back (render()); the counters and rays back.
        glMemoryBarrier(GL_ALL_BARRIER_BITS);
        glUseProgram(0);
        readStageTimes(stamp, fit.cascades.size(), timings);
        readCounters(fit.cascades.size(), timings);
        timings.rays = size_t(camera.width) * size_t(camera.height);
        throwOnGlError();
        timings.totalMs = frameClock.milliseconds();
        return fit;
    }

    GLuint program(const std::string& name) const {
        if (name == "approximate") return approximate;
        if (name == "mipmap") return mipmap;
        if (name == "raycast") return raycast;
        if (name == "shade") return shade;
        throw Error("no GL program " + name);
    }

    Frame readBack(const Camera& camera, Timings& timings) {
        const Stopwatch clock;
        const int W = camera.width, H = camera.height;
        const size_t pixels = size_t(W) * size_t(H);
        Frame f;
        f.width = W;
        f.height = H;
        f.originWorldX = scene.grid().originWorldX;
        f.originWorldY = scene.grid().originWorldY;
        std::vector<uint8_t> rgba(pixels * 4);
        glBindTexture(GL_TEXTURE_2D, colorTex);
        glPixelStorei(GL_PACK_ALIGNMENT, 1);
        glGetTexImage(GL_TEXTURE_2D, 0, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
        // The rays are copied on the GPU into a buffer of their own (readbackBuf), read through a mapping of it (no
        // staging copy in host memory) and spread over the frame's layers on all cores.
        for (auto* v : {&f.distanceM, &f.posX, &f.posY, &f.posZ, &f.nX, &f.nY, &f.nZ, &f.waterDepthM, &f.cascade, &f.wall}) v->resize(pixels);
        f.rgb.resize(pixels * 3);
        const size_t rayBytes = pixels * sizeof(gpu::GpuPixel);
        readbackBuf.reserve(rayBytes);
        glBindBuffer(GL_COPY_READ_BUFFER, pixelsBuf.name);
        glBindBuffer(GL_COPY_WRITE_BUFFER, readbackBuf.name);
        glCopyBufferSubData(GL_COPY_READ_BUFFER, GL_COPY_WRITE_BUFFER, 0, 0, GLsizeiptr(rayBytes));
        glBindBuffer(GL_SHADER_STORAGE_BUFFER, readbackBuf.name);
        const auto* px = static_cast<const gpu::GpuPixel*>(glMapBufferRange(GL_SHADER_STORAGE_BUFFER, 0, GLsizeiptr(rayBytes), GL_MAP_READ_BIT));
        if (!px) throw Error("the GL backend cannot map its rays for reading on " + device);
        const float inf = std::numeric_limits<float>::infinity();
        parallelFor(size_t(H), 16, 0, [&](size_t rowBegin, size_t rowEnd, unsigned) {
            for (size_t row = rowBegin; row < rowEnd; ++row)
                for (size_t col = 0; col < size_t(W); ++col) {
                    const size_t i = row * size_t(W) + col;
                    const gpu::GpuPixel p = px[i];
                    const uint8_t* src = &rgba[((size_t(H) - 1 - row) * size_t(W) + col) * 4];  // the texture's row 0 is the bottom
                    std::memcpy(&f.rgb[i * 3], src, 3);
                    if (!(p.t < inf)) {
                        f.distanceM[i] = inf;
                        f.posX[i] = f.posY[i] = f.posZ[i] = f.nX[i] = f.nY[i] = f.nZ[i] = f.waterDepthM[i] = f.wall[i] = 0.0f;
                        f.cascade[i] = -1.0f;
                        continue;
                    }
                    f.distanceM[i] = p.t;
                    // Camera-relative offsets back to the local frame in double.
                    f.posX[i] = float(setup.eyeLocal.x + double(p.relX));
                    f.posY[i] = float(setup.eyeLocal.y + double(p.relY));
                    f.posZ[i] = float(setup.eyeLocal.z + double(p.relZ));
                    f.nX[i] = p.nx, f.nY[i] = p.ny, f.nZ[i] = p.nz;
                    f.cascade[i] = float(p.cascade);
                    f.waterDepthM[i] = p.depth;
                    f.wall[i] = p.wall ? 1.0f : 0.0f;
                }
        });
        glUnmapBuffer(GL_SHADER_STORAGE_BUFFER);
        detail::frameToWorldAxes(scene.grid(), f);
        timings.readbackMs = clock.milliseconds();
        timings.totalMs += timings.readbackMs;
        return f;
    }
};

GlRenderer::GlRenderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
GlRenderer::~GlRenderer() = default;

std::unique_ptr<GlRenderer> GlRenderer::inCurrentContext(const Scene& scene) {
    return std::unique_ptr<GlRenderer>(new GlRenderer(std::make_unique<Impl>(scene, nullptr)));
}

std::unique_ptr<GlRenderer> GlRenderer::headless(const Scene& scene) {
    auto context = gl::HeadlessContext::create();
    return std::unique_ptr<GlRenderer>(new GlRenderer(std::make_unique<Impl>(scene, std::move(context))));
}

Frame GlRenderer::render(const Camera& camera, const RenderOptions& options, Timings& timings) {
    impl_->runFrame(camera, options, timings);
    return impl_->readBack(camera, timings);
}

unsigned GlRenderer::renderToTexture(const Camera& camera, const RenderOptions& options, Timings& timings) {
    impl_->runFrame(camera, options, timings);
    return impl_->colorTex;
}

std::string GlRenderer::deviceName() const { return impl_->device; }

std::vector<GlRenderer::CascadeTexels> GlRenderer::cascadeTexturesForTest() const {
    if (impl_->headless) impl_->headless->makeCurrent();
    std::vector<CascadeTexels> out(impl_->lastCascadeCount);
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, impl_->heightsBuf.name);
    for (size_t k = 0; k < out.size(); ++k) {
        const gpu::GpuCascade& c = impl_->lastCascades[k];
        out[k].n = c.n;
        const size_t texels = size_t(c.n) * size_t(c.n);
        auto read = [&](std::vector<float>& to, uint32_t offset) {
            to.resize(texels);
            if (texels) glGetBufferSubData(GL_SHADER_STORAGE_BUFFER, GLintptr(offset) * 4, GLsizeiptr(texels * 4), to.data());
        };
        read(out[k].terrain, c.terrainOffset);
        if (impl_->scene.hasWater()) read(out[k].water, c.waterOffset), read(out[k].depth, c.depthOffset);
    }
    return out;
}

void GlRenderer::forgetCascades() { impl_->cascadeCache.clear(); }

void GlRenderer::limitIndexChunksForTest(uint64_t entries) { gIndexChunkLimitForTest = entries ? entries : uint64_t{1} << 31; }
void GlRenderer::limitAtlasForTest(uint32_t tiles) { gAtlasTileLimitForTest = tiles; }

void GlRenderer::compileForTest(const std::string& name, const std::string& source) const {
    if (impl_->headless) impl_->headless->makeCurrent();
    glDeleteProgram(gl::compileCompute(name, source));
}

GlRenderer::VariableLayout GlRenderer::bufferVariableLayout(const std::string& program, const std::string& variable) const {
    if (impl_->headless) impl_->headless->makeCurrent();
    const GLuint p = impl_->program(program);
    VariableLayout out;
    const GLuint index = glGetProgramResourceIndex(p, GL_BUFFER_VARIABLE, variable.c_str());
    if (index == GL_INVALID_INDEX) return out;
    const GLenum props[2] = {GL_OFFSET, GL_TOP_LEVEL_ARRAY_STRIDE};
    GLint values[2] = {-1, -1};
    glGetProgramResourceiv(p, GL_BUFFER_VARIABLE, index, 2, props, 2, nullptr, values);
    out.offset = values[0];
    out.topLevelArrayStride = values[1];
    return out;
}

long GlRenderer::bufferBlockSize(const std::string& program, const std::string& block) const {
    if (impl_->headless) impl_->headless->makeCurrent();
    const GLuint p = impl_->program(program);
    const GLuint index = glGetProgramResourceIndex(p, GL_SHADER_STORAGE_BLOCK, block.c_str());
    if (index == GL_INVALID_INDEX) return -1;
    const GLenum prop = GL_BUFFER_DATA_SIZE;
    GLint value = -1;
    glGetProgramResourceiv(p, GL_SHADER_STORAGE_BLOCK, index, 1, &prop, 1, nullptr, &value);
    return value;
}

}  // namespace hc::render
