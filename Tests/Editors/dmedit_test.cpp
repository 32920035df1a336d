// dmedit: the scene document (validated edits with the JSON path of a
// refused one, undo and redo, saving that dmplatform reads back, relative
// sources kept loadable when the scene moves) and, where Xvfb and the GUI
// were built, the editor itself: started on a virtual X display with the
// bundled scene, it must draw its panels and the head into the screenshot.
#include <dm/core/filesystem.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <thread>

#include "dmtool_run.hpp"
#include "virtual_display.hpp"
#include "document.hpp"
#include "../common/build_paths.hpp"

namespace {

namespace fs = std::filesystem;
using dmtool_test::TempDir;

const fs::path kScene = fs::path(dm::test::besideExecutable(DM_SOURCE_SCENES_DIR)) / "head_probe.json";

TEST(DmeditDocument, EditsAreValidatedUndoneAndSaved) {
  auto doc = dmedit::SceneDocument::open(kScene);
  ASSERT_TRUE(doc) << doc.error();
  EXPECT_FALSE(doc->dirty());
  const dm::SceneDesc original = doc->scene();

  dm::SceneObject tool = *doc->scene().object("tool");
  tool.pose.p = dm::Vec3(0.01, -0.02, 0.03);
  tool.scale = 2.0;
  ASSERT_TRUE(doc->setObject(tool));
  EXPECT_TRUE(doc->dirty());
  EXPECT_EQ(doc->scene().object("tool")->pose.p, dm::Vec3(0.01, -0.02, 0.03));

  // A value out of range is refused with its JSON path; nothing changes.
  tool.scale = -1.0;
  const auto refused = doc->setObject(tool);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message().find("/objects/1/scale"), std::string::npos) << refused.error();
  EXPECT_EQ(doc->scene().object("tool")->scale, 2.0);
  // So is removing an object the haptic engine still shows the proxy with.
  const auto removal = doc->removeObject("tool");
  ASSERT_FALSE(removal);
  EXPECT_NE(removal.error().message().find("proxy_object"), std::string::npos) << removal.error();
  EXPECT_FALSE(doc->removeObject("no_such_object"));

  // Materials and lights.
  dm::SceneMaterial skin = *doc->scene().material("skin");
  skin.color = dm::Vec4(0.5, 0.4, 0.3, 1.0);
  skin.haptic->stiffness = 650;
  ASSERT_TRUE(doc->setMaterial(skin));
  skin.haptic->dynamicFriction = skin.haptic->staticFriction + 1;  // dynamic > static
  EXPECT_FALSE(doc->setMaterial(skin));
  dm::SceneLight light = doc->scene().lights.at(0);
  light.intensity = 2.0;
  ASSERT_TRUE(doc->setLight(0, light));
  EXPECT_FALSE(doc->setLight(99, light));

  // Place an object of a drawable resource; an unknown resource is refused.
  dm::SceneObject ball;
  ball.name = "marker";
  ball.mesh = "tool";
  ASSERT_TRUE(doc->addObject(ball));
  EXPECT_FALSE(doc->addObject(ball));  // the name is taken
  ball.name = "other";
  ball.mesh = "no_such_resource";
  EXPECT_FALSE(doc->addObject(ball));

  // Undo walks back to the original, redo forward again.
  int undone = 0;
  while (doc->undo()) ++undone;
  EXPECT_EQ(undone, 4);
  EXPECT_EQ(doc->scene(), original);
  EXPECT_TRUE(doc->redo());
  EXPECT_EQ(doc->scene().object("tool")->scale, 2.0);
  while (doc->redo()) {
  }
  ASSERT_NE(doc->scene().object("marker"), nullptr);

  // Saved elsewhere, it reads back as the same scene (sources still load:
  // the bundled one uses mounted data, "mricron:...").
  TempDir dir;
  const fs::path out = dir.path / "edited.json";
  ASSERT_TRUE(doc->save(out));
  EXPECT_FALSE(doc->dirty());
  EXPECT_EQ(doc->file(), out);
  auto back = dm::readScene(out);
  ASSERT_TRUE(back) << back.error();
  EXPECT_EQ(back->object("tool")->pose.p, dm::Vec3(0.01, -0.02, 0.03));
  EXPECT_EQ(back->material("skin")->haptic->stiffness, 650);
  EXPECT_NE(back->object("marker"), nullptr);
  EXPECT_EQ(back->resources, doc->scene().resources);
}

TEST(DmeditDocument, RelativeSourcesStayLoadableWhenTheSceneMoves) {
  TempDir a, b;
  const std::string obj = dmtool_test::writeUnitBox(a);
  {
    std::ofstream f(a.path / "scene.json");
    f << R"({"format": "dmplatform-scene", "version": 1,
             "resources": {"box": {"type": "mesh", "source": "unit_box.obj"}},
             "objects": [{"name": "box", "mesh": "box"}],
             "cameras": [{"name": "c", "position": [2, 2, 2], "target": [0, 0, 0], "up": [0, 0, 1]}]})";
  }
  auto doc = dmedit::SceneDocument::open(a.path / "scene.json");
  ASSERT_TRUE(doc) << doc.error();
  ASSERT_TRUE(doc->save(b.path / "moved.json"));
  auto moved = dm::readScene(b.path / "moved.json");
  ASSERT_TRUE(moved) << moved.error();
  EXPECT_EQ(fs::path(moved->resource("box")->source), fs::path(obj));
  // The old folder is now outside the scene's: the editor allowed it for this
  // process; without that (another process), the source is refused and the
  // error says how to allow it (issue 37, FileSystem::confine).
  dm::FileSystem::global().disallowRoot(fs::absolute(a.path));
  auto refused = dm::readScene(b.path / "moved.json");
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message().find("DM_ALLOW_PATH"), std::string::npos) << refused.error();
  // Saved in place, the relative source stays relative.
  auto again = dmedit::SceneDocument::open(a.path / "scene.json");
  ASSERT_TRUE(again);
  ASSERT_TRUE(again->save());
  EXPECT_EQ(dm::readScene(a.path / "scene.json")->resource("box")->source, "unit_box.obj");
}

TEST(DmeditDocument, ABadSceneIsRefusedWithEveryProblem) {
  TempDir dir;
  {
    std::ofstream f(dir.path / "bad.json");
    f << R"({"format": "dmplatform-scene", "version": 1, "objects": [{"name": "x", "mesh": "missing"}],
             "lights": [{"type": "laser"}]})";
  }
  auto doc = dmedit::SceneDocument::open(dir.path / "bad.json");
  ASSERT_FALSE(doc);
  EXPECT_NE(doc.error().message().find("/objects/0/mesh"), std::string::npos) << doc.error();
  EXPECT_NE(doc.error().message().find("/lights/0/type"), std::string::npos) << doc.error();
}

#ifdef DMEDIT_PATH
TEST(Dmedit, DrawsThePanelsAndTheSceneUnderXvfb) {
  dm::test::VirtualDisplay x;
  if (x.display().empty()) GTEST_SKIP() << "no Xvfb (apt install xvfb)";
  TempDir dir;
  const fs::path shot = dir.path / "dmedit.png";
  setenv("DISPLAY", x.display().c_str(), 1);
  const auto run = dmtool_test::runProgram(
      dm::test::besideExecutable(DMEDIT_PATH), {kScene.string(), "--size", "1000x640", "--screenshot", shot.string(), "--frames", "4"}, 300);
  unsetenv("DISPLAY");
  ASSERT_EQ(run.exitCode, 0) << dmtool_test::describe(run);
  auto image = dm::readPng(shot);
  ASSERT_TRUE(image) << image.error();
  ASSERT_EQ(image->width(), 1000);
  ASSERT_EQ(image->height(), 640);
  // Not blank: many colours (panels, text, the shaded head), and skin-toned
  // pixels in the View panel (the middle of the window), where the head is.
  std::set<std::uint32_t> colours;
  std::size_t skin = 0;
  for (int y = 0; y < image->height(); ++y)
    for (int x2 = 0; x2 < image->width(); ++x2) {
      const int r = image->at<std::uint8_t>(x2, y, 0), g = image->at<std::uint8_t>(x2, y, 1),
                b = image->at<std::uint8_t>(x2, y, 2);
      colours.insert(static_cast<std::uint32_t>(r << 16 | g << 8 | b));
      if (x2 > 300 && x2 < 700 && r > 120 && r > g + 20 && g > b + 10) ++skin;
    }
  EXPECT_GT(colours.size(), 200u);
  EXPECT_GT(skin, 5000u) << "the head should be drawn in the View panel";
}

TEST(Dmedit, RefusesABadSceneAndABadSize) {
  TempDir dir;
  const auto missing = dmtool_test::runProgram(dm::test::besideExecutable(DMEDIT_PATH), {(dir.path / "none.json").string()}, 60);
  EXPECT_EQ(missing.exitCode, 1) << dmtool_test::describe(missing);
  EXPECT_NE(missing.err.find("none.json"), std::string::npos) << missing.err;
  const auto size = dmtool_test::runProgram(dm::test::besideExecutable(DMEDIT_PATH), {kScene.string(), "--size", "10x10"}, 60);
  EXPECT_EQ(size.exitCode, 1) << dmtool_test::describe(size);
  EXPECT_NE(size.err.find("--size"), std::string::npos) << size.err;
}
#endif

}  // namespace
