// render_fixture.hpp — one headless GL context per test binary, shared by
// every render test (creating a context costs ~50 ms on llvmpipe).
#pragma once

#include <dm/renderer/context.hpp>
#include <dm/renderer/scene_renderer.hpp>
#include <dm/renderer/shader.hpp>

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <gtest/gtest.h>

#include <GL/glcorearb.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <numbers>

namespace dm::test {

inline constexpr double kPi = std::numbers::pi;

/// Black background and no ambient light: only the scene's lights count.
inline const RenderSettings kDark{.background = Vec4f(0, 0, 0, 1), .ambient = Vec3f(0, 0, 0)};

/// The process-wide context, created on first use; null (the reason printed)
/// when this machine has no EGL OpenGL 4.5. It lives until the process ends
/// and is never destroyed: tearing it down from a static destructor would
/// race Mesa's own exit handlers.
inline GlContext* renderContext() {
  static GlContext* ctx = [] {
    auto c = GlContext::create();
    if (!c) {
      std::fprintf(stderr, "no GL context: %s\n", c.error().message().c_str());
      return static_cast<GlContext*>(nullptr);
    }
    return c->release();
  }();
  return ctx;
}

/// sRGB encoding of a linear value in [0, 1] as the GL_FRAMEBUFFER_SRGB path
/// stores it, on the 0..255 scale (unrounded).
inline double srgbEncode255(double linear) {
  const double s = linear <= 0.0031308 ? 12.92 * linear : 1.055 * std::pow(linear, 1 / 2.4) - 0.055;
  return s * 255;
}

/// Linear value of an sRGB-encoded 8-bit channel.
inline double srgbToLinear(int encoded) {
  const double s = encoded / 255.0;
  return s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4);
}

/// A flat-colour program for raw test draws: vec2 NDC positions at
/// attribute 0, depth `u_depth` (NDC), colour `u_color`.
inline constexpr const char* kFlatVs = R"(
layout(location = 0) in vec2 a_pos;
uniform float u_depth;
void main() { gl_Position = vec4(a_pos, u_depth, 1.0); }
)";
inline constexpr const char* kFlatFs = R"(
uniform vec4 u_color;
out vec4 o_color;
void main() { o_color = u_color; }
)";

/// Draws the NDC rectangle [x0, x1] x [y0, y1] at NDC depth `ndcZ` in a flat
/// linear colour into the bound framebuffer and viewport, with the depth
/// test on (GL_LESS, depth written). Raw GL: no renderer involved.
inline ::testing::AssertionResult drawNdcRect(float x0, float y0, float x1, float y1, float ndcZ,
                                              const Vec4f& color) {
  auto prog =
      ShaderProgram::create("test rect", {{ShaderStage::Vertex, kFlatVs}, {ShaderStage::Fragment, kFlatFs}});
  if (!prog) return ::testing::AssertionFailure() << prog.error();
  const float quad[] = {x0, y0, x1, y0, x1, y1, x0, y0, x1, y1, x0, y1};
  GLuint vao = 0, vbo = 0;
  glCreateVertexArrays(1, &vao);
  glCreateBuffers(1, &vbo);
  glNamedBufferStorage(vbo, sizeof(quad), quad, 0);
  glVertexArrayVertexBuffer(vao, 0, vbo, 0, 2 * sizeof(float));
  glEnableVertexArrayAttrib(vao, 0);
  glVertexArrayAttribFormat(vao, 0, 2, GL_FLOAT, GL_FALSE, 0);
  glVertexArrayAttribBinding(vao, 0, 0);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  prog->use();
  prog->set("u_color", color);
  prog->set("u_depth", ndcZ);
  glBindVertexArray(vao);
  glDrawArrays(GL_TRIANGLES, 0, 6);
  glBindVertexArray(0);
  glDeleteVertexArrays(1, &vao);
  glDeleteBuffers(1, &vbo);
  return ::testing::AssertionSuccess();
}

/// Where golden references live: $DM_SOURCE_DIR/Tests/DMRenderer/golden.
inline std::filesystem::path goldenDir() {
  const char* src = std::getenv("DM_SOURCE_DIR");
  return std::filesystem::path(src != nullptr ? src : ".") / "Tests" / "DMRenderer" / "golden";
}

/// Where failing render tests write NAME.actual.png / NAME.diff.png.
inline std::filesystem::path renderOutDir() {
  return std::filesystem::temp_directory_path() / "dm_render_test";
}

}  // namespace dm::test

/// Every render test starts with this: the context must exist (CI machines
/// have Mesa's surfaceless llvmpipe; a missing one is a failure, not a skip).
#define DM_REQUIRE_GL()                                             \
  ASSERT_NE(::dm::test::renderContext(), nullptr) << "EGL context"; \
  ASSERT_TRUE(::dm::test::renderContext()->makeCurrent())
