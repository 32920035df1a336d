// render_fixture.hpp — one headless GL context per test binary, shared by
// every render test (creating a context costs ~50 ms on llvmpipe).
#pragma once

#include <dm/renderer/context.hpp>

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <gtest/gtest.h>

#include <GL/glcorearb.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>

namespace dm::test {

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
