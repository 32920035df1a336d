// Tests of dm/collide/gjk.hpp: GJK distance and EPA penetration against FCL
// (the reference), against exact brute force on polytopes (FCL's PQP
// triangle–triangle distance) and against closed forms.
#include <dm/collide/gjk.hpp>
#include <dm/collide/shapes.hpp>

#include <gtest/gtest.h>

#include <fcl/fcl.h>
#include <fcl/narrowphase/detail/primitive_shape_algorithm/triangle_distance.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace {

using dm::Isometry3;
using dm::Vec3;

Isometry3 randomPose(std::mt19937_64& rng, double maxOffset) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::Vector4d q(g(rng), g(rng), g(rng), g(rng));
  q.normalize();
  Isometry3 pose = Isometry3::Identity();
  pose.linear() = dm::Quat(q[0], q[1], q[2], q[3]).toRotationMatrix();
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Vec3 t;
  do t = Vec3(u(rng), u(rng), u(rng));
  while (t.squaredNorm() > 1.0);
  pose.translation() = maxOffset * t;
  return pose;
}

std::vector<Vec3> spherePoints(std::mt19937_64& rng, int n, double radius) {
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<Vec3> p(n);
  for (auto& v : p) v = radius * Vec3(g(rng), g(rng), g(rng)).normalized();
  return p;
}

// One convex shape in both libraries.
struct Both {
  std::string name;
  std::shared_ptr<const dm::ConvexShape> ours;
  std::shared_ptr<fcl::CollisionGeometryd> fcl;
  bool exactInFcl;                                     // FCL answers with a closed form for pairs of these
  std::shared_ptr<const dm::Mesh> polytope = nullptr;  // boxes and hulls: the surface
};

// Exact reference for polytopes: the minimum over triangle pairs of the
// triangle–triangle distance (FCL's PQP routine), valid when separated.
double bruteForceDistance(const dm::Mesh& ma, const Isometry3& pa, const dm::Mesh& mb, const Isometry3& pb) {
  double best = std::numeric_limits<double>::infinity();
  for (const auto& ta : ma.triangles) {
    const fcl::Vector3d t1[3] = {pa * ma.positions[ta[0]], pa * ma.positions[ta[1]],
                                 pa * ma.positions[ta[2]]};
    for (const auto& tb : mb.triangles) {
      const fcl::Vector3d t2[3] = {pb * mb.positions[tb[0]], pb * mb.positions[tb[1]],
                                   pb * mb.positions[tb[2]]};
      fcl::Vector3d p, q;
      best = std::min(best, fcl::detail::TriangleDistance<double>::triDistance(t1, t2, p, q));
    }
  }
  return best;
}

dm::Mesh boxMesh(const Vec3& h) {
  std::vector<Vec3> corners;
  for (int k = 0; k < 8; ++k)
    corners.emplace_back(k & 1 ? h.x() : -h.x(), k & 2 ? h.y() : -h.y(), k & 4 ? h.z() : -h.z());
  auto hull = dm::ConvexHull::create(corners);
  return (*hull)->mesh();
}

std::shared_ptr<fcl::Convexd> toFcl(const dm::ConvexHull& hull) {
  auto verts = std::make_shared<std::vector<fcl::Vector3d>>(hull.vertices().begin(), hull.vertices().end());
  auto faces = std::make_shared<std::vector<int>>();
  for (const auto& t : hull.mesh().triangles)
    faces->insert(faces->end(), {3, int(t[0]), int(t[1]), int(t[2])});
  return std::make_shared<fcl::Convexd>(verts, int(hull.mesh().triangles.size()), faces);
}

std::vector<Both> testShapes() {
  std::mt19937_64 rng(7);
  auto hull = dm::ConvexHull::create(spherePoints(rng, 24, 0.35));
  EXPECT_TRUE(hull.ok());
  return {
      {"sphere", std::make_shared<dm::Sphere>(0.3), std::make_shared<fcl::Sphered>(0.3), true},
      {"box", std::make_shared<dm::Box>(Vec3(0.4, 0.25, 0.15)), std::make_shared<fcl::Boxd>(0.8, 0.5, 0.3),
       false, std::make_shared<dm::Mesh>(boxMesh(Vec3(0.4, 0.25, 0.15)))},
      {"capsule", std::make_shared<dm::Capsule>(0.2, 0.3), std::make_shared<fcl::Capsuled>(0.2, 0.6), true},
      {"cylinder", std::make_shared<dm::Cylinder>(0.25, 0.35), std::make_shared<fcl::Cylinderd>(0.25, 0.7),
       false},
      {"ellipsoid", std::make_shared<dm::Ellipsoid>(Vec3(0.4, 0.25, 0.2)),
       std::make_shared<fcl::Ellipsoidd>(0.4, 0.25, 0.2), false},
      {"hull", *hull, toFcl(**hull), false, std::make_shared<dm::Mesh>((*hull)->mesh())},
  };
}

double fclDistance(const Both& a, const Isometry3& pa, const Both& b, const Isometry3& pb) {
  fcl::CollisionObjectd oa(a.fcl, pa), ob(b.fcl, pb);
  fcl::DistanceRequestd req;
  req.gjk_solver_type = fcl::GST_INDEP;
  fcl::DistanceResultd res;
  fcl::distance(&oa, &ob, req, res);
  return res.min_distance;
}

bool fclCollide(const Both& a, const Isometry3& pa, const Both& b, const Isometry3& pb) {
  fcl::CollisionObjectd oa(a.fcl, pa), ob(b.fcl, pb);
  fcl::CollisionRequestd req;
  fcl::CollisionResultd res;
  fcl::collide(&oa, &ob, req, res);
  return res.isCollision();
}

// Distance and boolean against FCL on every pair of the six convex kinds,
// 1,000 poses each: near misses, touching and deep overlaps (B's centre
// uniform in a ball of 1.2 × the sum of bounding radii; every tenth pose is
// moved to 1e-4 m from touching, on either side).
// Distance tolerances, by what the reference can do:
// - sphere and capsule pairs: FCL has closed forms; 1e-9 m (shapes ~0.5 m).
// - polytope pairs (box, hull): FCL's GJK misses by up to 4e-2 m on ~1 % of
//   poses (on 20,000 box–box poses its own GJK was off by > 1e-5 m 54 times,
//   libccd once), so the reference is the exact brute-force minimum over
//   triangle pairs (PQP's triangle distance); 1e-9 m.
// - pairs with a cylinder or ellipsoid: FCL's GJK (GST_INDEP) stops at its
//   1e-6 tolerance; 1e-5 m, with at most 1 % of poses beyond it. Both GJKs
//   return the norm of a point of A − B, an upper bound of the true distance,
//   so ours must never exceed FCL's by more than rounding.
// Booleans must agree with FCL outside a 1e-5 m band around touching.
TEST(Gjk, DistanceAndBooleanMatchFclOnAllConvexPairs) {
  const auto shapes = testShapes();
  std::mt19937_64 rng(11);
  for (std::size_t i = 0; i < shapes.size(); ++i) {
    for (std::size_t j = i; j < shapes.size(); ++j) {
      const Both& a = shapes[i];
      const Both& b = shapes[j];
      const std::string pair = a.name + "-" + b.name;
      const bool polytopes = a.polytope && b.polytope;
      const double reach = 1.2 * (a.ours->boundingSphere().radius + b.ours->boundingSphere().radius);
      int separated = 0, overlapping = 0, compared = 0, fclStoppedEarly = 0;
      for (int k = 0; k < 1000; ++k) {
        const Isometry3 pa = randomPose(rng, 0.2);
        Isometry3 pb = randomPose(rng, reach);
        pb.translation() += pa.translation();
        dm::GjkResult r = dm::gjkDistance(*a.ours, pa, *b.ours, pb);
        if (k % 10 == 0) {  // near touching, either side
          const double gap = (k % 20 == 0 ? 1e-4 : -1e-4);
          pb.translation() += (gap - r.distance) * r.normal;
          r = dm::gjkDistance(*a.ours, pa, *b.ours, pb);
        }
        // The points realise the distance (EPA on curved shapes stops at 1e-9
        // relative to the polytope size, hence 1e-8 m for overlaps).
        ASSERT_NEAR((r.pointB - r.pointA).norm(), std::abs(r.distance), r.distance > 0 ? 1e-9 : 1e-8)
            << pair << " pose " << k;
        (r.distance > 0 ? separated : overlapping)++;
        if (polytopes) {
          const double exact = bruteForceDistance(*a.polytope, pa, *b.polytope, pb);
          if (r.distance > 0) {
            ++compared;
            ASSERT_NEAR(r.distance, exact, 1e-9) << pair << " pose " << k;
          } else if (exact > 1e-9) {
            // Overlap without touching surfaces: one contains the other.
            ASSERT_TRUE(fclCollide(a, pa, b, pb)) << pair << " pose " << k;
          }
        } else {
          const double ref = fclDistance(a, pa, b, pb);
          if (ref > 1e-6) {
            ++compared;
            ASSERT_LE(r.distance, ref + 1e-9) << pair << " pose " << k;
            if (a.exactInFcl && b.exactInFcl) {
              ASSERT_NEAR(r.distance, ref, 1e-9) << pair << " pose " << k;
            } else if (std::abs(r.distance - ref) > 1e-5) {
              ++fclStoppedEarly;
            }
          }
        }
        if (std::abs(r.distance) > 1e-5) {
          const bool hit = dm::gjkIntersect(*a.ours, pa, *b.ours, pb);
          ASSERT_EQ(hit, r.distance <= 0) << pair << " pose " << k;
          if (!polytopes) {
            ASSERT_EQ(hit, fclCollide(a, pa, b, pb)) << pair << " pose " << k << " d " << r.distance;
          }
        }
      }
      EXPECT_GT(separated, 200) << pair;
      EXPECT_GT(overlapping, 150) << pair;
      EXPECT_GT(compared, 200) << pair;
      EXPECT_LE(fclStoppedEarly, compared / 100) << pair;
    }
  }
}

// Polytope pairs (box–box, box–hull, hull–hull) are exact to rounding: GJK
// terminates on a face/edge/vertex feature, so the distance agrees with the
// brute-force minimum to 1e-12 relative.
TEST(Gjk, PolytopeDistanceIsExact) {
  std::mt19937_64 rng(5);
  auto hullA = dm::ConvexHull::create(spherePoints(rng, 16, 0.3));
  auto hullB = dm::ConvexHull::create(spherePoints(rng, 40, 0.25));
  ASSERT_TRUE(hullA.ok() && hullB.ok());
  const dm::Box box(Vec3(0.3, 0.2, 0.1));
  const dm::Mesh bm = boxMesh(box.halfExtents());
  struct Case {
    const dm::ConvexShape* a;
    const dm::Mesh* ma;
    const dm::ConvexShape* b;
    const dm::Mesh* mb;
  };
  const Case cases[] = {{&box, &bm, &box, &bm},
                        {&box, &bm, hullA->get(), &(*hullA)->mesh()},
                        {hullA->get(), &(*hullA)->mesh(), hullB->get(), &(*hullB)->mesh()}};
  for (const Case& c : cases) {
    int compared = 0;
    for (int k = 0; k < 300; ++k) {
      const Isometry3 pa = randomPose(rng, 0.1), pb = randomPose(rng, 1.0);
      const double ref = bruteForceDistance(*c.ma, pa, *c.mb, pb);
      if (ref < 1e-6) continue;
      ++compared;
      const dm::GjkResult r = dm::gjkDistance(*c.a, pa, *c.b, pb);
      ASSERT_NEAR(r.distance, ref, 1e-12 * std::max(1.0, ref)) << "pose " << k;
    }
    EXPECT_GT(compared, 100);
  }
}

// Sphere–sphere is point–point plus radii: machine precision.
TEST(Gjk, SphereSphereIsExactToRounding) {
  const dm::Sphere a(0.25), b(0.5);
  std::mt19937_64 rng(3);
  for (int k = 0; k < 1000; ++k) {
    const Isometry3 pa = randomPose(rng, 1.0), pb = randomPose(rng, 2.0);
    const double d = (pb.translation() - pa.translation()).norm();
    const dm::GjkResult r = dm::gjkDistance(a, pa, b, pb);
    ASSERT_NEAR(r.distance, d - 0.75, 2e-15 * (d + 1)) << k;  // a few ulps
    ASSERT_NEAR(r.normal.dot((pb.translation() - pa.translation()) / d), 1.0, 1e-15);
  }
}

// Parallel capsules: distance is the axis offset minus the radii, and for
// overlapping ones the depth is the radius sum minus the offset.
TEST(Gjk, CapsuleParallelSegments) {
  const dm::Capsule a(0.1, 0.5), b(0.05, 0.3);
  for (double offset : {0.5, 0.2, 0.151, 0.1, 0.02}) {
    Isometry3 pb = Isometry3::Identity();
    pb.translation() = Vec3(offset, 0.0, 0.2);
    const dm::GjkResult r = dm::gjkDistance(a, Isometry3::Identity(), b, pb);
    EXPECT_NEAR(r.distance, offset - 0.15, 1e-15) << offset;
    EXPECT_NEAR(r.normal.x(), 1.0, 1e-12) << offset;
  }
}

// Minimum translation distance of two boxes from the 15 separating axes: an
// independent closed form for EPA's depth.
double boxOverlap(const dm::Box& a, const Isometry3& pa, const dm::Box& b, const Isometry3& pb) {
  std::vector<Vec3> axes;
  for (int i = 0; i < 3; ++i) axes.push_back(pa.linear().col(i)), axes.push_back(pb.linear().col(i));
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const Vec3 c = pa.linear().col(i).cross(pb.linear().col(j));
      if (c.norm() > 1e-9) axes.push_back(c.normalized());
    }
  double best = std::numeric_limits<double>::infinity();
  const Vec3 t = pb.translation() - pa.translation();
  for (const Vec3& l : axes) {
    const double ra = (pa.linear().transpose() * l).cwiseAbs().dot(a.halfExtents());
    const double rb = (pb.linear().transpose() * l).cwiseAbs().dot(b.halfExtents());
    best = std::min(best, ra + rb - std::abs(t.dot(l)));
  }
  return best;
}

// Exact penetration depth of two posed polytopes: the minimum over unit
// directions u of h(u) = max over A of u·x − min over B of u·x, which a
// convex polytope's Minkowski difference attains at a facet normal: a face
// normal of A or B or the cross product of an edge of A and an edge of B.
// Every candidate (both signs) is evaluated; extra ones cannot go below.
double bruteForceDepth(const dm::Mesh& ma, const Isometry3& pa, const dm::Mesh& mb, const Isometry3& pb) {
  std::vector<Vec3> va, vb;
  for (const Vec3& p : ma.positions) va.push_back(pa * p);
  for (const Vec3& p : mb.positions) vb.push_back(pb * p);
  std::vector<Vec3> normals, edgesA, edgesB;
  auto collect = [](const dm::Mesh& m, const std::vector<Vec3>& v, std::vector<Vec3>& n,
                    std::vector<Vec3>& e) {
    for (const auto& t : m.triangles) {
      n.push_back((v[t[1]] - v[t[0]]).cross(v[t[2]] - v[t[0]]));
      for (int k = 0; k < 3; ++k)
        if (t[k] < t[(k + 1) % 3]) e.push_back(v[t[(k + 1) % 3]] - v[t[k]]);  // each edge once
    }
  };
  collect(ma, va, normals, edgesA);
  collect(mb, vb, normals, edgesB);
  for (const Vec3& ea : edgesA)
    for (const Vec3& eb : edgesB) normals.push_back(ea.cross(eb));
  double best = std::numeric_limits<double>::infinity();
  for (const Vec3& n : normals) {
    if (n.squaredNorm() < 1e-24) continue;
    const Vec3 u = n.normalized();
    for (const Vec3& d : {u, Vec3(-u)}) {
      double hiA = -std::numeric_limits<double>::infinity(), loB = std::numeric_limits<double>::infinity();
      for (const Vec3& x : va) hiA = std::max(hiA, d.dot(x));
      for (const Vec3& x : vb) loB = std::min(loB, d.dot(x));
      best = std::min(best, hiA - loB);
    }
  }
  return best;
}

// EPA on hull pairs: the depth is the exact minimum translation distance,
// and the deepest points are depth apart along the normal.
TEST(Gjk, EpaDepthOfHullsIsTheMinimumTranslation) {
  std::mt19937_64 rng(21);
  for (int nv : {6, 12, 24}) {
    auto hullA = dm::ConvexHull::create(spherePoints(rng, nv, 0.3));
    auto hullB = dm::ConvexHull::create(spherePoints(rng, nv, 0.25));
    ASSERT_TRUE(hullA.ok() && hullB.ok());
    const dm::Mesh& ma = (*hullA)->mesh();
    const dm::Mesh& mb = (*hullB)->mesh();
    int tested = 0;
    for (int k = 0; k < 200; ++k) {
      const Isometry3 pa = randomPose(rng, 0.1), pb = randomPose(rng, 0.4);
      const double depth = bruteForceDepth(ma, pa, mb, pb);
      if (depth < 1e-6) continue;
      ++tested;
      const dm::GjkResult r = dm::gjkDistance(**hullA, pa, **hullB, pb);
      ASSERT_TRUE(r.exact) << nv << " pose " << k;
      ASSERT_NEAR(-r.distance, depth, 1e-9) << nv << " pose " << k;
      ASSERT_NEAR((r.pointA - r.pointB).dot(r.normal), -r.distance, 1e-9) << nv << " pose " << k;
      ASSERT_TRUE(dm::gjkIntersect(**hullA, pa, **hullB, pb)) << nv << " pose " << k;
    }
    EXPECT_GT(tested, 80) << nv;
  }
}

// EPA on boxes: depth equals the separating-axis minimum, and moving B by
// depth along the normal makes the boxes touch.
TEST(Gjk, EpaDepthOfBoxesIsTheMinimumTranslation) {
  const dm::Box a(Vec3(0.3, 0.2, 0.1)), b(Vec3(0.15, 0.25, 0.2));
  std::mt19937_64 rng(9);
  int tested = 0;
  for (int k = 0; k < 1000; ++k) {
    const Isometry3 pa = randomPose(rng, 0.1), pb = randomPose(rng, 0.5);
    const double mtd = boxOverlap(a, pa, b, pb);
    if (mtd < 1e-6) continue;
    ++tested;
    const dm::GjkResult r = dm::gjkDistance(a, pa, b, pb);
    ASSERT_TRUE(r.exact);
    ASSERT_NEAR(-r.distance, mtd, 1e-9) << k;
    Isometry3 moved = pb;
    moved.translation() += (-r.distance) * r.normal;
    const dm::GjkResult touch = dm::gjkDistance(a, pa, b, moved);
    ASSERT_NEAR(touch.distance, 0.0, 1e-9) << k;
    // The deepest points are depth apart along the normal.
    ASSERT_NEAR((r.pointA - r.pointB).dot(r.normal), -r.distance, 1e-9);
  }
  EXPECT_GT(tested, 300);
}

// Axis-aligned boxes: depth and normal in closed form.
// A pose clang's draw order produced (the random poses above differ by
// compiler): 1e-4 m of overlap where a box edge meets a cylinder rim. EPA's
// nearest face is then a sliver (two 0.8 m edges 1e-6 m apart), and the
// witness points, solved from its first vertex, missed the face point by up
// to 9e-5 m while the depth was right. At every tolerance they now realise
// the depth to rounding.
TEST(Gjk, EpaWitnessesOnASliverFace) {
  const auto pose = [](std::initializer_list<double> m) {
    Isometry3 p = Isometry3::Identity();
    auto it = m.begin();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) p.matrix()(r, c) = *it++;
    return p;
  };
  const Isometry3 pa =
      pose({0.73624954932999964, 0.65449187494898498, -0.17197961139953433, 0.068014935765181986,
            0.40134011316459373, -0.62693564430575788, -0.66774082656668243, -0.11673628435540893,
            -0.54485109403983367, 0.42260156592786946, -0.72425492873635999, 0.0074133230954887891});
  const Isometry3 pb =
      pose({0.49343157780851488, 0.41003228562847582, 0.76707157603686982, 0.76283665076810292,
            0.45197302436806586, 0.63261760090767294, -0.62890011628668341, -0.17664847449830132,
            -0.74313233226995523, 0.65701483679145944, 0.12682996874125751, 0.34673527127414588});
  const dm::Box box(Vec3(0.4, 0.25, 0.15));
  const dm::Cylinder cylinder(0.25, 0.35);
  for (const double tolerance : {1e-9, 1e-10, 1e-11, 1e-12}) {
    dm::GjkOptions o;
    o.epaTolerance = tolerance;
    const dm::GjkResult r = dm::gjkDistance(box, pa, cylinder, pb, nullptr, o);
    EXPECT_NEAR(r.distance, -1e-4, 1e-9) << tolerance;
    EXPECT_NEAR((r.pointB - r.pointA).norm(), -r.distance, 1e-15) << tolerance;
    EXPECT_NEAR((r.pointA - r.pointB).normalized().dot(r.normal), 1.0, 1e-9) << tolerance;
  }
}

TEST(Gjk, EpaAxisAlignedBoxes) {
  const dm::Box a(Vec3(1.0, 1.0, 1.0)), b(Vec3(0.5, 0.5, 0.5));
  Isometry3 pb = Isometry3::Identity();
  pb.translation() = Vec3(0.2, 0.1, 1.3);  // overlap along z: 1.5 − 1.3 = 0.2
  const dm::GjkResult r = dm::gjkDistance(a, Isometry3::Identity(), b, pb);
  EXPECT_NEAR(r.distance, -0.2, 1e-12);
  EXPECT_NEAR(r.normal.z(), 1.0, 1e-12);
}

// Spheres through EPA's margin path: cores apart, surfaces overlapping.
TEST(Gjk, SpherePenetrationIsAnalytic) {
  const dm::Sphere a(0.5), b(0.3);
  Isometry3 pb = Isometry3::Identity();
  pb.translation() = Vec3(0.3, 0.4, 0.0);  // centres 0.5 apart
  const dm::GjkResult r = dm::gjkDistance(a, Isometry3::Identity(), b, pb);
  EXPECT_NEAR(r.distance, -0.3, 1e-15);
  EXPECT_NEAR(r.normal.x(), 0.6, 1e-15);
  EXPECT_NEAR(r.normal.y(), 0.8, 1e-15);
  EXPECT_TRUE(dm::gjkIntersect(a, Isometry3::Identity(), b, pb));
  // Concentric: cores coincide, depth is the radius sum.
  const dm::GjkResult c = dm::gjkDistance(a, Isometry3::Identity(), b, Isometry3::Identity());
  EXPECT_NEAR(c.distance, -0.8, 1e-15);
}

// A warm cache gives the same answers as a cold start along a smooth motion.
TEST(Gjk, WarmStartGivesTheColdAnswer) {
  std::mt19937_64 rng(2);
  auto hull = dm::ConvexHull::create(spherePoints(rng, 500, 0.3));
  ASSERT_TRUE(hull.ok());
  const dm::Cylinder cyl(0.1, 0.2);
  dm::GjkCache cache;
  for (int k = 0; k < 200; ++k) {
    Isometry3 pb = Isometry3::Identity();
    pb.linear() = dm::AngleAxis(0.05 * k, Vec3(0.3, 1.0, 0.2).normalized()).toRotationMatrix();
    pb.translation() = Vec3(0.6 * std::cos(0.03 * k), 0.6 * std::sin(0.03 * k), 0.1);
    const dm::GjkResult warm = dm::gjkDistance(**hull, Isometry3::Identity(), cyl, pb, &cache);
    const dm::GjkResult cold = dm::gjkDistance(**hull, Isometry3::Identity(), cyl, pb);
    ASSERT_NEAR(warm.distance, cold.distance, 1e-9) << k;
    ASSERT_EQ(dm::gjkIntersect(**hull, Isometry3::Identity(), cyl, pb, &cache), cold.distance <= 0);
  }
}

dm::GjkOptions mprOptions() {
  dm::GjkOptions o;
  o.method = dm::PenetrationMethod::Mpr;
  return o;
}

// MPR on hull pairs: separated pairs get GJK's exact distance; overlapping
// pairs a depth no smaller than the minimum translation distance (EPA's),
// deepest points depth apart along the normal, and the same overlap verdict
// as the boolean GJK.
TEST(Gjk, MprDepthBoundsTheMinimumTranslation) {
  std::mt19937_64 rng(33);
  const dm::GjkOptions mpr = mprOptions();
  for (int nv : {8, 32, 128}) {
    auto hullA = dm::ConvexHull::create(spherePoints(rng, nv, 0.3));
    auto hullB = dm::ConvexHull::create(spherePoints(rng, nv, 0.25));
    ASSERT_TRUE(hullA.ok() && hullB.ok());
    int overlapping = 0, separated = 0, tight = 0;
    for (int k = 0; k < 400; ++k) {
      const Isometry3 pa = randomPose(rng, 0.1), pb = randomPose(rng, k % 2 ? 0.3 : 0.8);
      const dm::GjkResult epa = dm::gjkDistance(**hullA, pa, **hullB, pb);
      const dm::GjkResult r = dm::gjkDistance(**hullA, pa, **hullB, pb, nullptr, mpr);
      if (epa.distance > 1e-7) {
        ++separated;
        ASSERT_NEAR(r.distance, epa.distance, 1e-12) << nv << " pose " << k;
        continue;
      }
      if (epa.distance > -1e-7) continue;  // touching within rounding
      ++overlapping;
      ASSERT_LT(r.distance, 0.0) << nv << " pose " << k;
      ASSERT_GE(-r.distance, -epa.distance - 1e-9) << nv << " pose " << k;
      ASSERT_NEAR(r.normal.norm(), 1.0, 1e-12);
      ASSERT_NEAR((r.pointA - r.pointB).dot(r.normal), -r.distance, 1e-9) << nv << " pose " << k;
      ASSERT_TRUE(dm::gjkIntersect(**hullA, pa, **hullB, pb)) << nv << " pose " << k;
      tight += (-r.distance < 1.5 * -epa.distance);
    }
    EXPECT_GT(overlapping, 80) << nv;
    EXPECT_GT(separated, 80) << nv;
    // An upper bound, but not a loose one: most depths are within 50 %.
    EXPECT_GT(tight, overlapping * 3 / 4) << nv;
  }
}

// Where the ray between the centres leaves A − B through the face that
// also gives the minimum (a shallow face contact), MPR is exact; spheres go
// through the margin path either way.
TEST(Gjk, MprFaceContactAndSpheresAreExact) {
  const dm::Box a(Vec3(1.0, 1.0, 1.0)), b(Vec3(0.5, 0.5, 0.5));
  Isometry3 pb = Isometry3::Identity();
  pb.translation() = Vec3(0.2, 0.1, 1.3);  // overlap along z: 1.5 − 1.3 = 0.2
  const dm::GjkResult r = dm::gjkDistance(a, Isometry3::Identity(), b, pb, nullptr, mprOptions());
  EXPECT_NEAR(r.distance, -0.2, 1e-12);
  EXPECT_NEAR(r.normal.z(), 1.0, 1e-12);
  EXPECT_NEAR(r.pointA.z() - r.pointB.z(), 0.2, 1e-12);

  const dm::Sphere sa(0.5), sb(0.3);
  Isometry3 ps = Isometry3::Identity();
  ps.translation() = Vec3(0.3, 0.4, 0.0);
  const dm::GjkResult s = dm::gjkDistance(sa, Isometry3::Identity(), sb, ps, nullptr, mprOptions());
  EXPECT_NEAR(s.distance, -0.3, 1e-15);
  EXPECT_NEAR(s.normal.x(), 0.6, 1e-15);

  // A box sunk into an ellipsoid along its axis: exact by symmetry.
  const dm::Ellipsoid e(Vec3(0.4, 0.3, 0.2));
  Isometry3 pe = Isometry3::Identity();
  pe.translation() = Vec3(0.0, 0.0, 0.65);  // box top at z = 0.5 (b), ellipsoid bottom at 0.45
  const dm::GjkResult be = dm::gjkDistance(b, Isometry3::Identity(), e, pe, nullptr, mprOptions());
  EXPECT_NEAR(be.distance, -0.05, 1e-6);
  EXPECT_NEAR(be.normal.z(), 1.0, 1e-6);
}

// MPR scans small hulls' vertices in A's frame (2-wide, padded to a multiple
// of 4) and, above 16 vertices, climbs the hull's edges while refining: a
// hull of a box's corners must answer like the box, also where an axis
// direction finds four corners tied, against a hull, against another shape
// on either side, at every padding (6, 7 and 8 vertices) and with a 24-vertex
// prism. Overlapping pairs: MPR's depth bounds EPA's exact one.
TEST(Gjk, MprOnSmallHullsMatchesTheShapes) {
  const Vec3 h(0.3, 0.2, 0.1);
  std::vector<Vec3> corners;
  for (int i = 0; i < 8; ++i)
    corners.emplace_back(i & 1 ? h.x() : -h.x(), i & 2 ? h.y() : -h.y(), i & 4 ? h.z() : -h.z());
  auto cube = dm::ConvexHull::create(corners);
  // A wedge (six corners) and a wedge with a cap (seven).
  auto wedge = dm::ConvexHull::create(std::vector<Vec3>(corners.begin(), corners.begin() + 6));
  std::vector<Vec3> capped(corners.begin(), corners.begin() + 6);
  capped.emplace_back(0.0, 0.0, 0.4);
  auto cap = dm::ConvexHull::create(capped);
  // A 12-sided prism (24 vertices: the refinement climbs the hull's edges;
  // axis directions tie whole rings).
  std::vector<Vec3> rings;
  for (int k = 0; k < 12; ++k)
    for (double zk : {-0.15, 0.15})
      rings.emplace_back(0.25 * std::cos(k * 3.14159265358979323846 / 6),
                         0.25 * std::sin(k * 3.14159265358979323846 / 6), zk);
  auto prism = dm::ConvexHull::create(rings);
  ASSERT_TRUE(cube.ok() && wedge.ok() && cap.ok() && prism.ok());
  ASSERT_EQ((*prism)->vertices().size(), 24u);
  ASSERT_EQ((*cube)->vertices().size(), 8u);
  ASSERT_EQ((*wedge)->vertices().size(), 6u);
  ASSERT_EQ((*cap)->vertices().size(), 7u);
  const dm::Box box(h);
  const dm::Sphere ball(0.15);
  const dm::GjkOptions mpr = mprOptions();
  std::mt19937_64 rng(17);
  int overlapping = 0;
  for (int k = 0; k < 300; ++k) {
    Isometry3 pa = randomPose(rng, 0.1), pb = randomPose(rng, 0.6);
    if (k % 10 == 0) pa.linear().setIdentity(), pb.linear().setIdentity();  // ties between corners
    struct Case {
      const dm::ConvexShape& a;
      const dm::ConvexShape& b;
      const dm::ConvexShape& refA;
      const dm::ConvexShape& refB;
    };
    for (const Case& c : {Case{**cube, **cube, box, box}, Case{**cube, ball, box, ball},
                          Case{ball, **cube, ball, box}, Case{**wedge, **cap, **wedge, **cap},
                          Case{**prism, **prism, **prism, **prism}, Case{**prism, **cube, **prism, box}}) {
      const dm::GjkResult exact = dm::gjkDistance(c.refA, pa, c.refB, pb);
      const dm::GjkResult r = dm::gjkDistance(c.a, pa, c.b, pb, nullptr, mpr);
      if (exact.distance > 1e-7) {
        ASSERT_NEAR(r.distance, exact.distance, 1e-12) << k;
        continue;
      }
      if (exact.distance > -1e-7) continue;  // touching within rounding
      ++overlapping;
      ASSERT_GE(-r.distance, -exact.distance - 1e-9) << k;
      ASSERT_NEAR(r.normal.norm(), 1.0, 1e-12) << k;
      ASSERT_NEAR((r.pointA - r.pointB).dot(r.normal), -r.distance, 1e-9) << k;
    }
  }
  EXPECT_GT(overlapping, 500);
}

/// A hull seen only through its virtual support mapping: MPR on it takes the
/// generic path (no vertex scan, no edge climb).
class OpaqueHull final : public dm::ConvexShape {
 public:
  OpaqueHull(dm::ShapeType type, const dm::ConvexHull& hull) : ConvexShape(type, 0.0), hull_(hull) {}
  Vec3 supportCore(const Vec3& d, std::uint32_t& hint) const noexcept override {
    return hull_.supportCore(d, hint);
  }
  Vec3 interiorPoint() const noexcept override { return hull_.interiorPoint(); }
  dm::BoundingSphere boundingSphere() const noexcept override { return hull_.boundingSphere(); }
  dm::Aabb localAabb() const noexcept override { return hull_.localAabb(); }
  double volume() const noexcept override { return hull_.volume(); }

 private:
  const dm::ConvexHull& hull_;
};

// Above 16 vertices MPR's refinement climbs the hull's edges from the last
// support instead of scanning: it must find the supports the hull's own
// mapping finds, so the answers agree with the generic path's.
TEST(Gjk, MprEdgeClimbFindsTheSameSupports) {
  auto type = dm::registerShapeType("test-opaque-hull");
  ASSERT_TRUE(type.ok());
  std::mt19937_64 rng(8);
  const dm::GjkOptions mpr = mprOptions();
  for (int nv : {20, 40, 64}) {
    auto hullA = dm::ConvexHull::create(spherePoints(rng, nv, 0.3));
    auto hullB = dm::ConvexHull::create(spherePoints(rng, nv, 0.25));
    ASSERT_TRUE(hullA.ok() && hullB.ok());
    ASSERT_GT((*hullA)->vertices().size(), 16u);
    const OpaqueHull opaqueA(*type, **hullA), opaqueB(*type, **hullB);
    int overlapping = 0, same = 0;
    for (int k = 0; k < 300; ++k) {
      const Isometry3 pa = randomPose(rng, 0.1), pb = randomPose(rng, 0.35);
      const dm::GjkResult r = dm::gjkDistance(**hullA, pa, **hullB, pb, nullptr, mpr);
      const dm::GjkResult g = dm::gjkDistance(opaqueA, pa, opaqueB, pb, nullptr, mpr);
      if (g.distance >= 0) {
        ASSERT_NEAR(r.distance, g.distance, 1e-12) << nv << " pose " << k;
        continue;
      }
      ++overlapping;
      same += std::abs(r.distance - g.distance) < 1e-12 && (r.normal - g.normal).norm() < 1e-9;
    }
    EXPECT_GT(overlapping, 100) << nv;
    // Not all: the portal ends on a face of A − B, and which of the face's
    // vertices a support picks there is a tie broken by rounding (B's
    // vertices are mapped once here, per call there), so a few pairs end on
    // another triangle of the same face (about 3 %; a climb that stops
    // early disagrees on nearly all).
    EXPECT_GE(same, overlapping * 9 / 10) << nv;
  }
}

// The boolean on hull pairs: small hulls are scanned in place (B's through a
// rotation per support), larger ones climb their edges, and the simplex
// starts at an interior point of A − B. Whatever the path, the answer is the
// sign of the exact distance outside a 1e-9 m band around touching, cold,
// warm from the previous pose's cache, and with the centres coinciding.
TEST(Gjk, HullBooleanMatchesTheDistance) {
  std::mt19937_64 rng(14);
  std::vector<std::shared_ptr<const dm::ConvexHull>> hulls;
  for (int nv : {4, 8, 32, 33, 64, 300}) {
    auto h = dm::ConvexHull::create(spherePoints(rng, nv, 0.3));
    ASSERT_TRUE(h.ok());
    hulls.push_back(*h);
  }
  for (const auto& a : hulls) {
    for (const auto& b : hulls) {
      const std::size_t na = a->vertices().size(), nb = b->vertices().size();
      dm::GjkCache cache;
      int hits = 0, misses = 0, near = 0;
      for (int k = 0; k < 400; ++k) {
        const Isometry3 pa = randomPose(rng, 0.1);
        Isometry3 pb = randomPose(rng, 0.7);
        dm::GjkResult r = dm::gjkDistance(*a, pa, *b, pb);
        if (k % 4 == 0) {  // near touching, either side
          pb.translation() += ((k % 8 == 0 ? 1e-7 : -1e-7) - r.distance) * r.normal;
          r = dm::gjkDistance(*a, pa, *b, pb);
          ++near;
        }
        if (std::abs(r.distance) <= 1e-9) continue;
        const bool hit = r.distance < 0;
        (hit ? hits : misses)++;
        ASSERT_EQ(dm::gjkIntersect(*a, pa, *b, pb), hit) << na << "-" << nb << " pose " << k;
        ASSERT_EQ(dm::gjkIntersect(*a, pa, *b, pb, &cache), hit) << na << "-" << nb << " pose " << k;
      }
      EXPECT_GT(hits, 40) << na << "-" << nb;
      EXPECT_GT(misses, 40) << na << "-" << nb;
      EXPECT_GT(near, 50) << na << "-" << nb;
      const Isometry3 p = randomPose(rng, 0.5);
      EXPECT_TRUE(dm::gjkIntersect(*a, p, *b, p)) << na << "-" << nb;
    }
  }
}

// Flat shapes: two coplanar overlapping triangles give a finite answer,
// through EPA and through MPR (which falls back to EPA there).
TEST(Gjk, DegenerateFlatPairIsFinite) {
  const dm::TriangleShape t(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
  Isometry3 pb = Isometry3::Identity();
  pb.translation() = Vec3(0.2, 0.2, 0.0);
  for (const dm::GjkOptions& o : {dm::GjkOptions{}, mprOptions()}) {
    const dm::GjkResult r = dm::gjkDistance(t, Isometry3::Identity(), t, pb, nullptr, o);
    EXPECT_TRUE(std::isfinite(r.distance));
    EXPECT_LE(r.distance, 0.0);
    EXPECT_NEAR(r.normal.norm(), 1.0, 1e-12);
  }
  EXPECT_TRUE(dm::gjkIntersect(t, Isometry3::Identity(), t, pb));
}

}  // namespace
