// dm/engine/frame_camera.hpp — the camera a rendered frame was drawn with,
// as a live view needs it to turn a point of the frame into a ray in the
// world (the mouse moving a tool in the view's plane, picking). The render
// engine hands it out with each frame it shows (SceneRuntime::latestFrame).
#pragma once

#include <dm/core/types.hpp>

#include <cmath>
#include <utility>

namespace dm {

struct FrameCamera {
  Vec3 eye = Vec3::Zero();
  Vec3 forward = -Vec3::UnitZ(), right = Vec3::UnitX(), up = Vec3::UnitY();  ///< unit, orthogonal
  bool orthographic = false;
  double tanHalfFovY = 0.41421356237309503;  ///< perspective: tan of half the vertical field of view (45°)
  double orthoHeight = 1.0;                  ///< orthographic: m of world the frame's height shows

  /// The ray through (x, y) of a width × height frame (pixel units from its
  /// top-left corner; a pixel's centre is at +0.5): origin and unit
  /// direction, world.
  std::pair<Vec3, Vec3> ray(double x, double y, int width, int height) const noexcept {
    const double aspect = double(width) / double(height);
    const double u = 2.0 * x / width - 1.0, v = 1.0 - 2.0 * y / height;  // [-1, 1], up positive
    if (orthographic) {
      const double half = 0.5 * orthoHeight;
      return {eye + u * half * aspect * right + v * half * up, forward};
    }
    return {eye, (forward + u * tanHalfFovY * aspect * right + v * tanHalfFovY * up).normalized()};
  }
};

}  // namespace dm
