// render/gl/src/context.h: OpenGL contexts for the GL backend: the headless one (public: headless_context.h) and
// checks of the current one.
#pragma once

#include <string>

#include "heightcast/render/gl/headless_context.h"

namespace hc::render::gl {

// Throws hc::Error unless a context is current on this thread and offers OpenGL 4.3 (compute shaders).
void requireGl43(const char* who);
// "llvmpipe (LLVM 15.0.6, 256 bits), OpenGL 4.5 (Core Profile) Mesa 22.3.6" for the current context.
std::string currentDeviceName();

}  // namespace hc::render::gl
