// gl.hpp (private) — the OpenGL 4.5 core declarations DMRenderer calls.
// Functions come from libglvnd's libOpenGL.so, which exports every core
// entry point and dispatches to the current EGL context's driver; no loader
// is needed. Only DMRenderer's .cpp files include this header.
#pragma once

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <dm/core/image.hpp>
#include <dm/core/result.hpp>

#include <GL/glcorearb.h>

#include <string>

namespace dm::gl {

/// Name of a glGetError() code ("GL_INVALID_OPERATION", ...).
const char* errorName(GLenum e) noexcept;

/// Drains glGetError(); Internal error naming `what` and the first code when
/// any was set (GL errors are bugs of ours, never of user input).
Status check(const char* what);

/// Reverses the row order in place: GL rows run bottom to top, dm::Image
/// rows top to bottom.
void flipRows(Image& img);

/// Restores, when it goes out of scope, the GL state a renderer's draws
/// change: blending, culling, the depth test, function and mask, the front
/// face, and unbinds the vertex array and program.
struct StateGuard {
  GLboolean blend = glIsEnabled(GL_BLEND), cull = glIsEnabled(GL_CULL_FACE),
            depth = glIsEnabled(GL_DEPTH_TEST);
  GLint depthFunc = 0, frontFace = 0, cullFace = 0;
  GLboolean depthMask = GL_TRUE;
  StateGuard() {
    glGetIntegerv(GL_DEPTH_FUNC, &depthFunc);
    glGetIntegerv(GL_FRONT_FACE, &frontFace);
    glGetIntegerv(GL_CULL_FACE_MODE, &cullFace);
    glGetBooleanv(GL_DEPTH_WRITEMASK, &depthMask);
  }
  StateGuard(const StateGuard&) = delete;
  StateGuard& operator=(const StateGuard&) = delete;
  ~StateGuard() {
    blend ? glEnable(GL_BLEND) : glDisable(GL_BLEND);
    cull ? glEnable(GL_CULL_FACE) : glDisable(GL_CULL_FACE);
    depth ? glEnable(GL_DEPTH_TEST) : glDisable(GL_DEPTH_TEST);
    glDepthFunc(static_cast<GLenum>(depthFunc));
    glFrontFace(static_cast<GLenum>(frontFace));
    glCullFace(static_cast<GLenum>(cullFace));
    glDepthMask(depthMask);
    glBindVertexArray(0);
    glUseProgram(0);
  }
};

}  // namespace dm::gl
