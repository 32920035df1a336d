// gamepad.hpp — a gamepad as the tool of `dmplatform run --view` (a scene
// whose haptic device is a "pointer"): the sticks give the tool a
// velocity in the view, the pad's first two buttons are the device's.
//
// Axes as evdev-controller reports them (ABS_X, ABS_Y, ABS_Z, ABS_RX,
// ABS_RY, ABS_RZ → 0..5, each in [-1, 1]; a stick pushed right or down is
// positive): the left stick (0, 1) moves the tool right/left and up/down
// in the view, the right stick's vertical (4) into the view (pushed away)
// and back, at up to kGamepadSpeed; a stick within kGamepadDeadZone of its
// centre (where worn sticks rest) moves nothing, and the speed grows
// linearly from there to full deflection.
#pragma once

#include <dm/engine/frame_camera.hpp>
#include <dm/io/controller.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace dmplatform {

inline constexpr double kGamepadSpeed = 0.05;     ///< m/s at full deflection
inline constexpr double kGamepadDeadZone = 0.15;  ///< of the axis range, around its centre

/// An axis past the dead zone, rescaled to [-1, 1].
inline double gamepadAxis(double value) {
  const double v = std::clamp(value, -1.0, 1.0);
  if (std::abs(v) <= kGamepadDeadZone) return 0.0;
  return std::copysign((std::abs(v) - kGamepadDeadZone) / (1.0 - kGamepadDeadZone), v);
}

/// The tool's velocity (m/s, world) the pad asks for, in the frame of the
/// camera shown.
inline dm::Vec3 gamepadVelocity(const dm::ControllerState& pad, const dm::FrameCamera& camera) {
  return kGamepadSpeed * (gamepadAxis(pad.axes[0]) * camera.right - gamepadAxis(pad.axes[1]) * camera.up -
                          gamepadAxis(pad.axes[4]) * camera.forward);
}

/// The device buttons the pad holds: its buttons 0 and 1 as bits 0 and 1.
inline std::uint32_t gamepadButtons(const dm::ControllerState& pad) {
  return (pad.buttons[0] ? 1u : 0u) | (pad.buttons[1] ? 2u : 0u);
}

}  // namespace dmplatform
