// `dmplatform run` on scenes that cannot run: exit code 2, the JSON path or
// the object named on stderr, and no output folder left behind — whether
// the file is invalid or a model in it cannot be built.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "../common/temp_dir.hpp"
#include "dmtool_run.hpp"

namespace {

namespace fs = std::filesystem;

dmtool_test::ToolRun runPlatform(const fs::path& scene, const fs::path& out) {
  return dmtool_test::runProgram(
      dm::test::besideExecutable(DMPLATFORM_PATH),
      {"run", scene.string(), "--lockstep", "--duration", "0.5", "--out", out.string()});
}

// A table and a box; `boxKeys` are added to the box object.
std::string scene(const std::string& engines, const std::string& boxKeys,
                  const std::string& boxMesh = "box") {
  return R"({"format": "dmplatform-scene", "version": 2, "name": "bad",
    "resources": {
      "table": {"type": "shape", "shape": "plane", "half_extents": [0.2, 0.2]},
      "box": {"type": "shape", "shape": "box", "half_extents": [0.02, 0.02, 0.02]},
      "sheet": {"type": "mesh", "source": "sheet.obj"}
    },
    "objects": [
      {"name": "table", "mesh": "table"},
      {"name": "box", "mesh": ")" +
         boxMesh + R"(", "pose": {"position": [0, 0, 0.02]})" + boxKeys + R"(}
    ],
    "engines": {)" +
         engines + R"(}})";
}

}  // namespace

TEST(Dmplatform, InvalidScenesExitWithTwoAndNameTheEntry) {
  const dm::test::TempDir dir("dmplatform_invalid");
  struct Case {
    std::string text, where;
  };
  const Case cases[] = {
      // A dynamic object and no physics engine (once silently ignored).
      {scene(R"("monitor": {})", R"(, "dynamic": true, "mass": 0.1)"), "/objects/1/dynamic"},
      // A physics engine with nothing to move.
      {scene(R"("physics": {})", ""), "/engines/physics"},
      // A key the runtime does not know.
      {scene(R"("physics": {"rate_hz": 500, "substeps": 4})", R"(, "dynamic": true, "mass": 0.1)"),
       "/engines/physics/substeps"},
      // A wrong type.
      {scene(R"("physics": {})", R"(, "dynamic": true, "mass": "heavy")"), "/objects/1/mass"},
  };
  for (const Case& c : cases) {
    const fs::path file = dir / "bad.json", out = dir / "out";
    std::ofstream(file) << c.text;
    const dmtool_test::ToolRun r = runPlatform(file, out);
    EXPECT_EQ(r.exitCode, 2) << dmtool_test::describe(r);
    EXPECT_NE(r.err.find(c.where), std::string::npos) << c.where << "\n" << r.err;
    EXPECT_FALSE(fs::exists(out)) << c.where;
  }
}

TEST(Dmplatform, AModelThatCannotBeBuiltExitsWithTwoBeforeRunning) {
  // A valid scene whose dynamic body is an open sheet (one triangle): it has
  // no volume, so no mass properties; the run fails while the engines are
  // built, before anything is written.
  const dm::test::TempDir dir("dmplatform_model");
  std::ofstream(dir / "sheet.obj") << "v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n";
  const fs::path file = dir / "sheet.json", out = dir / "out";
  std::ofstream(file) << scene(R"("physics": {})", R"(, "dynamic": true, "mass": 0.1)", "sheet");
  const dmtool_test::ToolRun r = runPlatform(file, out);
  EXPECT_EQ(r.exitCode, 2) << dmtool_test::describe(r);
  EXPECT_NE(r.err.find("objects/box"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("closed"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
}
