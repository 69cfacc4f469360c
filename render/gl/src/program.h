// render/gl/src/program.h: compiling and linking the compute shaders.
#pragma once

#include <string>

#include "gl.h"

namespace hc::render::gl {

// A linked compute program. Throws hc::Error naming the shader, with the driver's info log, when the
// source does not compile or link.
GLuint compileCompute(const std::string& name, const std::string& source);
// The embedded shader `name` (render/gl/shaders/NAME.comp), compiled; throws hc::Error for an unknown name.
GLuint compileEmbedded(const std::string& name);

}  // namespace hc::render::gl
