// Tests of dm/collide/mesh_query.hpp against brute force over all triangle
// pairs (booleans identical, distances to 1e-12 relative) at random,
// touching and near-miss poses, and against FCL (BVHModel<OBBRSSd>) for
// mesh–mesh boolean and distance.
#include <dm/collide/mesh_query.hpp>
#include <dm/collide/triangle.hpp>
#include <dm/math/geometry.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <fcl/fcl.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <set>
#include <utility>
#include <vector>

namespace {

using dm::Isometry3;
using dm::Vec3;

dm::Mesh soup(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  dm::Mesh m;
  for (std::size_t t = 0; t < n; ++t) {
    const Vec3 c = 0.7 * Vec3(u(rng), u(rng), u(rng));
    const auto base = static_cast<std::uint32_t>(m.positions.size());
    for (int k = 0; k < 3; ++k) m.positions.push_back(c + 0.25 * Vec3(u(rng), u(rng), u(rng)));
    m.triangles.push_back({base, base + 1, base + 2});
  }
  return m;
}

Isometry3 randomMeshPose(std::mt19937_64& rng, double spread) {
  std::uniform_real_distribution<double> u(-1, 1);
  Isometry3 p = Isometry3::Identity();
  p.linear() = dm::Quat(Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng)).normalized()).toRotationMatrix();
  p.translation() = spread * Vec3(u(rng), u(rng), u(rng));
  return p;
}

// Brute force in A's frame, with B mapped exactly as the queries do.
struct Brute {
  const dm::Mesh& a;
  const dm::Mesh& b;
  std::vector<Vec3> mapped;
  void setPoses(const Isometry3& pa, const Isometry3& pb) {
    const Isometry3 m = pa.inverse(Eigen::Isometry) * pb;
    const dm::Mat3 r = m.linear();
    const Vec3 t = m.translation();
    mapped.resize(b.positions.size());
    for (std::size_t i = 0; i < mapped.size(); ++i) mapped[i] = r * b.positions[i] + t;
  }
  const Vec3& pa(std::size_t t, int c) const { return a.positions[a.triangles[t][c]]; }
  const Vec3& pb(std::size_t t, int c) const { return mapped[b.triangles[t][c]]; }
  // Disjoint corner boxes cannot intersect (exact, and it keeps the sweep fast).
  bool boxesApart(std::size_t i, std::size_t j) const {
    const Vec3 loA = pa(i, 0).cwiseMin(pa(i, 1)).cwiseMin(pa(i, 2)),
               hiA = pa(i, 0).cwiseMax(pa(i, 1)).cwiseMax(pa(i, 2));
    const Vec3 loB = pb(j, 0).cwiseMin(pb(j, 1)).cwiseMin(pb(j, 2)),
               hiB = pb(j, 0).cwiseMax(pb(j, 1)).cwiseMax(pb(j, 2));
    return (loA.array() > hiB.array()).any() || (loB.array() > hiA.array()).any();
  }
  bool intersect() const {
    for (std::size_t i = 0; i < a.triangleCount(); ++i)
      for (std::size_t j = 0; j < b.triangleCount(); ++j)
        if (!boxesApart(i, j) &&
            dm::trianglesIntersect(pa(i, 0), pa(i, 1), pa(i, 2), pb(j, 0), pb(j, 1), pb(j, 2)))
          return true;
    return false;
  }
  std::set<std::pair<std::uint32_t, std::uint32_t>> pairs() const {
    std::set<std::pair<std::uint32_t, std::uint32_t>> s;
    for (std::uint32_t i = 0; i < a.triangleCount(); ++i)
      for (std::uint32_t j = 0; j < b.triangleCount(); ++j)
        if (dm::trianglesIntersect(pa(i, 0), pa(i, 1), pa(i, 2), pb(j, 0), pb(j, 1), pb(j, 2)))
          s.insert({i, j});
    return s;
  }
  dm::TriangleDistance distance() const {
    dm::TriangleDistance best;
    best.distance = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < a.triangleCount(); ++i)
      for (std::size_t j = 0; j < b.triangleCount(); ++j) {
        const dm::TriangleDistance d =
            dm::triangleDistance(pa(i, 0), pa(i, 1), pa(i, 2), pb(j, 0), pb(j, 1), pb(j, 2));
        if (d.distance < best.distance) best = d;
      }
    return best;
  }
};

dm::MeshBvh bvhOf(const dm::Mesh& m) {
  auto b = dm::MeshBvh::build(m);
  EXPECT_TRUE(b) << (b ? "" : b.error().message());
  return std::move(*b);
}

void expectOnMesh(const Vec3& world, const dm::Mesh& m, const Isometry3& pose, std::uint32_t tri,
                  double tol) {
  const Vec3 local = pose.inverse(Eigen::Isometry) * world;
  const auto& t = m.triangles[tri];
  EXPECT_LT(
      std::sqrt(dm::closestPointOnTriangle(local, m.positions[t[0]], m.positions[t[1]], m.positions[t[2]])
                    .distanceSq),
      tol);
}

// Random poses, then the same poses moved along the closest-point direction
// to touching (up to rounding) and to ±1e-9 m near misses / overlaps.
void checkPair(const dm::Mesh& ma, const dm::Mesh& mb, std::uint64_t seed, int booleanPoses,
               int distancePoses, double spread = 1.0) {
  const dm::MeshBvh a = bvhOf(ma), b = bvhOf(mb);
  Brute brute{ma, mb, {}};
  std::mt19937_64 rng(seed);
  int hits = 0;
  for (int i = 0; i < booleanPoses; ++i) {
    const Isometry3 pa = randomMeshPose(rng, 0.5), pb = randomMeshPose(rng, spread);
    brute.setPoses(pa, pb);
    const bool ref = brute.intersect();
    hits += ref;
    ASSERT_EQ(dm::meshMeshIntersect(a, pa, b, pb), ref) << "pose " << i;
  }
  EXPECT_GT(hits, booleanPoses / 10);
  EXPECT_LT(hits, booleanPoses * 9 / 10);
  for (int i = 0; i < distancePoses; ++i) {
    const Isometry3 pa = randomMeshPose(rng, 0.5);
    Isometry3 pb = randomMeshPose(rng, 2.0);
    brute.setPoses(pa, pb);
    const dm::TriangleDistance ref = brute.distance();
    if (ref.distance == 0) continue;
    const Vec3 dir = pa.linear() * (ref.pointB - ref.pointA) / ref.distance;  // world
    for (double delta : {-1e-9, 0.0, 1e-9, 1e-3}) {
      Isometry3 moved = pb;
      moved.translation() -= (ref.distance - delta) * dir;
      brute.setPoses(pa, moved);
      const dm::TriangleDistance r = brute.distance();
      const dm::MeshDistance d = dm::meshMeshDistance(a, pa, b, moved);
      ASSERT_NEAR(d.distance, r.distance, 1e-12 * std::max(r.distance, 1e-9))
          << "pose " << i << " delta " << delta;
      // Exact booleans equal brute force; a rounded distance of 0 may still
      // belong to a pair the exact test finds apart, never the converse.
      const bool hit = dm::meshMeshIntersect(a, pa, b, moved);
      ASSERT_EQ(hit, brute.intersect()) << "pose " << i << " delta " << delta;
      if (hit) {
        ASSERT_EQ(d.distance, 0.0);
      }
      EXPECT_NEAR((d.pointA - d.pointB).norm(), d.distance, 1e-12);
      expectOnMesh(d.pointA, ma, pa, d.triangleA, 1e-12);
      expectOnMesh(d.pointB, mb, moved, d.triangleB, 1e-12);
      // Pruned search: maxDistance below the answer finds nothing.
      if (r.distance > 1e-6) {
        EXPECT_EQ(dm::meshMeshDistance(a, pa, b, moved, 0.5 * r.distance).triangleA, dm::kNoTriangle);
      }
    }
  }
}

TEST(MeshQuery, SphereTorusMatchBruteForce) {
  checkPair(dm::makeUvSphere(0.6, 6, 8), dm::makeTorus(0.6, 0.2, 12, 6), 1, 600, 20);
}
TEST(MeshQuery, TorusSoupMatchBruteForce) {
  checkPair(dm::makeTorus(0.5, 0.15, 10, 6), soup(100, 5), 2, 600, 20);
}
TEST(MeshQuery, SoupSoupMatchBruteForce) { checkPair(soup(120, 8), soup(90, 9), 3, 600, 20, 2.0); }

TEST(MeshQuery, ScaledMeshesMatchBruteForce) {
  for (double s : {1e-4, 1e4}) {
    dm::Mesh a = dm::makeUvSphere(0.6 * s, 5, 7), b = soup(60, 4);
    for (auto& p : b.positions) p *= s;
    const dm::MeshBvh ba = bvhOf(a), bb = bvhOf(b);
    Brute brute{a, b, {}};
    std::mt19937_64 rng(17);
    for (int i = 0; i < 400; ++i) {
      const Isometry3 pa = randomMeshPose(rng, 0.5 * s), pb = randomMeshPose(rng, s);
      brute.setPoses(pa, pb);
      ASSERT_EQ(dm::meshMeshIntersect(ba, pa, bb, pb), brute.intersect());
      if (i % 10 == 0) {
        const double ref = brute.distance().distance;
        ASSERT_NEAR(dm::meshMeshDistance(ba, pa, bb, pb).distance, ref, 1e-12 * std::max(ref, 1e-9 * s));
      }
    }
  }
}

std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> fclModel(const dm::Mesh& m) {
  auto model = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  std::vector<fcl::Vector3d> v(m.positions.begin(), m.positions.end());
  std::vector<fcl::Triangle> t;
  for (const auto& tri : m.triangles) t.emplace_back(tri[0], tri[1], tri[2]);
  model->beginModel();
  model->addSubModel(v, t);
  model->endModel();
  return model;
}

TEST(MeshQuery, MatchesFclBooleanAndDistance) {
  const dm::Mesh ma = dm::makeUvSphere(0.5, 12, 16), mb = dm::makeTorus(0.6, 0.2, 24, 12);
  const dm::MeshBvh a = bvhOf(ma), b = bvhOf(mb);
  auto fa = fclModel(ma), fb = fclModel(mb);
  std::mt19937_64 rng(23);
  int compared = 0, collided = 0;
  for (int i = 0; i < 400; ++i) {
    const Isometry3 pa = randomMeshPose(rng, 0.5), pb = randomMeshPose(rng, 1.5);
    fcl::CollisionObjectd oa(fa, pa), ob(fb, pb);
    fcl::CollisionRequestd creq;
    fcl::CollisionResultd cres;
    fcl::collide(&oa, &ob, creq, cres);
    const bool ours = dm::meshMeshIntersect(a, pa, b, pb);
    const dm::MeshDistance d = dm::meshMeshDistance(a, pa, b, pb);
    ASSERT_EQ(ours, d.distance == 0);
    if (d.distance > 1e-9) {
      ASSERT_FALSE(cres.isCollision()) << i;
      fcl::DistanceRequestd dreq(true);
      fcl::DistanceResultd dres;
      fcl::distance(&oa, &ob, dreq, dres);
      ASSERT_NEAR(d.distance, dres.min_distance, 1e-9 * dres.min_distance) << i;
      ++compared;
    } else {
      ASSERT_TRUE(cres.isCollision()) << i;
      ++collided;
    }
  }
  EXPECT_GT(compared, 50);
  EXPECT_GT(collided, 50);
}

TEST(MeshQuery, ContactsAreTheIntersectingPairs) {
  const dm::Mesh ma = dm::makeUvSphere(0.6, 8, 10), mb = dm::makeTorus(0.6, 0.2, 14, 7);
  const dm::MeshBvh a = bvhOf(ma), b = bvhOf(mb);
  Brute brute{ma, mb, {}};
  std::mt19937_64 rng(31);
  std::vector<dm::MeshContact> contacts;
  int withContacts = 0;
  for (int i = 0; i < 150; ++i) {
    const Isometry3 pa = randomMeshPose(rng, 0.3), pb = randomMeshPose(rng, 0.6);
    brute.setPoses(pa, pb);
    const auto ref = brute.pairs();
    const std::size_t n = dm::meshMeshContacts(a, pa, b, pb, contacts);
    ASSERT_EQ(n, contacts.size());
    std::set<std::pair<std::uint32_t, std::uint32_t>> got;
    for (const dm::MeshContact& c : contacts) {
      got.insert({c.triangleA, c.triangleB});
      EXPECT_NEAR(c.normal.norm(), 1.0, 1e-12);
      EXPECT_GE(c.depth, 0.0);
      EXPECT_LT(c.depth, 0.5);  // bounded by the triangle sizes
      expectOnMesh(c.position, ma, pa, c.triangleA, 1e-9);
      expectOnMesh(c.position, mb, pb, c.triangleB, 1e-9);
      expectOnMesh(c.segment[0], ma, pa, c.triangleA, 1e-9);
      expectOnMesh(c.segment[1], mb, pb, c.triangleB, 1e-9);
    }
    ASSERT_EQ(got, ref) << "pose " << i;
    if (!ref.empty()) {
      ++withContacts;
      EXPECT_EQ(dm::meshMeshContacts(a, pa, b, pb, contacts, 1), 1u);
    }
  }
  EXPECT_GT(withContacts, 30);
}

// Winding number of a closed mesh around p (1 inside, 0 outside), by solid angles.
double winding(const dm::Mesh& m, const Vec3& p) {
  double w = 0;
  for (const auto& t : m.triangles) {
    const Vec3 a = m.positions[t[0]] - p, b = m.positions[t[1]] - p, c = m.positions[t[2]] - p;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    w += 2 * std::atan2(a.dot(b.cross(c)), la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb);
  }
  return w / (4 * std::numbers::pi);
}

TEST(MeshQuery, SignedPointDistanceMatchesBruteForceAndWinding) {
  for (const dm::Mesh& m : {dm::makeUvSphere(0.5, 10, 14), dm::makeTorus(0.5, 0.2, 20, 10), soup(200, 12)}) {
    const dm::MeshBvh bvh = bvhOf(m);
    const bool closed = bvh.isClosed();
    EXPECT_EQ(closed, m.triangleCount() != 200);
    std::mt19937_64 rng(41);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int i = 0; i < 1500; ++i) {
      const Isometry3 pose = randomMeshPose(rng, 0.2);
      const Vec3 q = 0.9 * Vec3(u(rng), u(rng), u(rng));
      const dm::MeshPointQuery r = dm::closestPointOnMesh(bvh, pose, q);
      const Vec3 local = pose.inverse(Eigen::Isometry) * q;
      double best = 1e300;
      for (const auto& t : m.triangles)
        best = std::min(
            best, dm::closestPointOnTriangle(local, m.positions[t[0]], m.positions[t[1]], m.positions[t[2]])
                      .distanceSq);
      ASSERT_NEAR(std::abs(r.distance), std::sqrt(best), 1e-12 * std::sqrt(best) + 1e-15);
      EXPECT_NEAR((r.point - q).norm(), std::abs(r.distance), 1e-12);
      expectOnMesh(r.point, m, pose, r.triangle, 1e-12);
      if (closed) {
        const bool inside = winding(m, local) > 0.5;
        if (std::abs(r.distance) > 1e-9) {
          EXPECT_EQ(r.distance < 0, inside) << i;
        }
      } else {
        EXPECT_GE(r.distance, 0.0);
      }
    }
  }
}

TEST(MeshQuery, RaycastMatchesBruteForce) {
  const dm::Mesh m = dm::makeTorus(0.5, 0.2, 20, 10);
  const dm::MeshBvh bvh = bvhOf(m);
  std::mt19937_64 rng(43);
  std::uniform_real_distribution<double> u(-1, 1);
  int hits = 0;
  for (int i = 0; i < 3000; ++i) {
    const Isometry3 pose = randomMeshPose(rng, 0.2);
    const Vec3 o = 1.5 * Vec3(u(rng), u(rng), u(rng)), dir = Vec3(u(rng), u(rng), u(rng));
    const Isometry3 inv = pose.inverse(Eigen::Isometry);
    const Vec3 lo = inv * o, ld = inv.linear() * dir;
    double best = 5.0;
    bool any = false;
    for (const auto& t : m.triangles) {
      dm::RayTriangleHit h;
      if (dm::rayTriangle(lo, ld, m.positions[t[0]], m.positions[t[1]], m.positions[t[2]], 0, best, h)) {
        best = h.t;
        any = true;
      }
    }
    dm::MeshRayHit hit;
    ASSERT_EQ(dm::raycastMesh(bvh, pose, o, dir, 5.0, hit), any) << i;
    if (!any) continue;
    ++hits;
    EXPECT_EQ(hit.t, best);
    EXPECT_NEAR((hit.point - (o + best * dir)).norm(), 0, 1e-15);
    expectOnMesh(hit.point, m, pose, hit.triangle, 1e-12);
  }
  EXPECT_GT(hits, 100);
}

TEST(MeshQuery, SphereAndCapsuleMatchBruteForce) {
  const dm::Mesh m = soup(150, 77);
  const dm::MeshBvh bvh = bvhOf(m);
  std::mt19937_64 rng(47);
  std::uniform_real_distribution<double> u(-1, 1), r01(0, 0.3);
  int overlapping = 0;
  for (int i = 0; i < 1500; ++i) {
    const Isometry3 pose = randomMeshPose(rng, 0.2);
    const Vec3 p0 = Vec3(u(rng), u(rng), u(rng)), p1 = p0 + 0.4 * Vec3(u(rng), u(rng), u(rng));
    const double radius = r01(rng);
    const Isometry3 inv = pose.inverse(Eigen::Isometry);
    const Vec3 l0 = inv * p0, l1 = inv * p1;
    double sphereRef = 1e300, capsuleRef = 1e300;
    for (const auto& t : m.triangles) {
      const Vec3 &a = m.positions[t[0]], &b = m.positions[t[1]], &c = m.positions[t[2]];
      sphereRef = std::min(sphereRef, dm::segmentTriangleDistance(l0, l0, a, b, c).distance);
      capsuleRef = std::min(capsuleRef, dm::segmentTriangleDistance(l0, l1, a, b, c).distance);
    }
    const dm::MeshDistance s = dm::sphereMeshDistance(bvh, pose, p0, radius);
    const dm::MeshDistance c = dm::capsuleMeshDistance(bvh, pose, p0, p1, radius);
    ASSERT_NEAR(s.distance, sphereRef - radius, 1e-12);
    ASSERT_NEAR(c.distance, capsuleRef - radius, 1e-12);
    ASSERT_EQ(dm::sphereMeshIntersect(bvh, pose, p0, radius), sphereRef <= radius);
    ASSERT_EQ(dm::capsuleMeshIntersect(bvh, pose, p0, p1, radius), capsuleRef <= radius);
    overlapping += capsuleRef <= radius;
    expectOnMesh(c.pointB, m, pose, c.triangleB, 1e-12);
  }
  EXPECT_GT(overlapping, 100);
}

}  // namespace
