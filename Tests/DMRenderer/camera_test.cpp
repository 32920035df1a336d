// Cameras against the pinhole model: projections, stereo parallax, paths.
#include <dm/renderer/camera.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <tuple>

namespace {

dm::Mat4f viewProj(const dm::Camera& c, double aspect) { return c.projectionMatrix(aspect) * c.viewMatrix(); }

}  // namespace

TEST(Camera, PerspectiveProjectsLikeAPinhole) {
  dm::Camera cam = dm::Camera::lookAt({0, 0, 1}, {0, 0, 0});
  cam.fovYDeg = 60;
  const int w = 400, h = 200;
  const double f = (h / 2.0) / std::tan(30.0 * std::numbers::pi / 180.0);  // focal length in pixels
  dm::Vec3 px;
  // A point 0.1 m right and 0.05 m up on the target plane (1 m away).
  ASSERT_TRUE(dm::projectToPixel(viewProj(cam, double(w) / h), {0.1, 0.05, 0}, w, h, px));
  EXPECT_NEAR(px.x(), w / 2.0 + f * 0.1, 1e-3);
  EXPECT_NEAR(px.y(), h / 2.0 - f * 0.05, 1e-3);
  EXPECT_GT(px.z(), 0);
  EXPECT_LT(px.z(), 1);
  // Behind the camera.
  EXPECT_FALSE(dm::projectToPixel(viewProj(cam, 2.0), {0, 0, 2}, w, h, px));
}

TEST(Camera, DepthIsMonotoneBetweenNearAndFar) {
  dm::Camera cam = dm::Camera::lookAt({0, 0, 0}, {0, 0, -1});
  cam.nearPlane = 0.1;
  cam.farPlane = 10;
  dm::Vec3 a, b, n, fa;
  ASSERT_TRUE(dm::projectToPixel(viewProj(cam, 1), {0, 0, -0.1}, 10, 10, n));
  ASSERT_TRUE(dm::projectToPixel(viewProj(cam, 1), {0, 0, -1}, 10, 10, a));
  ASSERT_TRUE(dm::projectToPixel(viewProj(cam, 1), {0, 0, -5}, 10, 10, b));
  ASSERT_TRUE(dm::projectToPixel(viewProj(cam, 1), {0, 0, -10}, 10, 10, fa));
  EXPECT_NEAR(n.z(), 0.0, 1e-5);
  EXPECT_NEAR(fa.z(), 1.0, 1e-5);
  EXPECT_LT(a.z(), b.z());
}

TEST(Camera, OrthographicKeepsSizeAtAnyDepth) {
  dm::Camera cam = dm::Camera::lookAt({0, 0, 1}, {0, 0, 0});
  cam.projection = dm::Camera::Projection::Orthographic;
  cam.orthoHeight = 0.5;  // 200 px tall -> 400 px/m
  dm::Vec3 p1, p2;
  ASSERT_TRUE(dm::projectToPixel(viewProj(cam, 1), {0.1, 0, 0.5}, 200, 200, p1));
  ASSERT_TRUE(dm::projectToPixel(viewProj(cam, 1), {0.1, 0, -0.5}, 200, 200, p2));
  EXPECT_NEAR(p1.x(), 100 + 40, 1e-3);
  EXPECT_NEAR(p2.x(), 100 + 40, 1e-3);
}

TEST(Camera, PoseIsRigidAndLooksAtTheTarget) {
  dm::Camera cam = dm::Camera::lookAt({0.3, 0.2, -0.4}, {0.01, -0.02, 0.03}, {0, 0, 1});
  const dm::Isometry3 T = cam.pose();
  EXPECT_NEAR((T.linear().transpose() * T.linear() - dm::Mat3::Identity()).norm(), 0, 1e-12);
  EXPECT_NEAR(T.linear().determinant(), 1, 1e-12);
  // The target lies on the camera's -z axis.
  const dm::Vec3 local = T.inverse() * cam.target;
  EXPECT_NEAR(local.x(), 0, 1e-12);
  EXPECT_NEAR(local.y(), 0, 1e-12);
  EXPECT_LT(local.z(), 0);
}

TEST(Camera, StereoPairHasZeroParallaxAtConvergenceAndCrossedParallaxNearer) {
  dm::Camera cam = dm::Camera::lookAt({0, 0, 1}, {0, 0, 0});
  cam.fovYDeg = 40;
  const double e = 0.065, c = 1.0;
  // Named references, not a structured binding: clang 14 cannot capture one.
  const auto stereo = cam.stereoPair(e, c);
  const auto& left = std::get<0>(stereo);
  const auto& right = std::get<1>(stereo);
  EXPECT_NEAR((right.position - left.position).norm(), e, 1e-12);
  const int w = 320, h = 240;
  auto disparity = [&](const dm::Vec3& p) {
    dm::Vec3 l, r;
    EXPECT_TRUE(dm::projectToPixel(viewProj(left, double(w) / h), p, w, h, l));
    EXPECT_TRUE(dm::projectToPixel(viewProj(right, double(w) / h), p, w, h, r));
    EXPECT_NEAR(l.y(), r.y(), 1e-3);  // no vertical parallax (no toe-in)
    return r.x() - l.x();
  };
  EXPECT_NEAR(disparity({0, 0, 0}), 0, 1e-3);
  EXPECT_NEAR(disparity({0.05, 0.03, 0}), 0, 1e-3);  // the whole convergence plane
  // A point at distance z: disparity = f * e * (1/c - 1/z), negative (crossed) when nearer.
  const double f = (h / 2.0) / std::tan(20.0 * std::numbers::pi / 180.0);
  const double z = 0.5;
  EXPECT_NEAR(disparity({0, 0, 1 - z}), -f * e * (1 / z - 1 / c), 1e-2);
}

TEST(Camera, TrackingKeepsTheOffset) {
  dm::Camera cam = dm::Camera::lookAt({0.1, 0.2, 0.3}, {0, 0, 0});
  dm::Camera t = cam.tracking({1, 2, 3});
  EXPECT_TRUE((t.position - t.target).isApprox(cam.position - cam.target));
  EXPECT_TRUE(t.target.isApprox(dm::Vec3(1, 2, 3)));
}

TEST(Camera, ValidateNamesTheBadField) {
  dm::Camera cam = dm::Camera::lookAt({0, 0, 0}, {0, 0, 0});
  EXPECT_EQ(cam.validate().error().where, "camera.position");
  cam = dm::Camera::lookAt({0, 1, 0}, {0, 0, 0});  // up parallel to view
  EXPECT_EQ(cam.validate().error().where, "camera.up");
  cam = dm::Camera::lookAt({0, 0, 1}, {0, 0, 0});
  cam.nearPlane = 0;
  EXPECT_EQ(cam.validate().error().where, "camera.near");
  cam.nearPlane = 0.1;
  cam.fovYDeg = 180;
  EXPECT_EQ(cam.validate().error().where, "camera.fov_y_deg");
  cam.fovYDeg = 45;
  EXPECT_TRUE(cam.validate());
}

TEST(CameraPath, PassesThroughKeysAndClampsAtTheEnds) {
  std::vector<dm::CameraKey> keys = {{0, {1, 0, 0}, {0, 0, 0}},
                                     {1, {0, 1, 0}, {0, 0, 0}},
                                     {2, {-1, 0, 0}, {0, 0.1, 0}},
                                     {4, {0, -1, 0}, {0, 0, 0}}};
  auto path = dm::CameraPath::create(keys);
  ASSERT_TRUE(path) << path.error();
  dm::Camera base;
  for (const auto& k : keys) {
    const dm::Camera c = path->at(base, k.time);
    EXPECT_LT((c.position - k.position).norm(), 1e-9) << k.time;
    EXPECT_LT((c.target - k.target).norm(), 1e-9) << k.time;
  }
  EXPECT_TRUE(path->at(base, -5).position.isApprox(keys.front().position));
  EXPECT_TRUE(path->at(base, 50).position.isApprox(keys.back().position));
  EXPECT_DOUBLE_EQ(path->duration(), 4.0);
  // Continuity: no jump across a key.
  const dm::Vec3 before = path->at(base, 1 - 1e-6).position, after = path->at(base, 1 + 1e-6).position;
  EXPECT_LT((before - after).norm(), 1e-4);
  // Between inner keys on a unit circle the spline bulges out of the chord
  // (midpoint norm 0.707) towards the circle; uniform Catmull-Rom gives 0.884.
  const double r = path->at(base, 1.5).position.norm();
  EXPECT_GT(r, 0.85);
  EXPECT_LT(r, 1.0);
}

TEST(CameraPath, RefusesTooFewOrUnorderedKeys) {
  EXPECT_FALSE(dm::CameraPath::create({{0, {0, 0, 1}, {0, 0, 0}}}));
  auto bad = dm::CameraPath::create({{0, {0, 0, 1}, {0, 0, 0}}, {0, {0, 0, 2}, {0, 0, 0}}});
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().where, "camera.path[1].t");
}
