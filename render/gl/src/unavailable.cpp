// The GL backend's API in a build without OpenGL (-DHC_WITH_GL=OFF): every way to get a renderer says the
// backend was built out, so `--backend gl` fails with that reason and `auto` renders on the CPU. Links no GL.
#include "heightcast/core/error.h"
#include "heightcast/render/gl/gl_renderer.h"
#include "heightcast/render/gl/headless_context.h"

namespace hc::render {
namespace {
const char* const kBuiltOut =
    "this heightcast was built without the OpenGL backend (-DHC_WITH_GL=OFF; rebuild with "
    "-DHC_WITH_GL=ON, Debian packages libegl-dev libgl-dev glslang-tools libglfw3-dev)";
}

std::string headlessGlUnavailable(std::string*) { return kBuiltOut; }
struct GlRenderer::Impl {};
GlRenderer::GlRenderer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
GlRenderer::~GlRenderer() = default;
std::unique_ptr<GlRenderer> GlRenderer::inCurrentContext(const Scene&) { throw Error(kBuiltOut); }
std::unique_ptr<GlRenderer> GlRenderer::headless(const Scene&) { throw Error(kBuiltOut); }
// No renderer can exist, so the members below are never reached.
Frame GlRenderer::render(const Camera&, const RenderOptions&, Timings&, ReadBack) { throw Error(kBuiltOut); }
void GlRenderer::setScene(const Scene&) { throw Error(kBuiltOut); }
void GlRenderer::submitPicture(const Camera&, const RenderOptions&) { throw Error(kBuiltOut); }
size_t GlRenderer::picturesInFlight() const { return 0; }
GlRenderer::Picture GlRenderer::collectPicture() { throw Error(kBuiltOut); }
unsigned GlRenderer::renderToTexture(const Camera&, const RenderOptions&, Timings&) { throw Error(kBuiltOut); }
std::string GlRenderer::deviceName() const { return ""; }
void GlRenderer::forgetCascades() {}
void GlRenderer::limitIndexChunksForTest(uint64_t) {}
void GlRenderer::limitAtlasForTest(uint32_t) {}
void GlRenderer::limitStorageBlockForTest(uint64_t) {}
void GlRenderer::compileForTest(const std::string&, const std::string&) const { throw Error(kBuiltOut); }
GlRenderer::VariableLayout GlRenderer::bufferVariableLayout(const std::string&, const std::string&) const { return {}; }
long GlRenderer::bufferBlockSize(const std::string&, const std::string&) const { return -1; }
std::vector<GlRenderer::CascadeTexels> GlRenderer::cascadeTexturesForTest() const { return {}; }

// No context can exist either.
std::unique_ptr<gl::HeadlessContext> gl::HeadlessContext::create() { throw Error(kBuiltOut); }
gl::HeadlessContext::~HeadlessContext() = default;
void gl::HeadlessContext::makeCurrent() const {}

}  // namespace hc::render
