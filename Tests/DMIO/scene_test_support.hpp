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

// The problem at `pointer` says `words` (in its hint with `inHint`).
inline void expectAt(const std::vector<dm::Error>& problems, const std::string& pointer,
                     const std::string& words, bool inHint = false) {
  const dm::Error* e = at(problems, pointer);
  if (e == nullptr) return;
  const std::string& text = inHint ? e->hint : e->what;
  EXPECT_NE(text.find(words), std::string::npos) << pointer << ": " << text;
}

// `scene` parsed as scene.json in /data/scenes (a failure lists its problems).
inline dm::Result<dm::SceneDesc> parsed(const dm::Json& scene) {
  std::vector<dm::Error> problems;
  auto s = dm::parseScene(scene.dump(), "scene.json", "/data/scenes", &problems);
  EXPECT_TRUE(s) << dm::formatSceneErrors(problems);
  return s;
}

// Parses `scene`, writes it as canonical JSON and parses that again: the
// two must be equal. Returns the canonical JSON (null after a failure).
inline dm::Json expectRoundTrip(const dm::Json& scene) {
  auto s = parsed(scene);
  if (!s) return {};
  const dm::Json j = dm::toJson(*s);
  auto again = parsed(j);
  if (!again) return {};
  EXPECT_EQ(*again, *s);
  return j;
}

}  // namespace scene_test
