// dm/io/pointer_device.hpp — "pointer": a kinematic stand-in haptic device
// that the program itself moves (a live view's mouse, a GUI, a script), so
// that a scene can be probed without hardware.
//
// A pointer device reads its pose from a named PointerChannel, process-wide:
// the program writes the position (device frame, m) and buttons with
// set(), the driver's read_state() takes the newest; the velocity is the
// difference of the last two reads over the host's time between them. The
// force the host sends is kept in the channel (force()) for the program to
// show; nothing pushes back, so the hand is where the program puts it
// (kinematic: a god-object or a coupling still renders the contact force).
// The driver is built into DM::IO only (registerBuiltinDrivers): its
// channels live in the program that moves them.
//
// Parameters: channel (name, default "mouse"); workspace (m, half extent of
// the cube it reports, default 0.1; positions are clamped to it);
// max_force (N, default 5); servo_rate (Hz, default 1000).
//
// Threads: set() from one thread (the program's), the driver's read_state
// and write_output from the servo thread, force() from one reader; all
// lock-free (triple buffers). pointerChannel() creates a channel under a
// lock on first use: call it before the run starts.
//
// @code
//   dm::PointerChannel& mouse = dm::pointerChannel("mouse");
//   mouse.set(dm::Vec3(0.01, 0.0, -0.02), /*buttons=*/0);     // UI thread
//   // a scene device {"driver": "pointer"} follows it; mouse.force() is what it felt
// @endcode
#pragma once

#include <dm/core/triple_buffer.hpp>
#include <dm/core/types.hpp>

#include <cstdint>
#include <string>

namespace dm {

/// Where a pointer device is and what it was sent; see the file comment.
class PointerChannel {
 public:
  struct Input {
    Vec3 position = Vec3::Zero();  ///< m, device frame
    std::uint32_t buttons = 0;
  };
  /// The device's next position and buttons (one writer thread).
  void set(const Vec3& position, std::uint32_t buttons) noexcept {
    Input& in = input_.writeBuffer();
    in.position = position;
    in.buttons = buttons;
    input_.publish();
  }
  /// The newest input (the driver's servo thread).
  const Input& input() noexcept { return input_.read(); }
  /// The force the host last sent (N, device frame; one reader thread).
  const Vec3& force() noexcept { return force_.read(); }
  /// Kept by the driver's write_output (the servo thread).
  void sent(const Vec3& f) noexcept {
    force_.writeBuffer() = f;
    force_.publish();
  }

 private:
  TripleBuffer<Input> input_;
  TripleBuffer<Vec3> force_;
};

/// The process-wide channel `name`, created on first use (under a lock;
/// the reference stays valid for the process's life).
PointerChannel& pointerChannel(const std::string& name);

}  // namespace dm
