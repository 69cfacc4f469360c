// The OpenGL 4.3 compute backend (docs/design.md sections 5 and 9): GlRenderer.
//
// Per frame: cascade fitting on the CPU (fitCascades, shared with renderFrame()), then four compute
// stages, each mirroring a CPU function: approximate.comp (detail::approximate), shore.comp and mipmap.comp
// (CascadeTextures::extendWaterToShores, Heightfield::buildMip), raycast.comp (detail::castRay) and shade.comp
// (renderFrame's shading and drawLegend). The scene (cells, sorted Morton keys, influence lists) is uploaded once; per
// frame only the FrameBlock (gpu_layout.h) and the cascades' visible row spans go up. GPU stage times come from
// GL_TIMESTAMP queries between the dispatches.
//
// The cascades stay on the GPU from one frame to the next (two heights buffers, swapped each frame): assemble.comp
// starts each frame's textures from the last frame's texels that the frame still sees (the incremental cascades of
// docs/design.md section 5, planned on the CPU as renderFrame() plans them), and only the others are evaluated. In
// memory approximate.comp sums those (detail::planCascades gives the spans).
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
//
// The renderer's parts: its state (GlRenderer::Impl) in backend_internal.h; here its set-up, uploads, the frame's
// stages in turn and the read-back; stage 2 from the CPU in backend_cpu_fill.cpp, the atlas in backend_atlas.cpp, the
// dispatches in backend_dispatch.cpp.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include "backend_internal.h"
#include "program.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/timer.h"
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
// GlRenderer::limitStorageBlockForTest: the storage buffer size renderers made after it take as the driver's (0: the
// driver's own).
uint64_t gStorageBlockLimitForTest = 0;

void copyFloats(float* dst, const glm::dvec3& v) {
    for (int i = 0; i < 3; ++i) dst[i] = float(v[i]);
}

}  // namespace

GlRenderer::Impl::Impl(const Scene& s, std::unique_ptr<gl::HeadlessContext> context)
    : scene(&s), headless(std::move(context)), cpuCascades(s.outOfCore()) {
    gl::requireGl43("the GL backend");
    device = gl::currentDeviceName();
    software = isSoftwareRenderer(device);
    glGetInteger64v(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &maxStorageBlock);
    terrainAtlas.limit = waterAtlas.limit = gAtlasTileLimitForTest;
    if (maxStorageBlock <= 0) maxStorageBlock = GLint64{1} << 24;  // OpenGL 4.3's minimum
    if (gStorageBlockLimitForTest > 0) maxStorageBlock = std::min(maxStorageBlock, GLint64(gStorageBlockLimitForTest));
    glGenQueries(kStamps, stamps.data());
    try {
        approximate = gl::compileEmbedded("approximate");
        assemble = gl::compileEmbedded("assemble");
        atlas = gl::compileEmbedded("atlas");
        interpolate = gl::compileEmbedded("interpolate");
        beams = gl::compileEmbedded("beams");
        shore = gl::compileEmbedded("shore");
        mipmap = gl::compileEmbedded("mipmap");
        raycast = gl::compileEmbedded("raycast");
        shade = gl::compileEmbedded("shade");
        uploadScene();
    } catch (...) {
        release();  // a caller's context outlives this failed renderer: leave nothing in it
        throw;
    }
}

GlRenderer::Impl::~Impl() {
    if (headless) headless->makeCurrent();
    release();
}

void GlRenderer::Impl::release() {
    for (GLuint p : {approximate, assemble, atlas, interpolate, beams, shore, mipmap, raycast, shade})
        if (p) glDeleteProgram(p);
    approximate = assemble = atlas = interpolate = beams = shore = mipmap = raycast = shade = 0;
    for (Buffer* b :
         {&frameBuf, &cellsBuf, &keysBuf, &visibleBuf, &heightsBuf, &pixelsBuf, &countersBuf, &readbackBuf,
          &lastHeightsBuf, &fillRowsBuf, &fillTexelsBuf, &beamsBuf, &atlasTilesBuf, &atlasBlocksBuf, &overlayBuf})
        b->release();
    terrainAtlas.release(), waterAtlas.release();
    releasePictures();
    for (Buffer& b : indexBufs) b.release();
    if (colorTex) glDeleteTextures(1, &colorTex);
    colorTex = 0;
    if (stamps[0]) glDeleteQueries(kStamps, stamps.data());
    stamps = {};
}

void GlRenderer::Impl::checkBlock(size_t bytes, const char* what) const {
    if (maxStorageBlock > 0 && bytes > size_t(maxStorageBlock))
        throw Error(std::string("the GL backend needs ") + std::to_string(bytes >> 20) + " MiB for " + what +
                    " in one storage buffer; this driver allows " + std::to_string(maxStorageBlock >> 20) + " MiB" +
                    (std::strcmp(what, "the cascade textures") == 0 ? " (use fewer --texels or --cascades)" : ""));
}

// Cells (plus a sentinel), their sorted Morton keys and the influence lists: once per renderer. Out of core
// none: every binding gets a small buffer (the shaders that would read them are not run, and cellCount is 0).
void GlRenderer::Impl::uploadScene() {
    GLint bindings = 0;
    glGetIntegerv(GL_MAX_SHADER_STORAGE_BUFFER_BINDINGS, &bindings);
    if (bindings <= HC_BIND_LAST)
        throw Error("the GL backend needs " + std::to_string(HC_BIND_LAST + 1) + " shader storage buffer bindings; " +
                    device + " has " + std::to_string(bindings) + ": use --backend cpu");
    for (Buffer* b : {&lastHeightsBuf, &fillRowsBuf, &fillTexelsBuf, &beamsBuf, &atlasTilesBuf, &atlasBlocksBuf,
                      &terrainAtlas.buffer, &waterAtlas.buffer, &overlayBuf})
        b->reserve(16);
    frameBuf.reserve(sizeof(gpu::FrameBlock));
    countersBuf.reserve(sizeof(uint32_t) * gpu::kCounterUints);
    if (cpuCascades) {
        const gpu::GpuCell sentinel{};
        cellsBuf.reserve(sizeof sentinel);
        cellsBuf.upload(&sentinel, sizeof sentinel);
        keysBuf.reserve(16);
        for (Buffer& b : indexBufs) b.reserve(16);
        return;
    }
    const Grid& g = scene->grid();
    const auto& lists = scene->lists();
    const size_t count = g.cellCount();
    if (lists.entryCount() >= (uint64_t{1} << 32) || count >= (uint64_t{1} << 31))
        throw Error("the GL backend addresses influence lists with 32-bit indices: this grid has " +
                    std::to_string(lists.entryCount()) + " entries");
    std::vector<gpu::GpuCell> cells(count + 1);
    std::vector<uint32_t> keys(2 * count);
    const int water = scene->waterLayer();
    const auto offsets = lists.offsets();
    for (size_t k = 0; k < count; ++k) {
        gpu::GpuCell& c = cells[k];
        const uint64_t code = g.codes[k];
        c.ix = Grid::keyX(code);
        c.iy = Grid::keyY(code);
        c.level = uint32_t(codeLevel(code));
        c.listBegin = uint32_t(offsets[k]);
        c.a = scene->kernels()[k].a;
        c.r2 = scene->kernels()[k].r2;
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
    while (chunkEntries > 1 && (chunkEntries * 4 > uint64_t(maxStorageBlock) || chunkEntries > gIndexChunkLimitForTest))
        chunkEntries >>= 1;
    indexChunkShift = uint32_t(std::countr_zero(chunkEntries));
    const uint64_t chunks = (entries.size() + chunkEntries - 1) / chunkEntries;
    if (chunks > uint64_t(gpu::kIndexChunks))
        throw Error("the GL backend needs " + std::to_string(entries.size_bytes() >> 20) +
                    " MiB for the influence lists; this driver allows " + std::to_string(gpu::kIndexChunks) +
                    " storage buffers of " + std::to_string((chunkEntries * 4) >> 20) + " MiB");
    for (size_t c = 0; c < size_t(gpu::kIndexChunks); ++c) {
        const size_t begin = std::min<size_t>(c * chunkEntries, entries.size());
        const size_t n = std::min<size_t>(entries.size() - begin, chunkEntries);
        indexBufs[c].reserve(n * 4);  // empty chunks get a small buffer: every binding is valid
        if (n) indexBufs[c].upload(entries.data() + begin, n * 4);
    }
}

// The frame's constants (GpuFrame) for the shaders.
void GlRenderer::Impl::fillFrame(gpu::GpuFrame& f, const CascadeFit& fit, const Camera& camera,
                                 const RenderOptions& options) const {
    const Grid& g = scene->grid();
    f.eyeX = setup.eyeLocal.x, f.eyeY = setup.eyeLocal.y;
    f.finestM = g.finestCellM;
    f.domainM = g.domainSizeM();
    f.eyeZ = float(setup.eyeLocal.z);
    f.tanHalfX = float(setup.basis.tanHalfX), f.tanHalfY = float(setup.basis.tanHalfY);
    f.nearM = float(setup.nearM), f.farM = float(setup.farM);
    f.dirX = float(fit.dir.x), f.dirY = float(fit.dir.y);
    f.tail = float(scene->params().tail());
    copyFloats(f.forward, setup.basis.forward);
    copyFloats(f.right, setup.basis.right);
    copyFloats(f.up, setup.basis.up);
    const double sunAz = gpu::kSunAzimuthDeg * M_PI / 180, sunAlt = gpu::kSunAltitudeDeg * M_PI / 180;
    copyFloats(f.sun, {std::sin(sunAz) * std::cos(sunAlt), std::cos(sunAz) * std::cos(sunAlt), std::sin(sunAlt)});
    f.width = camera.width, f.height = camera.height;
    f.cascades = fit.hull.size() < 3 ? 0 : int(fit.cascades.size());  // no hull: every ray misses (as renderFrame)
    f.hasWater = scene->hasWater() ? 1 : 0;
    f.cellCount = cpuCascades ? 0u : uint32_t(g.cellCount());  // out of core no cell is on the GPU
    f.rootLevel = uint32_t(g.rootLevel);
    f.indexChunkShift = indexChunkShift;
    f.minDepthM = float(options.waterMinDepthM);
    f.fogDistM = float(gpu::kFogExtents * std::hypot(scene->xMax - scene->xMin, scene->yMax - scene->yMin));
    f.elevationMin = float(scene->elevationMin);
    f.zRange = float(std::max(scene->elevationMax - scene->elevationMin, 1e-6));
    f.dRange = float(std::max(scene->depthColorMaxM, 1e-6));
    f.pixelAngle = float(2.0 * setup.basis.tanHalfY / camera.height);
    f.colorMode = options.color == ColorMode::WaterDepth ? 1 : 0;
    f.cellOutlines = options.cellOutlines ? 1 : 0;
    const detail::LegendLayout legend = detail::legendLayout(*scene, options, camera.width, camera.height);
    if (legend.shown) {
        f.legendRamp = legend.layer ? 3 : legend.depth ? 1 : 2;
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
    for (int i = 0; i < 5; ++i)
        for (int c = 0; c < 4; ++c) f.layerRamp[4 * i + c] = float(gpu::kLayerRamp[i][c]);
    f.overlay = overlayBits(options);
    if (!options.colorLayer.empty()) {  // the ramp's range and what it colours, as renderFrame()'s shading
        const influence::Layer layer = influence::Layer::byName(scene->grid(), options.colorLayer);
        const auto [lo, hi] = detail::layerRange(scene->grid(), layer);
        f.layerLo = float(lo), f.layerRange = float(std::max(hi - lo, 1e-12));
        f.layerOnWater = layer.kind == influence::Layer::WaterCells ? 1 : 0;
    }
    for (int c = 0; c < 3; ++c) {
        f.skyHorizon[c] = float(gpu::kSkyHorizon[c]);
        f.skyZenith[c] = float(gpu::kSkyZenith[c]);
        f.dryColor[c] = float(gpu::kDryColor[c]);
        f.wallColor[c] = float(gpu::kWallColor[c]);
    }
    f.zFloor = float(scene->elevationMin);
    f.beamTile = options.beamTilePx > 1 ? options.beamTilePx : 0;  // beams.comp, raycast.comp
}

// Each cascade's places in the heights and visibility buffers (GpuCascade), and its statistics.
// Returns the floats the heights buffer needs; adds the visible row spans' ints to visibleWords.
size_t GlRenderer::Impl::layOutCascades(gpu::FrameBlock& block, const CascadeFit& fit, Timings& timings,
                                        size_t& visibleWords) const {
    const bool water = scene->hasWater();
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

// The bytes of the cascade textures and their mipmaps `fit` needs in the heights buffer (layOutCascades' count).
uint64_t GlRenderer::Impl::cascadeBytes(const CascadeFit& fit) const {
    gpu::FrameBlock block{};
    Timings scratch;
    size_t visibleWords = 0;
    return uint64_t(layOutCascades(block, fit, scratch, visibleWords)) * 4;
}

// The frame's constants, the cascades' places in the heights and visibility buffers and their row spans,
// into the buffers (grown as needed); the counters zeroed; the colour texture at the frame's size.
void GlRenderer::Impl::uploadFrame(gpu::FrameBlock& block, const CascadeFit& fit, const Camera& camera,
                                   const RenderOptions& options, Timings& timings) {
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

// Runs every stage of one frame; leaves the picture in colorTex and the rays in pixelsBuf.
CascadeFit GlRenderer::Impl::runFrame(const Camera& camera, const RenderOptions& options, Timings& timings) {
    camera.validate();
    if (std::string why = options.validate(); !why.empty()) throw Error(why);
    if (!options.colorLayer.empty()) {  // before any work: the layer exists, and the evaluator can be had
        influence::Layer::byName(scene->grid(), options.colorLayer);
        scene->evaluator();
    }
    if (headless) headless->makeCurrent();
    layerValues.clear(), layerName.clear();
    raysCopied = false;
    const Stopwatch frameClock;
    timings = Timings{};
    setup = detail::setUpFrame(*scene, camera);
    // In memory the shaders sum the kernels of every texel: textures of N^2, not the pyramid's ladder (up to 2N a
    // side, renderer.cpp). Out of core the CPU fills them as renderFrame() does, from the pyramid where there is one.
    if (!cpuCascades) setup.view.ladderStepsPerOctave = 8;
    CascadeFit fit = detail::fitFrame(*scene, camera, setup, options, timings);  // stage 1, on the CPU
    if (cpuCascades && !options.pyramidCoarseTexels && cascadeBytes(fit) > uint64_t(maxStorageBlock)) {
        // The pyramid's ladder (up to 2N texels a side) does not fit the driver's storage buffer: N texels a side at
        // the next coarser spacing (--pyramid-coarse), said in the frame's notes.
        const uint64_t need = cascadeBytes(fit);
        RenderOptions coarser = options;
        coarser.pyramidCoarseTexels = true;
        timings = Timings{};
        fit = detail::fitFrame(*scene, camera, setup, coarser, timings);
        timings.notes.push_back("the cascade textures at the pyramid's spacings need " + std::to_string(need >> 20) +
                                " MiB in one storage buffer and " + device + " allows " +
                                std::to_string(maxStorageBlock >> 20) +
                                " MiB: drawn with N texels a side at the next coarser spacing (as --pyramid-coarse)");
    }
    gpu::FrameBlock block{};
    // The last frame's textures stay for assemble.comp to read, if that frame built them; from here until this frame
    // has built its own (dispatchAssembly), a failure leaves nothing to keep.
    const bool keep = lastAssembled;
    std::swap(heightsBuf, lastHeightsBuf), lastAssembled = false;
    uploadFrame(block, fit, camera, options, timings);
    if (cpuCascades)
        approximateOnCpu(fit, block, options, timings, keep);
    else
        planOnGpu(fit, block, options, timings, keep);
    bindFrame();
    int stamp = 0;
    timeStamp(stamp++, frameClock);
    dispatchAssembly(fit);
    dispatchAtlas();
    dispatchApproximation(fit, frameClock, stamp);
    std::copy(std::begin(block.cascades), std::end(block.cascades),
              lastCascades.begin());  // where this frame's textures lie
    lastCascadeCount = fit.cascades.size();
    dispatchMipmaps(fit, block);
    timeStamp(stamp++, frameClock);
    if (beamSlots > 0) {  // the beams' marches, blocks then tiles, counted in the ray casting's time
        glUseProgram(beams);
        const GLint outer = glGetUniformLocation(beams, "uOuter");
        for (const int pass : {1, 0}) {  // an image of one tile has as many blocks as tiles: told apart by the pass
            glUniform1i(outer, pass);
            const size_t slots = pass ? outerBeamSlots : beamSlots;
            const size_t groups = (slots + 63) / 64,
                         across = std::min<size_t>(groups, 65535);  // GL's least limit a dimension
            glDispatchCompute(GLuint(across), GLuint((groups + across - 1) / across), 1);
            glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
        }
    }
    dispatchPerPixel(raycast, camera);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
    timeStamp(stamp++, frameClock);
    if (const int bits = overlayBits(options)) fillOverlay(camera, options, bits);  // counted in the shading's time
    dispatchPerPixel(shade, camera);
    timeStamp(stamp++, frameClock);
    // The picture is read as a texture (a viewer) or back (render()); the counters and rays back.
    glMemoryBarrier(GL_ALL_BARRIER_BITS);
    glUseProgram(0);
    readStageTimes(stamp, fit.cascades.size(), timings);
    readCounters(fit.cascades.size(), timings);
    timings.rays = size_t(camera.width) * size_t(camera.height);
    throwOnGlError();
    detail::boundFrame(*scene, setup, fit, timings);
    timings.totalMs = frameClock.milliseconds();
    return fit;
}

GLuint GlRenderer::Impl::program(const std::string& name) const {
    if (name == "approximate") return approximate;
    if (name == "mipmap") return mipmap;
    if (name == "raycast") return raycast;
    if (name == "shade") return shade;
    throw Error("no GL program " + name);
}

Frame GlRenderer::Impl::readBack(const Camera& camera, Timings& timings, ReadBack what) {
    const Stopwatch clock;
    const int W = camera.width, H = camera.height;
    const size_t pixels = size_t(W) * size_t(H);
    Frame f;
    f.width = W;
    f.height = H;
    f.originWorldX = scene->grid().originWorldX;
    f.originWorldY = scene->grid().originWorldY;
    glBindTexture(GL_TEXTURE_2D, colorTex);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    // The texture's own format, RGBA: the copy a driver makes without converting on the CPU (asking for RGB made it
    // convert every pixel itself, on one core); the frame's RGB taken from it below, its rows flipped (the texture's
    // row 0 is the bottom, the frame's the top), on every core.
    std::vector<uint8_t> rgba(pixels * 4);
    glGetTexImage(GL_TEXTURE_2D, 0, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
    if (what == ReadBack::PictureOnly) {
        gl::rgbFromTexture(rgba.data(), W, H, f.rgb);
        timings.readbackMs = clock.milliseconds();
        timings.totalMs += timings.readbackMs;
        return f;
    }
    // The rays are copied on the GPU into a buffer of their own (readbackBuf), read through a mapping of it (no
    // staging copy in host memory) and spread over the frame's layers on all cores.
    for (auto* v : {&f.distanceM, &f.posX, &f.posY, &f.posZ, &f.nX, &f.nY, &f.nZ, &f.waterDepthM, &f.cascade, &f.wall})
        v->resize(pixels);
    f.rgb.resize(pixels * 3);
    const gpu::GpuPixel* px = mapRays(pixels);
    const float inf = std::numeric_limits<float>::infinity();
    parallelFor(size_t(H), 16, 0, [&](size_t rowBegin, size_t rowEnd, unsigned) {
        for (size_t row = rowBegin; row < rowEnd; ++row)
            for (size_t col = 0; col < size_t(W); ++col) {
                const size_t i = row * size_t(W) + col;
                const gpu::GpuPixel p = px[i];
                const uint8_t* src =
                    &rgba[((size_t(H) - 1 - row) * size_t(W) + col) * 4];  // the texture's row 0 is the bottom
                std::memcpy(&f.rgb[i * 3], src, 3);
                if (!(p.t < inf)) {
                    f.distanceM[i] = inf;
                    f.posX[i] = f.posY[i] = f.posZ[i] = f.nX[i] = f.nY[i] = f.nZ[i] = f.waterDepthM[i] = f.wall[i] =
                        0.0f;
                    f.cascade[i] = -1.0f;
                    continue;
                }
                f.distanceM[i] = p.t;
                // Camera-relative offsets back to the local frame in double.
                const glm::vec3 at = hitLocal(p);
                f.posX[i] = at.x, f.posY[i] = at.y, f.posZ[i] = at.z;
                f.nX[i] = p.nx, f.nY[i] = p.ny, f.nZ[i] = p.nz;
                f.cascade[i] = float(p.cascade);
                f.waterDepthM[i] = p.depth;
                f.wall[i] = p.wall ? 1.0f : 0.0f;
            }
    });
    glUnmapBuffer(GL_SHADER_STORAGE_BUFFER);
    if (!layerName.empty())  // as renderFrame() gives them; the frame's own, read back once
        f.colorLayer = std::move(layerName), f.colorLayerValue = std::move(layerValues);
    detail::frameToWorldAxes(scene->grid(), f);
    timings.readbackMs = clock.milliseconds();
    timings.totalMs += timings.readbackMs;
    return f;
}

GlRenderer::GlRenderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
GlRenderer::~GlRenderer() = default;

std::unique_ptr<GlRenderer> GlRenderer::inCurrentContext(const Scene& scene) {
    return std::unique_ptr<GlRenderer>(new GlRenderer(std::make_unique<Impl>(scene, nullptr)));
}

std::unique_ptr<GlRenderer> GlRenderer::headless(const Scene& scene) {
    auto context = gl::HeadlessContext::create();
    return std::unique_ptr<GlRenderer>(new GlRenderer(std::make_unique<Impl>(scene, std::move(context))));
}

Frame GlRenderer::render(const Camera& camera, const RenderOptions& options, Timings& timings, ReadBack what) {
    impl_->runFrame(camera, options, timings);
    return impl_->readBack(camera, timings, what);
}

void GlRenderer::setScene(const Scene& scene) {
    if (scene.outOfCore() != impl_->cpuCascades)
        throw Error(std::string("the GL renderer was made for a scene ") +
                    (impl_->cpuCascades ? "read out of core" : "in memory") + " and cannot take one " +
                    (scene.outOfCore() ? "read out of core" : "in memory"));
    if (impl_->headless) impl_->headless->makeCurrent();
    impl_->scene = &scene;
    impl_->cascadeCache.clear(), impl_->lastAssembled = false;
    impl_->terrainAtlas.release(), impl_->waterAtlas.release();  // tiles are known by their addresses in the old one
    impl_->uploadScene();
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
            if (texels)
                glGetBufferSubData(GL_SHADER_STORAGE_BUFFER, GLintptr(offset) * 4, GLsizeiptr(texels * 4), to.data());
        };
        read(out[k].terrain, c.terrainOffset);
        if (impl_->scene->hasWater()) read(out[k].water, c.waterOffset), read(out[k].depth, c.depthOffset);
    }
    return out;
}

void GlRenderer::forgetCascades() { impl_->cascadeCache.clear(); }

void GlRenderer::limitIndexChunksForTest(uint64_t entries) {
    gIndexChunkLimitForTest = entries ? entries : uint64_t{1} << 31;
}
void GlRenderer::limitAtlasForTest(uint32_t tiles) { gAtlasTileLimitForTest = tiles; }
void GlRenderer::limitStorageBlockForTest(uint64_t bytes) { gStorageBlockLimitForTest = bytes; }

void GlRenderer::compileForTest(const std::string& name, const std::string& source) const {
    if (impl_->headless) impl_->headless->makeCurrent();
    glDeleteProgram(gl::compileCompute(name, source));
}

GlRenderer::VariableLayout GlRenderer::bufferVariableLayout(const std::string& program,
                                                            const std::string& variable) const {
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
