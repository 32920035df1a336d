// `dmplatform run` on scenes that cannot run: exit code 2, the JSON path or
// the object named on stderr, and no output folder left behind — whether
// the file is invalid or a model in it cannot be built; and `run --view`
// on a virtual X display: the window shows, pixel for pixel, the frame the
// headless run writes, the mouse moved over the window moves a pointer
// device's tool to where the camera's rays put it, and --view refuses what
// it cannot show.
#include <dm/core/types.hpp>
#include <dm/io/image_io.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "../common/temp_dir.hpp"
#include "dmtool_run.hpp"
#include "gamepad.hpp"
#include "virtual_display.hpp"
#include "x_pointer.hpp"

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
      // Out of range.
      {scene(R"("physics": {})", R"(, "dynamic": true, "mass": -1)"), "/objects/1/mass"},
      // A dangling reference.
      {scene(R"("monitor": {})", R"(, "material": "steel")"), "/objects/1/material"},
      {scene(R"("physics": {}, "haptics": {"device": "hand", "objects": ["box"]})",
             R"(, "dynamic": true, "mass": 0.1)"),
       "/engines/haptics/device"},
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

// A device whose driver refuses its parameters fails as it is opened,
// after the scene was read and before anything runs: the device named,
// nothing written.
TEST(Dmplatform, ADeviceThatCannotOpenExitsWithTwoBeforeRunning) {
  const dm::test::TempDir dir("dmplatform_device");
  std::ofstream(dir / "sheet.obj") << "v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n";  // the helper's resource
  std::string text = scene(R"("physics": {}, "haptics": {"device": "hand", "objects": ["box"]})",
                           R"(, "dynamic": true, "mass": 0.1, "haptic": true, "material": "steel")");
  text.insert(text.rfind("\"engines\""),
              R"("materials": {"steel": {"model": "blinn-phong", "haptic": {"stiffness": 500}}},
                 "devices": [{"name": "hand", "driver": "sim-haptic",
                              "config": {"path": "line", "center": [0, 0, 0.05]}}], )");
  const fs::path file = dir / "device.json", out = dir / "out";
  std::ofstream(file) << text;
  const dmtool_test::ToolRun r = runPlatform(file, out);
  EXPECT_EQ(r.exitCode, 2) << dmtool_test::describe(r);
  EXPECT_NE(r.err.find("devices/hand"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("'center' does nothing with path line"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
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

// A red ball dropped on a table, watched by a 320 x 240 camera at 30 Hz
// with the HUD, every frame written.
constexpr const char* kViewScene = R"({"format": "dmplatform-scene", "version": 2, "name": "look",
  "resources": {"ball": {"type": "shape", "shape": "sphere", "radius": 0.03, "subdivisions": 3},
                "table": {"type": "shape", "shape": "plane", "half_extents": [0.2, 0.2]}},
  "materials": {"red": {"model": "blinn-phong", "color": [0.8, 0.05, 0.05]}},
  "objects": [{"name": "table", "mesh": "table"},
              {"name": "ball", "mesh": "ball", "material": "red", "dynamic": true, "mass": 0.1,
               "pose": {"position": [0, 0, 0.2]}}],
  "lights": [{"type": "directional", "direction": [0.3, 0.5, -0.8], "intensity": 1.2}],
  "cameras": [{"name": "side", "position": [0, -0.6, 0.15], "target": [0, 0, 0.08], "up": [0, 0, 1],
               "near": 0.01, "far": 5}],
  "engines": {"physics": {"rate_hz": 500}, "render": {"rate_hz": 30, "width": 320, "height": 240, "hud": true}},
  "outputs": {"summary": true, "frames": true, "frame_every": 1}})";

TEST(Dmplatform, TheLiveViewShowsTheFramesTheHeadlessRunWrites) {
  dm::test::VirtualDisplay x;
  if (x.display().empty()) GTEST_SKIP() << "no Xvfb (apt install xvfb)";
  const dm::test::TempDir dir("dmplatform_view");
  const fs::path file = dir / "look.json", out = dir / "out", shot = dir / "shot.png";
  std::ofstream(file) << kViewScene;
  setenv("DISPLAY", x.display().c_str(), 1);
  const dmtool_test::ToolRun r =
      dmtool_test::runProgram(dm::test::besideExecutable(DMPLATFORM_PATH),
                              {"run", file.string(), "--view", "--screenshot", shot.string(), "--duration",
                               "0.5", "--out", out.string()},
                              300);
  unsetenv("DISPLAY");
  ASSERT_EQ(r.exitCode, 0) << dmtool_test::describe(r);
  // The window's last picture is the last frame written (the newest the
  // render engine made, the HUD drawn over it), pixel for pixel.
  fs::path last;
  for (const auto& e : fs::directory_iterator(out / "frames"))
    if (last.empty() || e.path().filename() > last.filename()) last = e.path();
  ASSERT_FALSE(last.empty());
  auto window = dm::readPng(shot);
  auto frame = dm::readPng(last);
  ASSERT_TRUE(window) << window.error();
  ASSERT_TRUE(frame) << frame.error();
  ASSERT_EQ(window->width(), 320);
  ASSERT_EQ(window->height(), 240);
  ASSERT_EQ(frame->width(), 320);
  ASSERT_EQ(frame->height(), 240);
  std::size_t differ = 0, red = 0;
  for (int y = 0; y < 240; ++y)
    for (int x2 = 0; x2 < 320; ++x2) {
      for (int c = 0; c < 3; ++c)
        differ += window->at<std::uint8_t>(x2, y, c) != frame->at<std::uint8_t>(x2, y, c);
      red += window->at<std::uint8_t>(x2, y, 0) > 100 && window->at<std::uint8_t>(x2, y, 1) < 60;
    }
  EXPECT_EQ(differ, 0u) << last;
  EXPECT_GT(red, 200u);  // the ball is in the picture
}

// A pointer device (the mouse as the tool) over a block far below, seen
// from above by a 320 x 240 camera with a 40° field of view; the forces
// written (the proxy's position: the tool, in free space).
constexpr const char* kMouseScene = R"({"format": "dmplatform-scene", "version": 2, "name": "mouse",
  "resources": {"block": {"type": "shape", "shape": "box", "half_extents": [0.02, 0.02, 0.02]}},
  "materials": {"felt": {"model": "blinn-phong", "color": [0.6, 0.6, 0.6], "haptic": {"stiffness": 800}}},
  "objects": [{"name": "block", "mesh": "block", "material": "felt", "haptic": true,
               "pose": {"position": [0, 0, -0.3]}}],
  "lights": [{"type": "directional", "direction": [0.3, 0.5, -0.8], "intensity": 1.2}],
  "devices": [{"name": "mouse", "driver": "pointer", "config": {"workspace": 0.2}}],
  "cameras": [{"name": "top", "position": [0, 0, 0.5], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": 40}],
  "engines": {"haptics": {"device": "mouse", "object": "block"},
              "render": {"rate_hz": 30, "width": 320, "height": 240}},
  "outputs": {"forces": true}})";

// `dmplatform run --view` of kMouseScene for `seconds` on virtual display x;
// `act` gets the X pointer once the window is up (and a frame has come, with
// its camera). Returns the tool's positions, one per haptic tick (the
// proxy of forces.csv: the tool, in free space), empty after a failure.
std::vector<dm::Vec3> runMouseScene(const dm::test::VirtualDisplay& x, const std::string& name,
                                    double seconds, const std::function<void(dm::test::XPointer&)>& act) {
  const dm::test::TempDir dir(name);
  const fs::path file = dir / "mouse.json", out = dir / "out";
  std::ofstream(file) << kMouseScene;
  setenv("DISPLAY", x.display().c_str(), 1);
  dmtool_test::ToolRun r;
  std::thread run([&] {
    r = dmtool_test::runProgram(
        dm::test::besideExecutable(DMPLATFORM_PATH),
        {"run", file.string(), "--view", "--duration", std::to_string(seconds), "--out", out.string()}, 300);
  });
  dm::test::XPointer pointer(x.display());
  const bool window = pointer.waitForWindow("dmplatform", 30.0);  // once the scene is loaded
  std::this_thread::sleep_for(std::chrono::milliseconds(700));
  if (window) act(pointer);
  run.join();
  unsetenv("DISPLAY");
  EXPECT_TRUE(window) << "no window: " << dmtool_test::describe(r);
  EXPECT_EQ(r.exitCode, 0) << dmtool_test::describe(r);
  std::vector<dm::Vec3> tool;
  std::ifstream csv(out / "forces.csv");
  std::string line;
  std::getline(csv, line);  // t,fx,fy,fz,tx,ty,tz,px,py,pz,...
  while (std::getline(csv, line)) {
    std::vector<double> v;
    std::stringstream ss(line);
    for (std::string cell; std::getline(ss, cell, ',');) v.push_back(std::stod(cell));
    if (v.size() >= 10) tool.emplace_back(v[7], v[8], v[9]);
  }
  return tool;
}

TEST(Dmplatform, TheMouseOverTheLiveViewMovesAPointerDevicesTool) {
  dm::test::VirtualDisplay x;
  if (x.display().empty()) GTEST_SKIP() << "no Xvfb (apt install xvfb)";
  // The pointer over two points of the window, a second on each.
  const std::vector<dm::Vec3> tool = runMouseScene(x, "dmplatform_mouse", 4.0, [](dm::test::XPointer& p) {
    p.warp(240, 60);
    std::this_thread::sleep_for(std::chrono::milliseconds(1000));
    p.warp(80, 180);
  });
  ASSERT_FALSE(tool.empty());
  // The camera's ray through (x, y) meets the plane z = 0 (through the tool,
  // facing the view) at ±(0.5 h tan 20° · 4/3, 0.5 h tan 20°) for h = 0.5 m.
  const double s = 0.5 * 0.5 * std::tan(20.0 * 3.14159265358979323846 / 180.0);
  const dm::Vec3 first(s * 4.0 / 3.0, s, 0.0), second = -first;
  const auto near = [](const dm::Vec3& a, const dm::Vec3& b) { return (a - b).norm() < 1e-9; };
  EXPECT_TRUE(std::any_of(tool.begin(), tool.end(), [&](const dm::Vec3& t) { return near(t, first); }))
      << "the tool never went to " << first.transpose();
  EXPECT_TRUE(near(tool.back(), second)) << tool.back().transpose();
}

// The keyboard moves the same tool: five presses of D, 2 mm each along the
// camera's right (+x here), three of W along its up (+y).
TEST(Dmplatform, TheKeysOfTheLiveViewMoveAPointerDevicesTool) {
  dm::test::VirtualDisplay x;
  if (x.display().empty()) GTEST_SKIP() << "no Xvfb (apt install xvfb)";
  const std::vector<dm::Vec3> tool = runMouseScene(x, "dmplatform_keys", 3.0, [](dm::test::XPointer& p) {
    for (int i = 0; i < 5; ++i) p.key('d');
    for (int i = 0; i < 3; ++i) p.key('w');
  });
  ASSERT_FALSE(tool.empty());
  EXPECT_LT((tool.back() - dm::Vec3(0.010, 0.006, 0.0)).norm(), 1e-12) << tool.back().transpose();
}

TEST(Dmplatform, TheLiveViewRefusesWhatItCannotShow) {
  const dm::test::TempDir dir("dmplatform_noview");
  const fs::path file = dir / "look.json";
  std::ofstream(file) << kViewScene;
  const std::string platform = dm::test::besideExecutable(DMPLATFORM_PATH);
  // No display.
  const char* display = std::getenv("DISPLAY");
  const std::string saved = display ? display : "";
  unsetenv("DISPLAY");
  const auto noDisplay = dmtool_test::runProgram(
      platform, {"run", file.string(), "--view", "--duration", "0.1", "--out", (dir / "a").string()});
  if (!saved.empty()) setenv("DISPLAY", saved.c_str(), 1);
  EXPECT_EQ(noDisplay.exitCode, 1) << dmtool_test::describe(noDisplay);
  EXPECT_NE(noDisplay.err.find("--view"), std::string::npos) << noDisplay.err;
  // A screenshot without the window.
  const auto shotOnly = dmtool_test::runProgram(
      platform, {"run", file.string(), "--screenshot", (dir / "s.png").string(), "--duration", "0.1"});
  EXPECT_EQ(shotOnly.exitCode, 2) << dmtool_test::describe(shotOnly);
  EXPECT_NE(shotOnly.err.find("--view"), std::string::npos) << shotOnly.err;
  // A scene without a render engine.
  std::ofstream(dir / "sheet.obj") << "v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n";
  std::ofstream(dir / "blind.json") << scene(R"("physics": {})", R"(, "dynamic": true, "mass": 0.1)");
  const auto blind = dmtool_test::runProgram(platform, {"run", (dir / "blind.json").string(), "--view",
                                                        "--duration", "0.1", "--out", (dir / "b").string()});
  EXPECT_EQ(blind.exitCode, 2) << dmtool_test::describe(blind);
  EXPECT_NE(blind.err.find("engines/render"), std::string::npos) << blind.err;
}

// The gamepad's mapping: the left stick moves the tool in the view's plane
// (right, and up for a stick pushed up: evdev's negative y), the right
// stick's vertical into the view; within the dead zone nothing moves, past
// it the speed grows linearly to kGamepadSpeed at full deflection.
TEST(DmplatformGamepad, TheSticksMoveTheToolInTheView) {
  dm::FrameCamera camera;
  camera.right = dm::Vec3(0, 1, 0);
  camera.up = dm::Vec3(0, 0, 1);
  camera.forward = dm::Vec3(1, 0, 0);
  dm::ControllerState pad;
  EXPECT_TRUE(dmplatform::gamepadVelocity(pad, camera).isZero());
  pad.axes[0] = 1.0;   // full right
  pad.axes[1] = -1.0;  // full up
  pad.axes[4] = -1.0;  // right stick pushed away
  const dm::Vec3 v = dmplatform::gamepadVelocity(pad, camera);
  EXPECT_LT((v - dmplatform::kGamepadSpeed * dm::Vec3(1, 1, 1)).norm(), 1e-15) << v.transpose();
  pad = {};
  pad.axes[0] = 0.1;  // resting off-centre: inside the dead zone
  pad.axes[1] = -0.15;
  EXPECT_TRUE(dmplatform::gamepadVelocity(pad, camera).isZero());
  pad.axes[0] = -(0.15 + 0.85 / 2);  // halfway from the dead zone to full left
  EXPECT_NEAR(dmplatform::gamepadVelocity(pad, camera).y(), -0.5 * dmplatform::kGamepadSpeed, 1e-15);
  pad.axes[0] = -3.0;  // out of range: full
  EXPECT_NEAR(dmplatform::gamepadVelocity(pad, camera).y(), -dmplatform::kGamepadSpeed, 1e-15);
  pad = {};
  pad.buttons.set(1);
  pad.buttons.set(5);
  EXPECT_EQ(dmplatform::gamepadButtons(pad), 2u);
}

// --gamepad needs the live view, a pointer device and an evdev device;
// each missing is refused (exit 2) before anything runs, naming it.
TEST(Dmplatform, AGamepadIsRefusedWhereItCannotMoveTheTool) {
  const dm::test::TempDir dir("dmplatform_gamepad");
  const fs::path mouse = dir / "mouse.json", look = dir / "look.json";
  std::ofstream(mouse) << kMouseScene;
  std::ofstream(look) << kViewScene;
  const std::string platform = dm::test::besideExecutable(DMPLATFORM_PATH);
  const auto noView = dmtool_test::runProgram(
      platform, {"run", mouse.string(), "--gamepad", "/dev/null", "--duration", "0.1"});
  EXPECT_EQ(noView.exitCode, 2) << dmtool_test::describe(noView);
  EXPECT_NE(noView.err.find("--gamepad"), std::string::npos) << noView.err;
  EXPECT_NE(noView.err.find("--view"), std::string::npos) << noView.err;
  const auto notEvdev = dmtool_test::runProgram(
      platform, {"run", mouse.string(), "--view", "--gamepad", "/dev/null", "--duration", "0.1"});
  EXPECT_EQ(notEvdev.exitCode, 2) << dmtool_test::describe(notEvdev);
  EXPECT_NE(notEvdev.err.find("'/dev/null' is not an evdev input device"), std::string::npos) << notEvdev.err;
  const auto noPointer = dmtool_test::runProgram(
      platform, {"run", look.string(), "--view", "--gamepad", "/dev/null", "--duration", "0.1"});
  EXPECT_EQ(noPointer.exitCode, 2) << dmtool_test::describe(noPointer);
  EXPECT_NE(noPointer.err.find("pointer"), std::string::npos) << noPointer.err;
}
