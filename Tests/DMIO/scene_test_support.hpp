// Shared by the scene file tests: where the sources are, and the problems a
// scene that must fail reports, by JSON pointer.
#pragma once

#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

namespace scene_test {

inline std::filesystem::path sourceDir() {
  if (const char* s = std::getenv("DM_SOURCE_DIR")) return s;
  return std::filesystem::path(__FILE__).parent_path().parent_path().parent_path();
}

inline std::vector<dm::Error> problemsOf(const dm::Json& scene, dm::ErrorCode* code = nullptr) {
  std::vector<dm::Error> problems;
  auto s = dm::parseScene(scene.dump(), "scene.json", "/data/scenes", &problems);
  EXPECT_FALSE(s) << "the scene was expected to be invalid";
  if (!s && code) *code = s.error().code;
  return problems;
}

// The one problem recorded at `pointer`, or nullptr (with a failure listing all).
inline const dm::Error* at(const std::vector<dm::Error>& problems, const std::string& pointer) {
  for (const dm::Error& e : problems)
    if (e.where == "scene.json: " + pointer) return &e;
  ADD_FAILURE() << "no problem at " << pointer << "; got:\n" << dm::formatSceneErrors(problems);
  return nullptr;
}

}  // namespace scene_test
