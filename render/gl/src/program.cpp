#include "program.h"

#include <algorithm>
#include <vector>

#include "shader_sources.h"
#include "heightcast/core/error.h"

namespace hc::render::gl {
namespace {

std::string shaderLog(GLuint shader) {
    GLint length = 0;
    glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
    std::vector<char> log(size_t(std::max(length, 1)), '\0');
    glGetShaderInfoLog(shader, GLsizei(log.size()), nullptr, log.data());
    return log.data();
}

std::string programLog(GLuint program) {
    GLint length = 0;
    glGetProgramiv(program, GL_INFO_LOG_LENGTH, &length);
    std::vector<char> log(size_t(std::max(length, 1)), '\0');
    glGetProgramInfoLog(program, GLsizei(log.size()), nullptr, log.data());
    return log.data();
}

}  // namespace

GLuint compileCompute(const std::string& name, const std::string& source) {
    const GLuint shader = glCreateShader(GL_COMPUTE_SHADER);
    if (!shader) throw Error("GL shader " + name + ": glCreateShader failed (no current OpenGL 4.3 context?)");
    const char* text = source.c_str();
    glShaderSource(shader, 1, &text, nullptr);
    glCompileShader(shader);
    GLint ok = 0;
    glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        const std::string log = shaderLog(shader);
        glDeleteShader(shader);
        throw Error("GL shader " + name + ": compilation failed:\n" + log);
    }
    const GLuint program = glCreateProgram();
    glAttachShader(program, shader);
    glLinkProgram(program);
    glDeleteShader(shader);  // flagged; freed with the program
    glGetProgramiv(program, GL_LINK_STATUS, &ok);
    if (!ok) {
        const std::string log = programLog(program);
        glDeleteProgram(program);
        throw Error("GL shader " + name + ": linking failed:\n" + log);
    }
    return program;
}

GLuint compileEmbedded(const std::string& name) {
    for (int i = 0; i < kShaderSourceCount; ++i)
        if (name == kShaderSources[i].name) return compileCompute(name + ".comp", kShaderSources[i].source);
    throw Error("GL shader " + name + ": no such embedded shader");
}

}  // namespace hc::render::gl
