// Shared by the scene-run tests: a scene run in lockstep, its output files,
// the bundled scenes without their render engine (the mechanics is what
// those tests check; the examples' integration tests render them).
#pragma once

#include <dm/core/filesystem.hpp>
#include <dm/core/image.hpp>
#include <dm/core/types.hpp>
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/volume_io.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "../common/build_paths.hpp"

namespace scene_run {

namespace fs = std::filesystem;

/// The share of a frame's pixels that are red (red well over green and
/// blue: blood, or anything drawn in a red material).
inline double redShare(const dm::Image& frame) {
  std::size_t red = 0;
  for (int y = 0; y < frame.height(); ++y)
    for (int x = 0; x < frame.width(); ++x) {
      const int r = frame.at<std::uint8_t>(x, y, 0), g = frame.at<std::uint8_t>(x, y, 1),
                b = frame.at<std::uint8_t>(x, y, 2);
      if (r > 40 && r > 3 * g && r > 3 * b) ++red;
    }
  return double(red) / double(frame.width() * frame.height());
}

/// [x, y, z] of a summary.
inline dm::Vec3 vec(const nlohmann::json& j) {
  return {j[0].get<double>(), j[1].get<double>(), j[2].get<double>()};
}

/// The entry of `list` (a summary's array of objects) whose "name" is
/// `name`; an empty object (and a failure) when there is none.
inline const nlohmann::json& named(const nlohmann::json& list, const std::string& name) {
  for (const nlohmann::json& e : list)
    if (e.at("name") == name) return e;
  ADD_FAILURE() << "no entry " << name << " in " << list.dump(2);
  static const nlohmann::json none = nlohmann::json::object();
  return none;
}

/// The bytes of a run's output file, as text.
inline std::string fileText(const fs::path& p) {
  auto bytes = dm::readFile(p);
  EXPECT_TRUE(bytes) << bytes.error();
  return bytes ? std::string(reinterpret_cast<const char*>(bytes->data()), bytes->size()) : std::string();
}

/// One row of a run's forces.csv (dm::formatProbeCsv): scene time, the
/// force and torque sent to the hand and the proxy's position (world).
struct TraceRow {
  double t = 0;
  dm::Vec3 force, torque, proxy;
};

/// Every row of the forces.csv at `file` (its header skipped); a row that
/// does not parse is a failure.
inline std::vector<TraceRow> forceTrace(const fs::path& file) {
  std::vector<TraceRow> rows;
  const std::string text = fileText(file);
  std::size_t at = text.find('\n');  // after the header
  while (at != std::string::npos && at + 1 < text.size()) {
    double v[10];
    const int n = std::sscanf(text.c_str() + at + 1, "%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf", &v[0], &v[1],
                              &v[2], &v[3], &v[4], &v[5], &v[6], &v[7], &v[8], &v[9]);
    EXPECT_EQ(n, 10) << file << " row " << rows.size() + 1;
    if (n != 10) break;
    rows.push_back({v[0], {v[1], v[2], v[3]}, {v[4], v[5], v[6]}, {v[7], v[8], v[9]}});
    at = text.find('\n', at + 1);
  }
  return rows;
}

/// Runs `scene` in lockstep for `seconds` into `out` (emptied first); its
/// summary, or null after a failure (reported).
inline nlohmann::json runScene(const dm::SceneDesc& scene, double seconds, const fs::path& out) {
  fs::remove_all(out);
  auto rt = dm::SceneRuntime::create(scene);
  EXPECT_TRUE(rt) << rt.error();
  if (!rt) return {};
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = seconds, .outDir = out});
  EXPECT_TRUE(r) << r.error();
  return r ? r->summary : nlohmann::json();
}

/// `text` parsed as scene file `file` in `dir` (a failure lists its
/// problems); an empty scene after a failure.
inline dm::SceneDesc parsedScene(const std::string& text, const std::string& file,
                                 const fs::path& dir = fs::temp_directory_path()) {
  std::vector<dm::Error> problems;
  auto s = dm::parseScene(text, file, dir, &problems);
  EXPECT_TRUE(s) << dm::formatSceneErrors(problems);
  return s ? *s : dm::SceneDesc{};
}

/// A homogeneous ball of value 100 and `radius` (m) in a zero background,
/// n³ voxels of 1 mm centred on the origin, written as `file` (NIfTI): a
/// volume whose segmentation is known.
inline void writeBallVolume(const fs::path& file, double radius, int n = 40) {
  dm::Affine3 toWorld = dm::Affine3::Identity();
  toWorld.linear() = 0.001 * dm::Mat3::Identity();
  toWorld.translation() = dm::Vec3::Constant(-0.001 * (n - 1) / 2.0);
  auto v = dm::Volume::create({n, n, n}, dm::VoxelType::U8, toWorld);
  ASSERT_TRUE(v) << v.error();
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        if ((toWorld * dm::Vec3(i, j, k)).norm() <= radius) v->setValue(i, j, k, 100);
  ASSERT_TRUE(dm::writeVolume(*v, file));
}

/// examples/scenes/`file`, without its render engine, frames and plot.
inline dm::SceneDesc bundledScene(std::string_view file) {
  std::vector<dm::Error> problems;
  auto s = dm::readScene(fs::path(dm::test::besideExecutable(DM_EXAMPLE_SCENES_DIR)) / file, &problems);
  EXPECT_TRUE(s) << dm::formatSceneErrors(problems);
  if (!s) return {};
  dm::SceneDesc scene = *s;
  scene.engines.render.reset();
  scene.outputs.frames = false;
  scene.outputs.plot = false;
  return scene;
}

}  // namespace scene_run
