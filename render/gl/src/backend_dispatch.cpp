// render/gl/src/backend_dispatch.cpp: the GL backend's compute dispatches (backend.cpp's first comment): the buffers
// at their bindings, stage 2 (assemble.comp, atlas.comp and interpolate.comp, approximate.comp), stage 3 (shore.comp,
// mipmap.comp) and stages 4 and 5 (raycast.comp, shade.comp) as runFrame() orders them, with the time stamps between
// them, the stage times and the shaders' counters read back, and GL's errors.
#include <algorithm>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <tuple>
#include <vector>

#include "backend_internal.h"
#include "heightcast/core/error.h"
#include "heightcast/core/timer.h"
#include "heightcast/influence/surface.h"

namespace hc::render {

// Marks the end of the work submitted so far: a GPU timer query, or on software OpenGL the frame's clock
// after glFinish.
void GlRenderer::Impl::timeStamp(int i, const Stopwatch& frameClock) {
    if (!software) {
        glQueryCounter(stamps[size_t(i)], GL_TIMESTAMP);
        return;
    }
    glFinish();
    cpuStamps[size_t(i)] = frameClock.milliseconds();
}

// Every buffer and the colour image at the binding points the shaders declare (gpu_layout.h).
void GlRenderer::Impl::bindFrame() const {
    frameBuf.bind(HC_BIND_FRAME);
    cellsBuf.bind(HC_BIND_CELLS);
    keysBuf.bind(HC_BIND_KEYS);
    const GLuint indexBindings[gpu::kIndexChunks] = {HC_BIND_INDICES, HC_BIND_INDICES_1, HC_BIND_INDICES_2,
                                                     HC_BIND_INDICES_3};
    for (size_t c = 0; c < size_t(gpu::kIndexChunks); ++c) indexBufs[c].bind(indexBindings[c]);
    visibleBuf.bind(HC_BIND_VISIBLE);
    heightsBuf.bind(HC_BIND_HEIGHTS);
    pixelsBuf.bind(HC_BIND_PIXELS);
    beamsBuf.bind(HC_BIND_BEAMS);
    countersBuf.bind(HC_BIND_COUNTERS);
    overlayBuf.bind(HC_BIND_OVERLAY);
    glBindImageTexture(HC_IMAGE_COLOR, colorTex, 0, GL_FALSE, 0, GL_WRITE_ONLY, GL_RGBA8);
}

// Out of core with a pyramid: the texels copied from its tiles on the GPU and those interpolated from level 0's, after
// the assembly (a work group a tile, a block); they write disjoint texels.
void GlRenderer::Impl::dispatchAtlas() {
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
        const size_t across = std::min<size_t>(count, 65535);  // GL's least limit a dimension
        glDispatchCompute(GLuint(across), GLuint((count + across - 1) / across), 1);
    }
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
}

// Stage 2 on the GPU: each cascade's textures written whole by assemble.comp, the texels kept from the last frame's
// and (out of core) the packed ones placed, "no surface" elsewhere; in memory approximate.comp then sums the spans.
// Then they are this frame's: the next may keep them.
void GlRenderer::Impl::dispatchAssembly(const CascadeFit& fit) {
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
            throw Error("the GL backend's cascades kept on the GPU do not match the CPU's (cascade " +
                        std::to_string(k) + "): a bug");
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
        const GLuint texelsPerGroup =
            kAssembleRun * kAssembleGroup;  // assemble.comp: kRun texels an invocation, 64 apart
        glDispatchCompute((GLuint(fit.cascades[k].n) + texelsPerGroup - 1) / texelsPerGroup, GLuint(fit.cascades[k].n),
                          1);
    }
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    lastAssembled = true;
}

// Stage 2: the approximation, one dispatch per cascade, each followed by a time stamp (out of core the stamps
// only). The assembly before it counts in cascade 0's approximation time in memory, and in the frame's GPU span
// only out of core (where the CPU's times stand for the approximation).
void GlRenderer::Impl::dispatchApproximation(const CascadeFit& fit, const Stopwatch& frameClock, int& stamp) {
    glUseProgram(approximate);
    for (size_t k = 0; k < fit.cascades.size(); ++k) {
        for (int span = 0; span < 2 && !fit.cascades[k].empty() && !cpuCascades;
             ++span) {                                    // x: along the span, y: rows
            if (assembly[k].widest[span] <= 0) continue;  // no row has such a span (a fresh frame's second ones)
            glUniform1i(glGetUniformLocation(approximate, "uCascade"), int(k));
            glUniform1i(glGetUniformLocation(approximate, "uSpan"), span);
            const bool relative = assembly[k].widest[span] * 4 <= fit.cascades[k].n;  // narrow spans (approximate.comp)
            glUniform1i(glGetUniformLocation(approximate, "uRelative"), relative ? 1 : 0);
            glDispatchCompute(groups(relative ? assembly[k].widest[span] : fit.cascades[k].n),
                              groups(fit.cascades[k].n), 1);
        }
        timeStamp(stamp++, frameClock);
    }
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
}

// Stage 3: the water at the shores (shore.comp, one dispatch per cascade), then the max mipmaps, one dispatch per
// level of each cascade's terrain (and water).
void GlRenderer::Impl::dispatchMipmaps(const CascadeFit& fit, const gpu::FrameBlock& block) {
    if (scene->hasWater()) {
        glUseProgram(shore);
        const GLint uCascade = glGetUniformLocation(shore, "uCascade");
        for (size_t k = 0; k < fit.cascades.size(); ++k) {
            if (fit.cascades[k].empty()) continue;
            glUniform1i(uCascade, int(k));
            glDispatchCompute(groups(fit.cascades[k].n), groups(fit.cascades[k].n), 1);
        }
        glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    }
    glUseProgram(mipmap);
    const GLint uCascade = glGetUniformLocation(mipmap, "uCascade"), uWater = glGetUniformLocation(mipmap, "uWater"),
                uLevel = glGetUniformLocation(mipmap, "uLevel");
    glUniform1i(glGetUniformLocation(mipmap, "uEstimate"), estimatesError() ? 1 : 0);
    for (size_t k = 0; k < fit.cascades.size(); ++k) {
        if (fit.cascades[k].empty()) continue;
        glUniform1i(uCascade, int(k));
        for (int w = 0; w < (scene->hasWater() ? 2 : 1); ++w) {
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
void GlRenderer::Impl::dispatchPerPixel(GLuint program, const Camera& camera) const {
    glUseProgram(program);
    glDispatchCompute(groups(camera.width), groups(camera.height), 1);
}

// The stage times from the time stamps (waiting for the GPU): stamp 0 before the approximation, one after each
// cascade's, then after the mipmaps, the ray casting and the shading.
void GlRenderer::Impl::readStageTimes(int stampCount, size_t cascadeCount, Timings& timings) {
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
void GlRenderer::Impl::readCounters(size_t cascadeCount, Timings& timings) const {
    std::vector<uint32_t> counters(countersBuf.bytes / 4);
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, countersBuf.name);
    glGetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, GLsizeiptr(countersBuf.bytes), counters.data());
    for (size_t k = 0; k < cascadeCount; ++k)
        for (int s = 0; s < gpu::kCounterSlots; ++s)
            timings.cascades[k].gaussians += counters[k * gpu::kCounterSlots + size_t(s)];
    for (int s = 0; s < gpu::kCounterSlots; ++s)
        timings.hits += counters[size_t(gpu::kMaxCascades * gpu::kCounterSlots + s)];
    for (size_t k = 0; k < cascadeCount; ++k) {  // shade.comp's nearest hits
        uint32_t most = 0;
        for (int s = 0; s < gpu::kCounterSlots; ++s)
            most = std::max(most, counters[size_t(gpu::kNearestHitCounter) + k * gpu::kCounterSlots + size_t(s)]);
        float nearest = std::numeric_limits<float>::infinity();
        if (most > 0) {
            const uint32_t bits = gpu::kNearestHitBits - most;
            std::memcpy(&nearest, &bits, sizeof nearest);
        }
        timings.cascades[k].nearestHitM = nearest;
    }
    if (estimatesError())
        for (size_t k = 0; k < cascadeCount; ++k) {
            float estimate;
            std::memcpy(&estimate, &counters[size_t(gpu::kEstimateCounter) + k], sizeof estimate);
            timings.cascades[k].texelEstimateM = estimate;
        }
}

void GlRenderer::Impl::throwOnGlError() const {
    if (const GLenum e = glGetError(); e != GL_NO_ERROR) {
        char b[64];
        std::snprintf(b, sizeof b, "OpenGL error 0x%04x", unsigned(e));
        throw Error(std::string("the GL backend failed: ") + b + " on " + device);
    }
}

}  // namespace hc::render
