// isSoftwareRenderer: a GL_RENDERER string read as text, the same with and without the GL backend built
// (hc-render and hc-view decide on it through support/backend_choice.cpp), so one definition serves both builds.
#include "heightcast/render/gl/gl_renderer.h"

namespace hc::render {

bool isSoftwareRenderer(const std::string& device) {
    for (const char* name : {"llvmpipe", "softpipe", "swrast", "Software Rasterizer"})
        if (device.find(name) != std::string::npos) return true;
    return false;
}

}  // namespace hc::render
