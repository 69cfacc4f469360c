// render/gl/src/backend_cpu_fill.cpp: the GL backend's stage 2 from the CPU (backend.cpp's first comment): in memory
// its plan (the rows of the texels kept and of the spans approximate.comp sums), out of core the texels the CPU
// evaluates, each cascade's rows with them packed into fillRowsBuf and fillTexelsBuf for assemble.comp.
#include <algorithm>
#include <array>
#include <cstring>
#include <vector>

#include "backend_internal.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"
#include "heightcast/core/timer.h"

namespace hc::render {

// Stage 2 out of core, on the CPU (backend.cpp's first comment): the texels this frame newly sees, evaluated there and
// packed with each cascade's rows into fillTexelsBuf and fillRowsBuf for assemble.comp; their statistics and times
// replace the ones layOutCascades and the time stamps give.
// Cascade k's rows into fillRows for assemble.comp (RowFill, then where its spans' texels start in the packed planes,
// counting from `packed`) and its Assembly; returns where the packed texels end.
size_t GlRenderer::Impl::addRows(size_t k, const detail::CascadeFill& fill, size_t packed) {
    Assembly& a = assembly[k];
    a.rowBase = int(fillRows.size() / size_t(gpu::kFillRowInts));
    a.from = fill.from, a.di = fill.di, a.dj = fill.dj;
    for (const detail::RowFill& r : fill.rows) {
        const int32_t atA = int32_t(packed);
        packed += size_t(r.a.count());
        const int32_t atB = int32_t(packed);
        packed += size_t(r.b.count());
        fillRows.insert(fillRows.end(),
                        {r.kept.first, r.kept.last, r.a.first, r.a.last, r.b.first, r.b.last, atA, atB});
        a.widest[0] = std::max(a.widest[0], r.a.last - r.a.first + 1),
        a.widest[1] = std::max(a.widest[1], r.b.last - r.b.first + 1);
    }
    return packed;
}

// fillRows into fillRowsBuf; returns the bytes.
size_t GlRenderer::Impl::uploadRows() {
    const size_t bytes = fillRows.size() * sizeof(int32_t);
    checkBlock(bytes, "the cascades' rows");
    fillRowsBuf.reserve(bytes);
    if (bytes) fillRowsBuf.upload(fillRows.data(), bytes);
    return bytes;
}

// `keep`: the last frame's textures are in lastHeightsBuf (else the cache starts afresh: the GPU does not hold the
// frame it describes).
void GlRenderer::Impl::approximateOnCpu(const CascadeFit& fit, const gpu::FrameBlock& block,
                                        const RenderOptions& options, Timings& timings, bool keep) {
    if (!keep) cascadeCache.clear();
    const bool water = scene->hasWater();
    std::array<std::vector<float>, 3>& packed = fillTexels;
    fillRows.clear();
    for (std::vector<float>& p : packed) p.clear();
    assembly = {};
    Timings cpu;
    double packMs = 0;
    // With a pyramid the texels it holds are copied on the GPU, from its tiles resident there (the atlas); only the
    // tiles not yet there go up, with the tiles to copy from (16 bytes a tile) and each row's spans.
    const bool useAtlas = scene->pyramid() != nullptr;
    atlasTiles.clear(), atlasBlocks.clear(), atlasTexels = 0, atlasInterpolated = 0;
    std::vector<int32_t> spans;
    size_t spanBytes = 0;
    if (useAtlas) terrainAtlas.beginFrame(), waterAtlas.beginFrame();
    const float minDepth = float(options.waterMinDepthM);
    detail::approximateOnCpu(
        *scene, fit, options, cascadeCache, cpu,
        [&](size_t k, detail::CascadeTextures& tex, detail::CascadeFill& fill) {
            const Stopwatch clock;
            if (useAtlas) {  // cpu.cascades: one per cascade of the fit (approximateCascades)
                CascadeStats& stats = cpu.cascades[k];
                // The spans before the copies were taken out, of the rows of the tiles atlas.comp copies from and the
                // blocks interpolate.comp fills (the visible buffer is in-memory's otherwise): a moving frame's few
                // tiles need few rows.
                int lo = fit.cascades[k].n, hi = -1;
                stats.pyramidTexels += placeTiles(k, tex, fill, minDepth, lo, hi);
                placeBlocks(k, fit.cascades[k], tex, fill, options.waterMinDepthM, lo, hi);
                spans.clear();
                for (int j = lo; j <= hi; ++j) {
                    const detail::RowFill& r = fill.tiles.spans[size_t(j)];
                    spans.insert(spans.end(), {r.a.first, r.a.last, r.b.first, r.b.last});
                }
                if (!spans.empty())
                    visibleBuf.upload(spans.data(), spans.size() * sizeof(int32_t),
                                      (size_t(block.cascades[k].visibleOffset) + 4 * size_t(lo)) * 4);
                spanBytes += spans.size() * sizeof(int32_t);
            }
            // Each row's place in the packed planes, then the rows copied there on all cores.
            const size_t n = size_t(fit.cascades[k].n), first = packed[0].size(), end = addRows(k, fill, first);
            const size_t channels = water ? 3 : 1;
            for (size_t c = 0; c < channels; ++c) packed[c].resize(end);
            const int32_t* rowInts = &fillRows[size_t(assembly[k].rowBase) * size_t(gpu::kFillRowInts)];
            // On all cores where there is much to copy (a fresh cascade: up to 3 x 16 MB); a moving frame's few texels
            // on this one.
            const unsigned threads = end - first >= (size_t{1} << 16) ? options.threads : 1;
            parallelFor(fill.rows.size(), 64, threads, [&](size_t b, size_t e, unsigned) {
                for (size_t j = b; j < e; ++j) {
                    const detail::RowFill& r = fill.rows[j];
                    for (int span = 0; span < 2; ++span) {
                        const int lo = r.span(span).first, hi = r.span(span).last;
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
        },
        useAtlas);
    const Stopwatch clock;
    const size_t plane = packed[0].size(), planeBytes = plane * sizeof(float), channels = water ? 3 : 1;
    if (plane >= (size_t{1} << 31))
        throw Error("the GL backend out of core evaluated more than 2^31 texels in one frame");
    fillPlane = uint32_t(plane);
    checkBlock(planeBytes * channels, "the texels the CPU evaluated");
    const size_t rowBytes = uploadRows();
    fillTexelsBuf.reserve(planeBytes * channels);
    for (size_t c = 0; c < channels && plane; ++c) fillTexelsBuf.upload(packed[c].data(), planeBytes, c * planeBytes);
    size_t atlasBytes = 0;
    if (useAtlas) {
        checkBlock(atlasTiles.size() * sizeof(uint32_t), "the pyramid tiles to copy texels from");
        atlasBytes =
            terrainAtlas.uploadedBytes + waterAtlas.uploadedBytes + atlasTiles.size() * sizeof(uint32_t) + spanBytes;
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

// Stage 2 in memory, its plan on the CPU: each cascade's rows (the texels kept from the last frame, the spans to sum)
// into fillRowsBuf for assemble.comp, and the spans into visibleBuf for approximate.comp, which sums only those.
void GlRenderer::Impl::planOnGpu(const CascadeFit& fit, const gpu::FrameBlock& block, const RenderOptions& options,
                                 Timings& timings, bool keep) {
    if (!keep) cascadeCache.clear();
    const Stopwatch clock;
    const std::vector<detail::CascadeFill> fills = detail::planCascades(*scene, fit, options, cascadeCache, timings);
    fillRows.clear();
    assembly = {};
    std::vector<int32_t> spans;
    size_t spanBytes = 0;
    for (size_t k = 0; k < fit.cascades.size(); ++k) {
        if (fit.cascades[k].empty()) continue;
        addRows(k, fills[k], 0);  // nothing packed: approximate.comp sums the spans (assemble.comp's uPacked 0)
        spans.clear();
        for (const detail::RowFill& r : fills[k].rows)
            spans.insert(spans.end(), {r.a.first, r.a.last, r.b.first, r.b.last});
        visibleBuf.upload(spans.data(), spans.size() * sizeof(int32_t), size_t(block.cascades[k].visibleOffset) * 4);
        spanBytes += spans.size() * sizeof(int32_t);
    }
    const size_t rowBytes = uploadRows();
    fillPlane = 0;
    timings.uploadMs = clock.milliseconds();
    timings.uploadBytes = rowBytes + spanBytes;
}

}  // namespace hc::render
