// render/gl/src/backend_pictures.cpp: the GL backend's pictures in flight (GlRenderer::submitPicture), for batch
// output. A frame's picture is copied from the colour texture into a pixel buffer of a ring (GL_PIXEL_PACK_BUFFER: the
// driver copies on the GPU's side, asynchronously), a fence after the copy; it is mapped and converted only when
// collected, by then usually copied. With a synchronous read (render()) the CPU waits for the copy of each frame before
// it can fit the next.
#include <cstring>

#include "backend_internal.h"
#include "heightcast/core/error.h"
#include "heightcast/core/parallel.h"

namespace hc::render {

namespace gl {

void rgbFromTexture(const uint8_t* rgba, int W, int H, std::vector<uint8_t>& rgb) {
    rgb.resize(size_t(W) * size_t(H) * 3);
    parallelFor(size_t(H), 16, 0, [&](size_t rowBegin, size_t rowEnd, unsigned) {
        for (size_t row = rowBegin; row < rowEnd; ++row) {
            const uint8_t* src = &rgba[(size_t(H) - 1 - row) * size_t(W) * 4];
            uint8_t* dst = &rgb[row * size_t(W) * 3];
            for (size_t col = 0; col < size_t(W); ++col)
                dst[3 * col] = src[4 * col], dst[3 * col + 1] = src[4 * col + 1], dst[3 * col + 2] = src[4 * col + 2];
        }
    });
}

}  // namespace gl

// The ring has a free slot (submitPicture checked before the frame's work).
void GlRenderer::Impl::startPictureCopy(const Camera& camera, const Timings& timings) {
    PictureSlot& s = pictures[(picturesFirst + picturesCount) % pictures.size()];
    const size_t bytes = size_t(camera.width) * size_t(camera.height) * 4;
    if (!s.buffer) glGenBuffers(1, &s.buffer);
    glBindBuffer(GL_PIXEL_PACK_BUFFER, s.buffer);
    if (s.bytes < bytes)
        glBufferData(GL_PIXEL_PACK_BUFFER, GLsizeiptr(bytes), nullptr, GL_STREAM_READ), s.bytes = bytes;
    glBindTexture(GL_TEXTURE_2D, colorTex);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glGetTexImage(GL_TEXTURE_2D, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);  // into the bound buffer, at offset 0
    glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);  // a later glGetTexImage (render()) reads into host memory again
    s.fence = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
    glFlush();  // the copy and the fence go to the GPU now, not at the next frame's first wait
    throwOnGlError();
    s.frame = Frame{};
    s.frame.width = camera.width, s.frame.height = camera.height;
    s.frame.originWorldX = scene->grid().originWorldX, s.frame.originWorldY = scene->grid().originWorldY;
    s.timings = timings;
    ++picturesCount;
}

GlRenderer::Picture GlRenderer::Impl::finishPictureCopy() {
    if (picturesCount == 0) throw Error("no picture is in flight: submit one first");
    const Stopwatch clock;
    PictureSlot& s = pictures[picturesFirst];
    picturesFirst = (picturesFirst + 1) % pictures.size(), --picturesCount;  // taken out of the ring, whatever follows
    Picture out{std::move(s.frame), std::move(s.timings)};
    const GLsync fence = s.fence;
    s.fence = nullptr;
    GLenum waited = GL_TIMEOUT_EXPIRED;
    while (waited == GL_TIMEOUT_EXPIRED) waited = glClientWaitSync(fence, 0, GLuint64{1000000000});  // 1 s a try
    glDeleteSync(fence);
    if (waited == GL_WAIT_FAILED) throw Error("the GL backend lost a picture's copy on " + device);
    const int W = out.frame.width, H = out.frame.height;
    glBindBuffer(GL_PIXEL_PACK_BUFFER, s.buffer);
    const auto* rgba = static_cast<const uint8_t*>(
        glMapBufferRange(GL_PIXEL_PACK_BUFFER, 0, GLsizeiptr(size_t(W) * size_t(H) * 4), GL_MAP_READ_BIT));
    if (!rgba) {
        glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
        throw Error("the GL backend cannot map a picture for reading on " + device);
    }
    gl::rgbFromTexture(rgba, W, H, out.frame.rgb);
    glUnmapBuffer(GL_PIXEL_PACK_BUFFER);
    glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
    throwOnGlError();
    out.timings.readbackMs = clock.milliseconds();
    out.timings.totalMs += out.timings.readbackMs;
    return out;
}

void GlRenderer::Impl::releasePictures() {
    for (PictureSlot& s : pictures) {
        if (s.fence) glDeleteSync(s.fence);
        if (s.buffer) glDeleteBuffers(1, &s.buffer);
        s = PictureSlot{};
    }
    picturesFirst = picturesCount = 0;
}

void GlRenderer::submitPicture(const Camera& camera, const RenderOptions& options) {
    if (impl_->picturesCount == impl_->pictures.size())  // before the frame's work
        throw Error(std::to_string(impl_->pictures.size()) + " pictures are in flight already: collect one first");
    Timings timings;
    impl_->runFrame(camera, options, timings);
    impl_->startPictureCopy(camera, timings);
}

size_t GlRenderer::picturesInFlight() const { return impl_->picturesCount; }

GlRenderer::Picture GlRenderer::collectPicture() {
    if (impl_->headless) impl_->headless->makeCurrent();
    return impl_->finishPictureCopy();
}

}  // namespace hc::render
