// render/gl/src/gl.h: the one place render/ includes OpenGL. libglvnd's libOpenGL exports the core
// entry points and dispatches them to whatever context is current (EGL or a GLFW/GLX window), so the
// prototypes are used directly and no loader is needed.
#pragma once

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <GL/glcorearb.h>
