// live_view.hpp — `dmplatform run --view`: a window that shows a running
// scene's rendered frames as they come (GLFW; the frames are the render
// engine's, drawn 1:1, so the window shows exactly what a headless run
// writes, HUD included).
//
// Keys: Space pauses and resumes the simulation, N (or →) steps it one
// render frame while paused (both lockstep only: a real-time run's
// engines keep their own clocks), Esc or closing the window ends the run
// (its outputs are still written). Mouse: a left drag turns the camera
// about its target, another button's drag pans it, the wheel zooms, R
// puts it back (dm::ViewOrbit; the frames written turn with it; a paused
// run shows a turn at its next step). When the scene's haptic device is a
// "pointer" (dm/io/pointer_device.hpp) the mouse is the tool: the tool
// follows the cursor in the plane through it that faces the view, the wheel
// moves it into the view and back (2 mm a notch), the mouse's buttons are
// the device's, and W A S D move it 2 mm a press up, left, down and right in
// the view, Q and E into the view and back; T switches between this tool mode (the start) and the
// camera mode above. A gamepad given (--gamepad, gamepad.hpp) moves the
// same tool: its sticks give it a velocity in the view, its first two
// buttons are the device's. The HUD shows the force it renders (its magnitude and
// recent plot). In lockstep the virtual clock follows
// the wall clock while the machine keeps up (at most 0.1 s per shown
// frame); in real time the engines run on their threads and the window
// polls the newest frame.
//
// Threads: the window, its GL context and the lockstep engines all on the
// calling thread; the window's context is released while the engines
// tick (the render engine makes its own EGL context current per frame).
#pragma once

#include <dm/core/result.hpp>
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/controller.hpp>

#include <filesystem>

namespace dmplatform {

struct LiveViewOptions {
  /// When set: the window's last picture, written as PNG when the view
  /// closes (a screenshot; tests compare it with the headless frame).
  std::filesystem::path screenshot;
  /// When set: a controller (an evdev gamepad) that moves the pointer
  /// device's tool; polled at every shown frame. The scene's haptic device
  /// must be a pointer.
  dm::Controller* gamepad = nullptr;
};

/// Runs `runtime` (prepared here with `options` and liveFrames) with a
/// window showing its frames, then finishes it: the run's result, or an
/// error (no window system: InvalidArgument naming --view).
dm::Result<dm::SceneRunResult> runWithView(dm::SceneRuntime& runtime, dm::SceneRunOptions options,
                                           const LiveViewOptions& view);

}  // namespace dmplatform
