// gl.hpp (private) — the OpenGL 4.5 core declarations DMRenderer calls.
// Functions come from libglvnd's libOpenGL.so, which exports every core
// entry point and dispatches to the current EGL context's driver; no loader
// is needed. Only DMRenderer's .cpp files include this header.
#pragma once

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <GL/glcorearb.h>

#include <dm/core/result.hpp>

#include <string>

namespace dm::gl {

/// Name of a glGetError() code ("GL_INVALID_OPERATION", ...).
const char* errorName(GLenum e) noexcept;

/// Drains glGetError(); Internal error naming `what` and the first code when
/// any was set (GL errors are bugs of ours, never of user input).
Status check(const char* what);

}  // namespace dm::gl
