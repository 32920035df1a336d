// dm/renderer/camera.hpp — cameras: perspective and orthographic projection,
// look-at placement, target tracking, path following and stereo pairs.
//
// World units are metres; the camera looks down its -z axis with +y up (the
// OpenGL convention), clip depth in [-1, 1]. A lens shift (a horizontal
// slope: metres of frustum shift per metre of depth) gives off-axis frusta
// for stereo pairs that converge at a chosen distance without toe-in (no
// vertical parallax).
// Matrices are float (what GL takes), built from double poses.
//
// @code
//   dm::Camera cam = dm::Camera::lookAt({0.3, 0.1, 0.4}, {0, 0, 0});
//   cam.fovYDeg = 40;
//   dm::Mat4f vp = cam.projectionMatrix(16.0 / 9.0) * cam.viewMatrix();
//   auto [left, right] = cam.stereoPair(0.065, 0.5);    // 65 mm eyes, converge at 0.5 m
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <utility>
#include <vector>

namespace dm {

using Mat4f = Eigen::Matrix4f;

/// A pinhole or parallel camera.
struct Camera {
  enum class Projection : unsigned char { Perspective, Orthographic };

  Projection projection = Projection::Perspective;
  Vec3 position{0, 0, 1};   ///< eye, m
  Vec3 target{0, 0, 0};     ///< point looked at, m
  Vec3 up{0, 1, 0};         ///< approximate up; need not be orthogonal to the view direction
  double fovYDeg = 45.0;    ///< perspective: vertical field of view, degrees (0, 180)
  double orthoHeight = 1;   ///< orthographic: visible height, m
  double nearPlane = 0.01;  ///< m, > 0
  double farPlane = 100;    ///< m, > nearPlane
  double lensShiftX = 0;    ///< horizontal frustum shift, m per m of depth (orthographic: m)

  /// A camera at `eye` looking at `at`.
  static Camera lookAt(const Vec3& eye, const Vec3& at, const Vec3& upDir = Vec3(0, 1, 0));

  /// InvalidArgument naming the field when the camera is degenerate (eye on
  /// target, up parallel to the view direction, bad planes or angles).
  Status validate() const;

  /// Unit view direction (target - position).
  Vec3 forward() const;
  /// Unit right vector (forward x up).
  Vec3 right() const;
  /// Camera-to-world rigid transform (camera looks down its -z).
  Isometry3 pose() const;
  /// World-to-camera matrix.
  Mat4f viewMatrix() const;
  /// Projection for a viewport of width/height `aspect` (OpenGL clip space).
  Mat4f projectionMatrix(double aspect) const;
  /// The left and right eye cameras: eyes `eyeSeparation` m apart along
  /// right(), parallel axes, frusta shifted so both images coincide at
  /// `convergence` m (zero parallax there). Perspective cameras only.
  std::pair<Camera, Camera> stereoPair(double eyeSeparation, double convergence) const;
  /// The same camera keeping its offset from the target but re-aimed at
  /// `newTarget` (target tracking: the camera follows a moving object).
  Camera tracking(const Vec3& newTarget) const;
};

/// One key of a camera path.
struct CameraKey {
  double time = 0;  ///< s, strictly increasing along a path
  Vec3 position{0, 0, 1};
  Vec3 target{0, 0, 0};
};

/// Eye and target positions interpolated along keys by a centripetal
/// Catmull–Rom spline (C1, no overshoot loops), clamped at both ends.
class CameraPath {
 public:
  /// Fails when fewer than 2 keys or times do not strictly increase.
  static Result<CameraPath> create(std::vector<CameraKey> keys);
  /// `base` with position and target at time `t` (s).
  Camera at(const Camera& base, double t) const;
  double duration() const { return keys_.back().time - keys_.front().time; }

 private:
  std::vector<CameraKey> keys_;
};

/// Projects a world point with a view-projection matrix to pixel coordinates
/// (origin top-left, y down) of a width x height viewport; z is window depth
/// in [0, 1]. Returns false for points behind the camera.
bool projectToPixel(const Mat4f& viewProjection, const Vec3& world, int width, int height, Vec3& pixel);

}  // namespace dm
