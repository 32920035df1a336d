// live_view.cpp — `dmplatform run --view` (live_view.hpp).
#include "live_view.hpp"

#include <dm/io/image_io.hpp>
#include <dm/io/pointer_device.hpp>
#include <dm/io/scene_file.hpp>

#include <GLFW/glfw3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <string>
#include <thread>

#include "gamepad.hpp"

namespace dmplatform {

namespace {

using Clock = std::chrono::steady_clock;

// What the keys and the mouse asked for (GLFW's callbacks, on the calling
// thread).
struct Input {
  dm::SceneRuntime* runtime = nullptr;
  bool paused = false;
  int steps = 0;  // render frames to step while paused
  bool quit = false;
  dm::ViewOrbit orbit;
  int dragging = -1;  // the mouse button held, or -1
  double x = 0.0, y = 0.0;
  // The mouse as the tool (a scene whose haptic device is a "pointer").
  dm::PointerChannel* pointer = nullptr;
  bool toolMode = false;  // T toggles it with the camera mode
  dm::Isometry3 deviceToWorld = dm::Isometry3::Identity();
  dm::Vec3 tool = dm::Vec3::Zero();  // world
  std::uint32_t buttons = 0;         // the mouse's
  std::uint32_t padButtons = 0;      // the gamepad's
  dm::FrameCamera camera;            // of the frame shown
  int width = 1, height = 1;
};

// The tool to the device point the pointer reports.
void sendTool(Input& in) {
  in.pointer->set(in.deviceToWorld.inverse() * in.tool, in.buttons | in.padButtons);
}

// The gamepad's sticks move the tool for the `seconds` since its last poll.
void padTool(Input& in, dm::Controller& pad, double seconds) {
  const std::int64_t now =
      std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
  if (pad.poll(now) != dm::DeviceStatus::Ok) return;
  const dm::ControllerState& state = pad.state();
  const dm::Vec3 velocity = gamepadVelocity(state, in.camera);
  const std::uint32_t buttons = gamepadButtons(state);
  if (!in.toolMode || (velocity.isZero() && buttons == in.padButtons)) return;
  in.tool += seconds * velocity;
  in.padButtons = buttons;
  sendTool(in);
}

// The tool under the cursor, in the plane through it that faces the view.
void toolToCursor(Input& in, double x, double y) {
  const auto [origin, direction] = in.camera.ray(x, y, in.width, in.height);
  const double facing = direction.dot(in.camera.forward);
  if (facing < 1e-6) return;
  in.tool = origin + ((in.tool - origin).dot(in.camera.forward) / facing) * direction;
  sendTool(in);
}

Input& inputOf(GLFWwindow* window) { return *static_cast<Input*>(glfwGetWindowUserPointer(window)); }

void onKey(GLFWwindow* window, int key, int, int action, int) {
  if (action != GLFW_PRESS && action != GLFW_REPEAT) return;
  Input& in = inputOf(window);
  if (key == GLFW_KEY_ESCAPE) in.quit = true;
  if (key == GLFW_KEY_SPACE && action == GLFW_PRESS) in.paused = !in.paused;
  if ((key == GLFW_KEY_N || key == GLFW_KEY_RIGHT) && in.paused) ++in.steps;
  if (key == GLFW_KEY_T && action == GLFW_PRESS && in.pointer) in.toolMode = !in.toolMode;
  if (in.toolMode) {  // the keyboard moves the tool 2 mm a press: W A S D in the view, Q E along it
    const dm::FrameCamera& c = in.camera;
    dm::Vec3 step = dm::Vec3::Zero();
    if (key == GLFW_KEY_W) step = c.up;
    if (key == GLFW_KEY_S) step = -c.up;
    if (key == GLFW_KEY_D) step = c.right;
    if (key == GLFW_KEY_A) step = -c.right;
    if (key == GLFW_KEY_Q) step = c.forward;
    if (key == GLFW_KEY_E) step = -c.forward;
    if (!step.isZero()) {
      in.tool += 0.002 * step;
      sendTool(in);
    }
  }
  if (key == GLFW_KEY_R) {
    in.orbit = {};
    in.runtime->setViewOrbit(in.orbit);
  }
}

void onButton(GLFWwindow* window, int button, int action, int) {
  Input& in = inputOf(window);
  if (in.toolMode) {  // the mouse's buttons are the device's
    const std::uint32_t bit = 1u << std::clamp(button, 0, 31);
    in.buttons = action == GLFW_PRESS ? in.buttons | bit : in.buttons & ~bit;
    sendTool(in);
    return;
  }
  if (action == GLFW_PRESS && in.dragging < 0) {
    in.dragging = button;
    glfwGetCursorPos(window, &in.x, &in.y);
  } else if (action == GLFW_RELEASE && button == in.dragging) {
    in.dragging = -1;
  }
}

// Left drag turns the camera about its target (8 mrad a pixel), any other
// button pans it (2 ‰ of the distance a pixel).
void onCursor(GLFWwindow* window, double x, double y) {
  Input& in = inputOf(window);
  if (in.toolMode) return toolToCursor(in, x, y);
  if (in.dragging < 0) return;
  const double dx = x - in.x, dy = y - in.y;
  in.x = x, in.y = y;
  if (in.dragging == GLFW_MOUSE_BUTTON_LEFT) {
    in.orbit.yaw -= 0.008 * dx;
    in.orbit.pitch += 0.008 * dy;
  } else {
    in.orbit.panRight -= 0.002 * dx * in.orbit.zoom;
    in.orbit.panUp += 0.002 * dy * in.orbit.zoom;
  }
  in.runtime->setViewOrbit(in.orbit);
}

// The wheel zooms: 10 % nearer a notch (in tool mode it moves the tool).
void onScroll(GLFWwindow* window, double, double dy) {
  Input& in = inputOf(window);
  if (in.toolMode) {  // the tool 2 mm into the view (away from the eye) a notch
    in.tool += 0.002 * dy * in.camera.forward;
    sendTool(in);
    return;
  }
  in.orbit.zoom = std::clamp(in.orbit.zoom * std::pow(0.9, dy), 1e-3, 1e3);
  in.runtime->setViewOrbit(in.orbit);
}

// The frame 1:1 from the window's top-left corner (an image's first row is
// its top; GL's raster goes up, hence the flip).
void draw(GLFWwindow* window, const dm::Image& frame) {
  int w = 0, h = 0;
  glfwGetFramebufferSize(window, &w, &h);
  glViewport(0, 0, w, h);
  glClearColor(0.f, 0.f, 0.f, 1.f);
  glClear(GL_COLOR_BUFFER_BIT);
  if (frame.empty() || frame.type() != dm::PixelType::U8) return;
  glMatrixMode(GL_PROJECTION);
  glLoadIdentity();
  glOrtho(0, w, 0, h, -1, 1);
  glMatrixMode(GL_MODELVIEW);
  glLoadIdentity();
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, static_cast<GLint>(frame.strideBytes() / frame.pixelBytes()));
  glRasterPos2i(0, h);
  glPixelZoom(1.f, -1.f);
  const GLenum format = frame.channels() == 4 ? GL_RGBA : frame.channels() == 3 ? GL_RGB : GL_LUMINANCE;
  glDrawPixels(frame.width(), frame.height(), format, GL_UNSIGNED_BYTE, frame.data());
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
}

// The window's back buffer as an RGB image, top row first.
dm::Result<dm::Image> readWindow(GLFWwindow* window) {
  int w = 0, h = 0;
  glfwGetFramebufferSize(window, &w, &h);
  auto image = dm::Image::create(w, h, 3, dm::PixelType::U8);
  if (!image) return image.error();
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glPixelStorei(GL_PACK_ROW_LENGTH, static_cast<GLint>(image->strideBytes() / 3));
  glReadBuffer(GL_BACK);
  for (int y = 0; y < h; ++y)  // GL's row 0 is the bottom
    glReadPixels(0, h - 1 - y, w, 1, GL_RGB, GL_UNSIGNED_BYTE, image->row(y));
  glPixelStorei(GL_PACK_ROW_LENGTH, 0);
  return image;
}

}  // namespace

dm::Result<dm::SceneRunResult> runWithView(dm::SceneRuntime& runtime, dm::SceneRunOptions options,
                                           const LiveViewOptions& view) {
  const dm::SceneDesc& scene = runtime.scene();
  if (!scene.engines.render)
    return dm::fail(dm::ErrorCode::InvalidArgument, "the scene has no render engine to show", "--view",
                    "add \"render\": {\"rate_hz\": 30} to the scene's \"engines\", or leave out --view");
  if (glfwInit() != GLFW_TRUE)
    return dm::fail(dm::ErrorCode::InvalidArgument, "no window system to open a window on", "--view",
                    "run on a desktop (DISPLAY set), under xvfb-run, or leave out --view (headless)");
  struct Terminate {
    ~Terminate() { glfwTerminate(); }
  } terminate;
  glfwWindowHint(GLFW_RESIZABLE, GLFW_FALSE);
  glfwWindowHint(GLFW_DOUBLEBUFFER, GLFW_TRUE);
  const int width = scene.engines.render->width, height = scene.engines.render->height;
  GLFWwindow* window =
      glfwCreateWindow(width, height, ("dmplatform — " + scene.name).c_str(), nullptr, nullptr);
  if (window == nullptr)
    return dm::fail(dm::ErrorCode::InvalidArgument,
                    "the window system refused a " + std::to_string(width) + "x" + std::to_string(height) +
                        " OpenGL window",
                    "--view", "check the display's OpenGL (glxinfo), or leave out --view");
  Input keys;
  keys.runtime = &runtime;
  keys.width = width;
  keys.height = height;
  // A scene whose haptic device is a pointer: the mouse moves its tool.
  if (scene.engines.haptics)
    if (const dm::SceneDevice* dev = scene.device(scene.engines.haptics->device);
        dev && dev->driver == "pointer") {
      std::string channel = "mouse";
      for (const auto& [key, value] : dm::deviceParams(*dev))
        if (key == "channel") channel = value;
      keys.pointer = &dm::pointerChannel(channel);
      keys.toolMode = true;
      keys.deviceToWorld = scene.engines.haptics->devicePose.isometry();
      keys.tool = keys.deviceToWorld.translation();
      keys.pointer->set(dm::Vec3::Zero(), 0);
    }
  if (view.gamepad && !keys.pointer) {
    glfwDestroyWindow(window);
    return dm::fail(dm::ErrorCode::InvalidArgument, "a gamepad moves a pointer device's tool", "--gamepad",
                    "give the scene's haptic engine a device with \"driver\": \"pointer\"");
  }
  glfwSetWindowUserPointer(window, &keys);
  glfwSetKeyCallback(window, onKey);
  glfwSetMouseButtonCallback(window, onButton);
  glfwSetCursorPosCallback(window, onCursor);
  glfwSetScrollCallback(window, onScroll);

  options.liveFrames = true;
  const bool lockstep = options.mode == dm::RunMode::Lockstep;
  const double frameSeconds = 1.0 / scene.engines.render->rateHz;
  if (auto s = runtime.start(options); !s) {
    glfwDestroyWindow(window);
    return s.error();
  }
  std::uint64_t seen = 0;
  dm::Image frame;
  double frameTime = 0.0;
  const Clock::time_point start = Clock::now();
  Clock::time_point last = start, lastPad = start;
  dm::Status failed = dm::ok();
  const auto stopped = [&] {
    return keys.quit || glfwWindowShouldClose(window) || (options.stop && options.stop->load());
  };
  while (!stopped()) {
    glfwPollEvents();
    const Clock::time_point now = Clock::now();
    if (view.gamepad) {
      padTool(keys, *view.gamepad, std::min(std::chrono::duration<double>(now - lastPad).count(), 0.1));
      lastPad = now;
    }
    if (lockstep) {
      const double left = options.duration - runtime.time();
      if (left <= 1e-12) break;
      double step = 0.0;
      if (!keys.paused)
        step = std::min(std::chrono::duration<double>(now - last).count(), 0.1);
      else if (keys.steps > 0)
        step = frameSeconds, --keys.steps;
      last = now;
      if (step > 0.0) {
        glfwMakeContextCurrent(nullptr);  // the render engine's EGL context ticks here
        if (failed = runtime.advance(std::min(step, left)); !failed) break;
      }
    } else if (std::chrono::duration<double>(now - start).count() >= options.duration) {
      break;
    }
    glfwMakeContextCurrent(window);
    if (runtime.latestFrame(seen, frame, frameTime, &keys.camera)) {
      draw(window, frame);
      glfwSwapBuffers(window);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(lockstep && !keys.paused ? 1 : 10));
  }
  // Ended before its duration (Esc, the window closed, a signal).
  const bool early = lockstep
                         ? runtime.time() < options.duration - 1e-9
                         : std::chrono::duration<double>(Clock::now() - start).count() < options.duration;
  // The last frame once more: into the back buffer for the screenshot.
  glfwMakeContextCurrent(window);
  (void)runtime.latestFrame(seen, frame, frameTime);
  draw(window, frame);
  dm::Status shot = dm::ok();
  if (!view.screenshot.empty()) {
    auto picture = readWindow(window);
    shot = picture ? dm::writePng(*picture, view.screenshot) : dm::Status(picture.error());
  }
  glfwMakeContextCurrent(nullptr);
  glfwDestroyWindow(window);
  auto result = runtime.finish();
  if (!failed) return failed.error();
  if (!shot) return shot.error().within("--screenshot");
  if (result && early && failed) result->interrupted = true;
  return result;
}

}  // namespace dmplatform
