// render_fixture.hpp — one headless GL context per test binary, shared by
// every render test (creating a context costs ~50 ms on llvmpipe).
#pragma once

#include <dm/renderer/context.hpp>

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <gtest/gtest.h>

#include <GL/glcorearb.h>

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
