// camera.cpp — view/projection matrices, stereo pairs, camera paths.
#include <dm/renderer/camera.hpp>

#include <cmath>
#include <numbers>

namespace dm {

Camera Camera::lookAt(const Vec3& eye, const Vec3& at, const Vec3& upDir) {
  Camera c;
  c.position = eye;
  c.target = at;
  c.up = upDir;
  return c;
}

Status Camera::validate() const {
  const Vec3 f = target - position;
  if (!f.allFinite() || f.norm() < 1e-12)
    return fail(ErrorCode::InvalidArgument, "camera position equals its target", "camera.position",
                "place the camera away from what it looks at");
  if (!up.allFinite() || f.normalized().cross(up).norm() < 1e-9 * std::max(1.0, up.norm()))
    return fail(ErrorCode::InvalidArgument, "camera up is parallel to the view direction (or zero)",
                "camera.up", "pick an up vector across the view direction");
  if (!(nearPlane > 0) || !(farPlane > nearPlane))
    return fail(ErrorCode::InvalidArgument, formatString("near %g, far %g", nearPlane, farPlane),
                "camera.near", "need 0 < near < far");
  if (projection == Projection::Perspective && !(fovYDeg > 0 && fovYDeg < 180))
    return fail(ErrorCode::InvalidArgument, formatString("fov_y_deg is %g", fovYDeg), "camera.fov_y_deg",
                "use an angle in (0, 180)");
  if (projection == Projection::Orthographic && !(orthoHeight > 0))
    return fail(ErrorCode::InvalidArgument, formatString("ortho_height is %g", orthoHeight),
                "camera.ortho_height", "use a positive height in metres");
  return ok();
}

Vec3 Camera::forward() const { return (target - position).normalized(); }

Vec3 Camera::right() const { return forward().cross(up).normalized(); }

Isometry3 Camera::pose() const {
  const Vec3 f = forward();
  const Vec3 r = f.cross(up).normalized();
  const Vec3 u = r.cross(f);
  Isometry3 T = Isometry3::Identity();
  T.linear().col(0) = r;
  T.linear().col(1) = u;
  T.linear().col(2) = -f;
  T.translation() = position;
  return T;
}

Mat4f Camera::viewMatrix() const { return pose().inverse().matrix().cast<float>(); }

Mat4f Camera::projectionMatrix(double aspect) const {
  const double n = nearPlane, f = farPlane;
  Eigen::Matrix4d P = Eigen::Matrix4d::Zero();
  if (projection == Projection::Perspective) {
    const double top = n * std::tan(fovYDeg * std::numbers::pi / 360.0);
    const double halfW = top * aspect;
    const double shift = lensShiftX * n;
    const double l = -halfW + shift, r = halfW + shift, b = -top, t = top;
    P(0, 0) = 2 * n / (r - l);
    P(0, 2) = (r + l) / (r - l);
    P(1, 1) = 2 * n / (t - b);
    P(1, 2) = (t + b) / (t - b);
    P(2, 2) = -(f + n) / (f - n);
    P(2, 3) = -2 * f * n / (f - n);
    P(3, 2) = -1;
  } else {
    const double t = orthoHeight / 2, halfW = t * aspect;
    const double shift = lensShiftX;
    const double l = -halfW + shift, r = halfW + shift;
    P(0, 0) = 2 / (r - l);
    P(0, 3) = -(r + l) / (r - l);
    P(1, 1) = 1 / t;
    P(2, 2) = -2 / (f - n);
    P(2, 3) = -(f + n) / (f - n);
    P(3, 3) = 1;
  }
  return P.cast<float>();
}

std::pair<Camera, Camera> Camera::stereoPair(double eyeSeparation, double convergence) const {
  const Vec3 r = right();
  const Vec3 d = target - position;
  Camera left = *this, rightEye = *this;
  left.position = position - 0.5 * eyeSeparation * r;
  left.target = left.position + d;
  rightEye.position = position + 0.5 * eyeSeparation * r;
  rightEye.target = rightEye.position + d;
  // A point on the axis at distance `convergence` sits at x = +-e/2 in each
  // eye's frame (+ for the left eye); shifting each frustum by the slope
  // e/2 / c puts it at the centre of both images.
  const double slope = 0.5 * eyeSeparation / convergence;
  left.lensShiftX = lensShiftX + slope;
  rightEye.lensShiftX = lensShiftX - slope;
  return {left, rightEye};
}

Camera Camera::tracking(const Vec3& newTarget) const {
  Camera c = *this;
  c.position = newTarget + (position - target);
  c.target = newTarget;
  return c;
}

Result<CameraPath> CameraPath::create(std::vector<CameraKey> keys) {
  if (keys.size() < 2)
    return fail(ErrorCode::InvalidArgument, formatString("%zu camera path keys", keys.size()), "camera.path",
                "give at least 2 keys");
  for (std::size_t i = 1; i < keys.size(); ++i)
    if (!(keys[i].time > keys[i - 1].time))
      return fail(ErrorCode::InvalidArgument,
                  formatString("key %zu time %g is not after %g", i, keys[i].time, keys[i - 1].time),
                  formatString("camera.path[%zu].t", i), "times must strictly increase");
  CameraPath p;
  p.keys_ = std::move(keys);
  return p;
}

namespace {

// Centripetal Catmull–Rom between p1 and p2 (Barry–Goldman pyramid), u in [0, 1].
Vec3 catmullRom(const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec3& p3, double u) {
  auto knot = [](double t, const Vec3& a, const Vec3& b) {
    return t + std::max(std::sqrt((b - a).norm()), 1e-9);
  };
  const double t0 = 0, t1 = knot(t0, p0, p1), t2 = knot(t1, p1, p2), t3 = knot(t2, p2, p3);
  const double t = t1 + u * (t2 - t1);
  const Vec3 a1 = (t1 - t) / (t1 - t0) * p0 + (t - t0) / (t1 - t0) * p1;
  const Vec3 a2 = (t2 - t) / (t2 - t1) * p1 + (t - t1) / (t2 - t1) * p2;
  const Vec3 a3 = (t3 - t) / (t3 - t2) * p2 + (t - t2) / (t3 - t2) * p3;
  const Vec3 b1 = (t2 - t) / (t2 - t0) * a1 + (t - t0) / (t2 - t0) * a2;
  const Vec3 b2 = (t3 - t) / (t3 - t1) * a2 + (t - t1) / (t3 - t1) * a3;
  return (t2 - t) / (t2 - t1) * b1 + (t - t1) / (t2 - t1) * b2;
}

}  // namespace

Camera CameraPath::at(const Camera& base, double t) const {
  Camera c = base;
  if (t <= keys_.front().time) {
    c.position = keys_.front().position;
    c.target = keys_.front().target;
    return c;
  }
  if (t >= keys_.back().time) {
    c.position = keys_.back().position;
    c.target = keys_.back().target;
    return c;
  }
  std::size_t i = 0;
  while (keys_[i + 1].time < t) ++i;
  const std::size_t n = keys_.size();
  const CameraKey& k0 = keys_[i == 0 ? 0 : i - 1];
  const CameraKey& k1 = keys_[i];
  const CameraKey& k2 = keys_[i + 1];
  const CameraKey& k3 = keys_[std::min(i + 2, n - 1)];
  const double u = (t - k1.time) / (k2.time - k1.time);
  // End segments reflect the missing neighbour so the curve stays C1.
  auto ext = [](const Vec3& a, const Vec3& b) -> Vec3 { return 2 * a - b; };
  const Vec3 p0 = i == 0 ? ext(k1.position, k2.position) : k0.position;
  const Vec3 p3 = i + 2 >= n ? ext(k2.position, k1.position) : k3.position;
  const Vec3 q0 = i == 0 ? ext(k1.target, k2.target) : k0.target;
  const Vec3 q3 = i + 2 >= n ? ext(k2.target, k1.target) : k3.target;
  c.position = catmullRom(p0, k1.position, k2.position, p3, u);
  c.target = catmullRom(q0, k1.target, k2.target, q3, u);
  return c;
}

bool projectToPixel(const Mat4f& viewProjection, const Vec3& world, int width, int height, Vec3& pixel) {
  const Eigen::Vector4f clip =
      viewProjection * Eigen::Vector4f(float(world.x()), float(world.y()), float(world.z()), 1.f);
  if (clip.w() <= 0) return false;
  const Eigen::Vector3f ndc = clip.head<3>() / clip.w();
  pixel = Vec3((ndc.x() * 0.5 + 0.5) * width, (0.5 - ndc.y() * 0.5) * height, ndc.z() * 0.5 + 0.5);
  return true;
}

}  // namespace dm
