// Tests of the triangle-mesh–convex colliders (DMCollide/src/pair_mesh_convex.cpp,
// plus the mesh–sphere and mesh–capsule colliders of pair_mesh.cpp for
// regression) through dm::intersect, dm::collide and dm::distance.
//
// References, by what each can do:
//  * brute force: the minimum over all mesh triangles of dm::distance(triangle,
//    convex) — exact GJK (or closed form) per pair, no BVH, no warm start. It
//    is the tight reference: separated distances agree to 1e-9 relative.
//  * FCL (fcl::BVHModel<OBBRSSd> against Boxd, Cylinderd, Ellipsoidd, Convexd,
//    Sphered, Capsuled; a one-triangle BVHModel for the triangle): booleans
//    agree outside a band of kTouchBand around touching, where FCL's libccd
//    GJK decides within its own tolerance. FCL's mesh–shape distance also
//    runs GJK to a tolerance, so it is compared loosely (1e-5 m) on a few
//    poses only. FCL has no segment or point shape: those two are checked
//    against the brute force and the exact dm::segmentTriangleIntersect.
//  * closed meshes are solids for the pairs of pair_mesh_convex.cpp: a shape
//    fully inside collides with a negative distance, decided here by the
//    winding number of the mesh around the shape's centre. FCL and the
//    mesh–sphere/capsule colliders treat meshes as surfaces (not colliding).
#include <dm/collide/bvh.hpp>
#include <dm/collide/query.hpp>
#include <dm/collide/shapes.hpp>
#include <dm/collide/triangle.hpp>
#include <dm/math/primitives.hpp>

#include <gtest/gtest.h>

#include <fcl/fcl.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "collide_test_support.hpp"

namespace {

using dm::Isometry3;
using dm::Vec3;

// |distance| below which booleans are not compared with FCL (m; shapes are
// ~0.1–0.5 m): FCL's libccd GJK decides to its own tolerance there (with a
// 1e-9 m band some touching poses disagree; outside 1e-6 m all agree).
constexpr double kTouchBand = 1e-6;

Isometry3 randomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Isometry3 pose = Isometry3::Identity();
  pose.linear() = dm::Quat(g(rng), g(rng), g(rng), g(rng)).normalized().toRotationMatrix();
  return pose;
}

using dm::test::randomUnit;

struct MeshCase {
  std::string name;
  dm::Mesh mesh;
  std::shared_ptr<const dm::TriangleMesh> ours;
  std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> fcl;
  double reach = 0.0;  // bounding radius, m
};

std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> fclMesh(const dm::Mesh& m) {
  auto model = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  model->beginModel();
  for (const auto& t : m.triangles)
    model->addTriangle(m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]);
  model->endModel();
  return model;
}

MeshCase meshCase(std::string name, dm::Mesh m) {
  MeshCase c;
  c.name = std::move(name);
  c.mesh = m;
  auto made = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(std::move(m)));
  EXPECT_TRUE(made.ok());
  c.ours = *made;
  c.fcl = fclMesh(c.mesh);
  for (const Vec3& p : c.mesh.positions) c.reach = std::max(c.reach, p.norm());
  return c;
}

struct ConvexCase {
  std::string name;
  std::shared_ptr<const dm::ConvexShape> ours;
  std::shared_ptr<fcl::CollisionGeometryd> fcl;  // null: no FCL counterpart
  bool solidMeshes;     // per-triangle EPA depth when crossing (pair_mesh_convex.cpp; else pair_mesh.cpp's
                        // core–mesh distance − radius)
  bool curved = false;  // GJK converges linearly
  bool enclosedSolid = true;  // a shape inside a closed mesh collides (every built-in pair)
};

std::vector<ConvexCase> convexCases() {
  std::mt19937_64 rng(3);
  std::vector<Vec3> cloud(20);
  for (Vec3& p : cloud) p = 0.1 * randomUnit(rng);
  auto hull = dm::ConvexHull::create(cloud);
  EXPECT_TRUE(hull.ok());
  auto verts =
      std::make_shared<std::vector<fcl::Vector3d>>((*hull)->vertices().begin(), (*hull)->vertices().end());
  auto faces = std::make_shared<std::vector<int>>();
  for (const auto& t : (*hull)->mesh().triangles)
    faces->insert(faces->end(), {3, int(t[0]), int(t[1]), int(t[2])});
  const Vec3 t0(0.1, -0.05, 0.0), t1(-0.06, 0.09, 0.02), t2(-0.03, -0.07, -0.04);
  dm::Mesh triangleMesh;
  triangleMesh.positions = {t0, t1, t2};
  triangleMesh.triangles = {{0, 1, 2}};
  return {
      {"box", std::make_shared<dm::Box>(Vec3(0.12, 0.07, 0.05)), std::make_shared<fcl::Boxd>(0.24, 0.14, 0.1),
       true},
      {"cylinder", std::make_shared<dm::Cylinder>(0.06, 0.1), std::make_shared<fcl::Cylinderd>(0.06, 0.2),
       true, true},
      {"ellipsoid", std::make_shared<dm::Ellipsoid>(Vec3(0.12, 0.08, 0.05)),
       std::make_shared<fcl::Ellipsoidd>(0.12, 0.08, 0.05), true, true},
      {"hull", *hull, std::make_shared<fcl::Convexd>(verts, int((*hull)->mesh().triangles.size()), faces),
       true},
      {"triangle", std::make_shared<dm::TriangleShape>(t0, t1, t2), fclMesh(triangleMesh), true},
      {"segment", std::make_shared<dm::Segment>(Vec3(-0.12, 0.01, 0.0), Vec3(0.1, -0.02, 0.03)), nullptr,
       true},
      {"point", std::make_shared<dm::Point>(Vec3(0.01, 0.0, -0.02)), nullptr, true},
      {"sphere", std::make_shared<dm::Sphere>(0.08), std::make_shared<fcl::Sphered>(0.08), false},
      {"capsule", std::make_shared<dm::Capsule>(0.05, 0.08), std::make_shared<fcl::Capsuled>(0.05, 0.16),
       false},
  };
}

// Minimum over the mesh's triangles of the signed triangle–convex distance,
// with the closest points of the minimising pair (world frame).
dm::DistanceResult bruteForce(const MeshCase& m, const Isometry3& pa, const ConvexCase& c,
                              const Isometry3& pb) {
  dm::DistanceResult best;
  best.distance = std::numeric_limits<double>::infinity();
  for (const auto& t : m.mesh.triangles) {
    const dm::TriangleShape tri(m.mesh.positions[t[0]], m.mesh.positions[t[1]], m.mesh.positions[t[2]]);
    const dm::DistanceResult d = dm::distance(tri, pa, *c.ours, pb);
    if (d.distance < best.distance) best = d;
  }
  return best;
}

// Exact: does the segment or point touch some triangle (mesh frame)?
bool exactFlatHit(const MeshCase& m, const Isometry3& pa, const ConvexCase& c, const Isometry3& pb) {
  const Isometry3 rel = pa.inverse(Eigen::Isometry) * pb;
  Vec3 p, q;
  if (c.name == "segment") {
    const auto& s = static_cast<const dm::Segment&>(*c.ours);
    p = rel * s.a(), q = rel * s.b();
  } else {
    p = q = rel * static_cast<const dm::Point&>(*c.ours).position();
  }
  for (const auto& t : m.mesh.triangles)
    if (dm::segmentTriangleIntersect(p, q, m.mesh.positions[t[0]], m.mesh.positions[t[1]],
                                     m.mesh.positions[t[2]]))
      return true;
  return false;
}

// Generalised winding number of the closed mesh around the world point x:
// the sum of the triangles' signed solid angles (Van Oosterom–Strackee) / 4π.
double windingNumber(const MeshCase& m, const Isometry3& pa, const Vec3& x) {
  const Vec3 local = pa.inverse(Eigen::Isometry) * x;
  double solid = 0;
  for (const auto& t : m.mesh.triangles) {
    Vec3 r[3];
    double len[3];
    for (int i = 0; i < 3; ++i) {
      r[i] = m.mesh.positions[t[i]] - local;
      len[i] = r[i].norm();
    }
    const double num = r[0].dot(r[1].cross(r[2]));
    const double den = len[0] * len[1] * len[2] + len[2] * r[0].dot(r[1]) + len[0] * r[1].dot(r[2]) +
                       len[1] * r[2].dot(r[0]);
    solid += 2 * std::atan2(num, den);
  }
  return solid / (4 * std::numbers::pi);
}

bool fclCollide(const MeshCase& m, const Isometry3& pa, const ConvexCase& c, const Isometry3& pb) {
  fcl::CollisionObjectd oa(m.fcl, pa), ob(c.fcl, pb);
  fcl::CollisionRequestd req;
  fcl::CollisionResultd res;
  fcl::collide(&oa, &ob, req, res);
  return res.isCollision();
}

double fclDistance(const MeshCase& m, const Isometry3& pa, const ConvexCase& c, const Isometry3& pb) {
  fcl::CollisionObjectd oa(m.fcl, pa), ob(c.fcl, pb);
  fcl::DistanceRequestd req;
  req.gjk_solver_type = fcl::GST_INDEP;
  fcl::DistanceResultd res;
  fcl::distance(&oa, &ob, req, res);
  return res.min_distance;
}

enum class Placement { Random, Touching, NearMiss, Deep, Hole };

// Every convex kind against an icosphere, a torus and a box, 48 poses per
// pair (1,296 in all): random placements (deep, crossing, inside, separated),
// touching (moved by the brute-force distance along the closest-point
// direction, so the distance is 0 up to rounding), near misses (1e-6 to
// 1e-3 m) and deep overlaps; against the torus, every fifth pose sits in its
// hole.
TEST(MeshConvex, MatchesBruteForceAndFclOnRandomPoses) {
  const std::vector<MeshCase> meshes = {
      meshCase("icosphere", dm::makeIcosphere(0.3, 1)),
      meshCase("torus", dm::makeTorus(0.35, 0.12, 16, 8)),
      meshCase("box", dm::makeBox(Vec3(0.3, 0.2, 0.25))),
  };
  const std::vector<ConvexCase> shapes = convexCases();
  std::mt19937_64 rng(2024);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  int poses = 0, inside = 0, fclCompared = 0, fclDistanceCompared = 0;
  for (const MeshCase& m : meshes) {
    ASSERT_TRUE(m.ours->bvh()->isClosed()) << m.name;
    for (const ConvexCase& c : shapes) {
      const std::string pair = m.name + "-" + c.name;
      const double reach = m.reach + c.ours->boundingSphere().radius;
      int separated = 0, overlapping = 0;
      for (int k = 0; k < 48; ++k, ++poses) {
        Isometry3 pa = randomRotation(rng);
        pa.translation() = 0.1 * randomUnit(rng);
        Isometry3 pb = randomRotation(rng);
        const auto placement = static_cast<Placement>(k % 5);
        if (placement == Placement::Random || (placement == Placement::Hole && m.name != "torus")) {
          pb.translation() = pa.translation() + 1.2 * reach * std::cbrt(unit(rng)) * randomUnit(rng);
        } else if (placement == Placement::Hole) {
          // Centre within 2 cm of the torus axis, in its mid-plane: the hole
          // (radius 0.23 m) holds every shape (radius ≤ 0.13 m) untouched.
          const Vec3 offset(0.02 * (2 * unit(rng) - 1), 0.02 * (2 * unit(rng) - 1), 0.0);
          pb.translation() = pa * offset;
        } else {
          // From a separated start, along the closest-point direction.
          // GJK on curved shapes converges linearly (~1e-9 relative at 0.3 m),
          // so the step is repeated from the new closest points while apart.
          pb.translation() = pa.translation() + 1.5 * reach * randomUnit(rng);
          double target = 0;
          if (placement == Placement::NearMiss) target = std::pow(10.0, -6 + 3 * unit(rng));
          if (placement == Placement::Deep) target = -(0.005 + 0.03 * unit(rng));
          for (int step = 0; step < 3; ++step) {
            const dm::DistanceResult now = bruteForce(m, pa, c, pb);
            ASSERT_TRUE(step > 0 || now.distance > 0) << pair;
            if (!(now.distance > 0) || now.distance == target) break;
            pb.translation() += (target - now.distance) * (now.pointB - now.pointA).normalized();
          }
        }
        const dm::DistanceResult ref = bruteForce(m, pa, c, pb);
        const bool hit = dm::intersect(*m.ours, pa, *c.ours, pb);
        const dm::DistanceResult ours = dm::distance(*m.ours, pa, *c.ours, pb);
        ASSERT_TRUE(ours.supported) << pair;
        // Without a touching triangle B is all on one side: test one of its points.
        const bool enclosed =
            ref.distance > 0 && windingNumber(m, pa, pb * c.ours->support(Vec3::UnitX())) > 0.5;
        if (placement == Placement::Hole && m.name == "torus") {
          ASSERT_GT(ref.distance, 0.03) << pair << " pose " << k;
          ASSERT_FALSE(enclosed) << pair << " pose " << k;
        }
        if (placement == Placement::Touching) {
          ASSERT_NEAR(ref.distance, 0.0, c.curved ? 1e-6 : 1e-12) << pair << " pose " << k;
        }
        inside += enclosed;
        const bool truth = ref.distance <= 0 || (enclosed && c.enclosedSolid);
        (truth ? overlapping : separated)++;

        if (std::abs(ref.distance) <= (c.curved ? 1e-6 : 1e-12)) {
          // Touching to rounding (to GJK's accuracy on curved cores, see
          // below): either answer is right.
        } else if (c.name == "segment" || c.name == "point") {
          ASSERT_EQ(hit, exactFlatHit(m, pa, c, pb) || (enclosed && c.enclosedSolid))
              << pair << " pose " << k << " ref " << ref.distance << " enclosed " << enclosed << " ours "
              << ours.distance;
        } else {
          ASSERT_EQ(hit, truth) << pair << " pose " << k << " d " << ref.distance;
        }
        if (c.fcl && std::abs(ref.distance) > kTouchBand) {
          ++fclCompared;
          // FCL sees surfaces: a shape inside the closed mesh does not collide.
          ASSERT_EQ(fclCollide(m, pa, c, pb), ref.distance <= 0) << pair << " pose " << k;
        }
        if (ref.distance > 0 && !(enclosed && c.enclosedSolid)) {
          // GJK converges linearly on curved cores (a cylinder's cap parallel
          // to a mesh face, ellipsoids): both sides then carry an absolute
          // error of up to ~1e-8 m (seen: 2e-9 m at 1e-6 m).
          const double tol = 1e-9 * ref.distance + (c.curved ? 1e-8 : 1e-15);
          ASSERT_NEAR(ours.distance, ref.distance, tol) << pair << " pose " << k;
          ASSERT_NEAR((ours.pointB - ours.pointA).norm(), ours.distance, tol) << pair << " pose " << k;
          if (c.fcl && k % 8 == 1 && ref.distance > 1e-3) {
            ++fclDistanceCompared;
            EXPECT_NEAR(fclDistance(m, pa, c, pb), ref.distance, 1e-5) << pair << " pose " << k;
          }
        } else if (ref.distance <= 0) {
          // Crossing the surface: the deepest per-triangle penetration (the
          // capsule's core–mesh distance − radius stops at −radius).
          ASSERT_LE(ours.distance, c.curved ? 1e-8 : 1e-12) << pair << " pose " << k;
          if (c.solidMeshes || ours.distance > -c.ours->margin()) {
            ASSERT_NEAR(ours.distance, ref.distance, 1e-8) << pair << " pose " << k;
          }
        } else {
          // Enclosed: the push-out depth is at least the gap to the surface
          // (plus B's width along the push direction). A gap at rounding
          // level (a touching triangle's 3e-17 m) allows a zero depth: 1e-15
          // m is a few ulp of the 0.3 m scene.
          ASSERT_LE(ours.distance, -ref.distance * (1 - 1e-9) + 1e-15) << pair << " pose " << k;
        }

        dm::CollisionRequest req;
        req.maxContacts = 4;
        const dm::CollisionResult cr = dm::collide(*m.ours, pa, *c.ours, pb, req);
        if (c.solidMeshes || std::abs(ref.distance) > 1e-12) {
          ASSERT_EQ(cr.colliding, hit) << pair << " pose " << k;
          ASSERT_EQ(cr.contacts.empty(), !hit) << pair << " pose " << k;
        }
        ASSERT_LE(cr.contacts.size(), 4u) << pair;
        double deepest = 0;
        for (const dm::ContactPoint& p : cr.contacts) {
          ASSERT_NEAR(p.normal.norm(), 1.0, 1e-9) << pair << " pose " << k;
          ASSERT_GE(p.depth, 0.0) << pair << " pose " << k;
          deepest = std::max(deepest, p.depth);
        }
        if (hit && ours.distance < 0 && c.solidMeshes && c.ours->volume() > 0) {
          ASSERT_NEAR(deepest, -ours.distance, 1e-8) << pair << " pose " << k;
        }
      }
      EXPECT_GT(separated, 8) << pair;
      EXPECT_GT(overlapping, 8) << pair;
    }
  }
  EXPECT_GE(poses, 1000);
  EXPECT_GT(inside, 20);
  EXPECT_GT(fclCompared, 700);
  EXPECT_GT(fclDistanceCompared, 20);
}

// A box sunk into a box-shaped mesh's top face (within one of its two
// triangles: per-triangle EPA would otherwise also report the sideways push
// across the face's inner diagonal), and the same box inside the mesh:
// depths and normals have closed forms.
TEST(MeshConvex, BoxOnAndInsideAMeshBoxHasAnalyticContacts) {
  auto mesh = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(dm::makeBox(Vec3(0.5, 0.5, 0.5))));
  ASSERT_TRUE(mesh.ok());
  const dm::Box box(Vec3(0.1, 0.1, 0.1));
  // Rotated world frame: everything below is expressed in it.
  Isometry3 frame = Isometry3::Identity();
  frame.linear() = dm::Quat(Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized())).toRotationMatrix();
  frame.translation() = Vec3(0.3, -0.2, 0.1);
  const Vec3 up = frame.linear() * Vec3::UnitZ();
  for (const double depth : {0.01, 0.05}) {
    Isometry3 pb = Isometry3::Identity();
    pb.translation() = Vec3(0.3, 0.0, 0.5 + 0.1 - depth);
    pb = frame * pb;
    EXPECT_TRUE(dm::intersect(**mesh, frame, box, pb));
    const dm::DistanceResult d = dm::distance(**mesh, frame, box, pb);
    EXPECT_NEAR(d.distance, -depth, 1e-12);
    const dm::CollisionResult r = dm::collide(**mesh, frame, box, pb);
    ASSERT_FALSE(r.contacts.empty());
    for (const dm::ContactPoint& c : r.contacts) {
      EXPECT_NEAR(c.depth, depth, 1e-12);
      EXPECT_NEAR((c.normal - up).norm(), 0.0, 1e-12);
    }
    // Separated by 1 mm and 1 µm above the face.
    for (const double gap : {1e-3, 1e-6}) {
      const Isometry3 above = Eigen::Translation3d((depth + gap) * up) * pb;
      EXPECT_FALSE(dm::intersect(**mesh, frame, box, above));
      EXPECT_NEAR(dm::distance(**mesh, frame, box, above).distance, gap, 1e-12);
    }
  }
  // Inside, 0.1 m below the top face: pushing out takes 0.3 m along +z.
  Isometry3 pb = Isometry3::Identity();
  pb.translation() = Vec3(0.0, 0.05, 0.3);
  pb = frame * pb;
  EXPECT_TRUE(dm::intersect(**mesh, frame, box, pb));
  const dm::DistanceResult d = dm::distance(**mesh, frame, box, pb);
  EXPECT_NEAR(d.distance, -0.3, 1e-12);
  const Vec3 onTop = frame.inverse(Eigen::Isometry) * d.pointA;  // above B, on the face z = 0.5
  EXPECT_NEAR(onTop.z(), 0.5, 1e-12);
  EXPECT_LE(std::abs(onTop.x()), 0.1 + 1e-12);
  EXPECT_LE(std::abs(onTop.y() - 0.05), 0.1 + 1e-12);
  const dm::CollisionResult r = dm::collide(**mesh, frame, box, pb);
  ASSERT_EQ(r.contacts.size(), 1u);
  EXPECT_NEAR(r.contacts[0].depth, 0.3, 1e-12);
  EXPECT_NEAR((r.contacts[0].normal - up).norm(), 0.0, 1e-12);
  // The same query with the shapes swapped: the table flips it.
  const dm::CollisionResult s = dm::collide(box, pb, **mesh, frame);
  ASSERT_EQ(s.contacts.size(), 1u);
  EXPECT_NEAR((s.contacts[0].normal + up).norm(), 0.0, 1e-12);
  // An open mesh (the top face removed) is a surface: nothing inside it.
  dm::Mesh open = dm::makeBox(Vec3(0.5, 0.5, 0.5));
  std::erase_if(open.triangles, [&](const dm::Triangle& t) {
    return open.positions[t[0]].z() > 0 && open.positions[t[1]].z() > 0 && open.positions[t[2]].z() > 0;
  });
  auto shell = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(std::move(open)));
  ASSERT_TRUE(shell.ok());
  ASSERT_FALSE((*shell)->bvh()->isClosed());
  EXPECT_FALSE(dm::intersect(**shell, frame, box, pb));
  EXPECT_NEAR(dm::distance(**shell, frame, box, pb).distance, 0.35, 1e-12);  // to the wall at y = 0.5
}

// Many intersecting triangles give many contacts, reduced to maxContacts with
// the deepest kept; the pair cache carries over between queries.
TEST(MeshConvex, ContactsAreReducedAndCacheWarmStarts) {
  auto mesh = dm::TriangleMesh::create(std::make_shared<const dm::Mesh>(dm::makeIcosphere(0.3, 3)));
  ASSERT_TRUE(mesh.ok());
  const dm::Ellipsoid e(Vec3(0.2, 0.1, 0.05));
  Isometry3 pb = Isometry3::Identity();
  pb.translation() = Vec3(0.0, 0.0, 0.3);
  dm::CollisionRequest many;
  many.maxContacts = 1000;
  const dm::CollisionResult all = dm::collide(**mesh, Isometry3::Identity(), e, pb, many);
  ASSERT_GT(all.contacts.size(), 10u);
  double deepest = 0;
  for (const auto& c : all.contacts) deepest = std::max(deepest, c.depth);
  dm::CollisionRequest few;
  few.maxContacts = 3;
  const dm::CollisionResult reduced = dm::collide(**mesh, Isometry3::Identity(), e, pb, few);
  ASSERT_EQ(reduced.contacts.size(), 3u);
  EXPECT_EQ(reduced.contacts[0].depth, deepest);
  // Warm-started queries along a path give the cold answers.
  dm::PairCache cache;
  for (int i = 0; i < 50; ++i) {
    pb.translation() = Vec3(0.01 * i, 0.0, 0.32 + 0.002 * i);
    const dm::DistanceResult warm = dm::distance(**mesh, Isometry3::Identity(), e, pb, &cache);
    const dm::DistanceResult cold = dm::distance(**mesh, Isometry3::Identity(), e, pb);
    EXPECT_NEAR(warm.distance, cold.distance, 1e-9) << i;
    EXPECT_EQ(dm::intersect(**mesh, Isometry3::Identity(), e, pb, &cache),
              dm::intersect(**mesh, Isometry3::Identity(), e, pb))
        << i;
  }
}

}  // namespace
