// frame_slot.hpp (private) — the newest rendered frame, handed from the
// render engine to an engine that streams it (the OpenIGTLink engine). Both
// sides are non-real-time engine threads: a mutex, one frame held. A frame
// is never written once put (each read-back is a new image; dm::Image
// copies share the pixels), so both sides hold it without copying pixels.
#pragma once

#include <dm/core/image.hpp>
#include <dm/engine/frame_camera.hpp>

#include <cstdint>
#include <mutex>

namespace dm {

class FrameSlot {
 public:
  /// Render thread: the frame rendered at scene time `t` (with `camera`)
  /// replaces the held one.
  void put(const Image& frame, double t, const FrameCamera& camera = {}) {
    std::lock_guard lock(m_);
    frame_ = frame;
    t_ = t;
    camera_ = camera;
    ++sequence_;
  }
  /// Reader: the held frame (shared) and its time when it is newer than
  /// the one `seen` numbers (then `seen` is updated); false otherwise.
  bool takeIfNewer(std::uint64_t& seen, Image& out, double& t, FrameCamera* camera = nullptr) {
    std::lock_guard lock(m_);
    if (sequence_ == seen) return false;
    seen = sequence_;
    out = frame_;
    t = t_;
    if (camera) *camera = camera_;
    return true;
  }

 private:
  std::mutex m_;
  Image frame_;
  double t_ = 0.0;
  FrameCamera camera_;
  std::uint64_t sequence_ = 0;
};

}  // namespace dm
