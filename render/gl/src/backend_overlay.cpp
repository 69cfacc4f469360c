// render/gl/src/backend_overlay.cpp: what the CPU computes from a GL frame's hits before shade.comp draws them
// (GpuFrame::overlay, HC_BIND_OVERLAY): a --color-by layer's exact values at the hits (one batch through the exact
// evaluator, as renderFrame() colours them) and, out of core where the cells are not on the GPU, the cell outlines'
// factors. The rays are read back after the ray casting, these computed by shading.cpp's own functions (one rule for
// both backends), and uploaded; shade.comp then colours each pixel by the CPU's priorities.
#include <cmath>
#include <limits>
#include <vector>

#include "backend_internal.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"

namespace hc::render {

int GlRenderer::Impl::overlayBits(const RenderOptions& options) const {
    return (options.colorLayer.empty() ? 0 : 1) | (cpuCascades && options.cellOutlines ? 2 : 0);
}

const gpu::GpuPixel* GlRenderer::Impl::mapRays(size_t pixels) {
    const size_t rayBytes = pixels * sizeof(gpu::GpuPixel);
    if (!raysCopied) {  // shading reads the rays, never writes them: a frame copies them once
        readbackBuf.reserve(rayBytes);
        glBindBuffer(GL_COPY_READ_BUFFER, pixelsBuf.name);
        glBindBuffer(GL_COPY_WRITE_BUFFER, readbackBuf.name);
        glCopyBufferSubData(GL_COPY_READ_BUFFER, GL_COPY_WRITE_BUFFER, 0, 0, GLsizeiptr(rayBytes));
        raysCopied = true;
    }
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, readbackBuf.name);
    const auto* px = static_cast<const gpu::GpuPixel*>(
        glMapBufferRange(GL_SHADER_STORAGE_BUFFER, 0, GLsizeiptr(rayBytes), GL_MAP_READ_BIT));
    if (!px) throw Error("the GL backend cannot map its rays for reading on " + device);
    return px;
}

void GlRenderer::Impl::fillOverlay(const Camera& camera, const RenderOptions& options, int bits) {
    const size_t W = size_t(camera.width), pixels = W * size_t(camera.height);
    // The hits as renderFrame()'s shading sees them: local positions in float, a wall flag, a water flag.
    Frame hits;
    hits.width = camera.width, hits.height = camera.height;
    for (auto* v : {&hits.distanceM, &hits.posX, &hits.posY, &hits.wall}) v->resize(pixels);
    std::vector<uint8_t> isWater(pixels);
    const gpu::GpuPixel* px = mapRays(pixels);
    const float inf = std::numeric_limits<float>::infinity();
    parallelFor(size_t(camera.height), 16, options.threads, [&](size_t rowBegin, size_t rowEnd, unsigned) {
        for (size_t i = rowBegin * W; i < rowEnd * W; ++i) {
            const gpu::GpuPixel& p = px[i];
            const bool hit = p.t < inf;
            hits.distanceM[i] = hit ? p.t : inf;
            const glm::vec3 at = hitLocal(p);
            hits.posX[i] = hit ? at.x : 0.0f, hits.posY[i] = hit ? at.y : 0.0f;
            hits.wall[i] = hit && p.wall ? 1.0f : 0.0f;
            isWater[i] = hit && p.water ? 1 : 0;
        }
    });
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, readbackBuf.name);
    glUnmapBuffer(GL_SHADER_STORAGE_BUFFER);
    std::vector<gpu::GpuOverlay> overlay(pixels, gpu::GpuOverlay{0.0f, 1.0f, 0});
    if (bits & 1) {
        const influence::Layer layer = influence::Layer::byName(scene->grid(), options.colorLayer);
        layerValues = detail::colorLayerValues(*scene, layer, options, hits, isWater);
        layerName = options.colorLayer;
        for (size_t i = 0; i < pixels; ++i)
            if (!std::isnan(layerValues[i])) overlay[i].layer = layerValues[i], overlay[i].valued = 1;
    }
    if (bits & 2) {
        const double pixelAngle = 2.0 * setup.basis.tanHalfY / camera.height;  // as renderFrame()'s shading
        parallelFor(pixels, 4096, options.threads, [&](size_t b, size_t e, unsigned) {
            for (size_t i = b; i < e; ++i) overlay[i].dim = float(detail::cellOutlineDim(*scene, hits, i, pixelAngle));
        });
    }
    overlayBuf.reserve(pixels * sizeof(gpu::GpuOverlay));
    overlayBuf.upload(overlay.data(), pixels * sizeof(gpu::GpuOverlay));
    overlayBuf.bind(HC_BIND_OVERLAY);
}

}  // namespace hc::render
