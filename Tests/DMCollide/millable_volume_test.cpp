// MillableVolume: partial-volume occupancy, the tool's overlap and contact
// normal against analytic geometry, Archard removal, change sets and the
// block surfaces that a renderer swaps in.
#include <dm/collide/millable_volume.hpp>
#include <dm/collide/sphere_tree.hpp>
#include <dm/math/isosurface.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <numbers>
#include <set>

namespace dm {
namespace millable_test {

constexpr double kH = 0.25e-3;  // m, voxel

// A float volume of n³ voxels of kH with its first centre at `origin`,
// holding f(centre).
Volume field(int n, const Vec3& origin, const std::function<double(const Vec3&)>& f) {
  Affine3 a = Affine3::Identity();
  a.linear() = Mat3::Identity() * kH;
  a.translation() = origin;
  auto v = Volume::create(Vec3i(n, n, n), VoxelType::F32, a);
  EXPECT_TRUE(v.ok());
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) v->setValue(i, j, k, f(a * Vec3(i, j, k)));
  return std::move(*v);
}

// Bone filling z < top over a 40³ grid centred on the origin.
MillableVolume slab(double top, MillingMaterial m = {}) {
  const Volume sdf = field(40, Vec3::Constant(-20 * kH), [top](const Vec3& p) { return p.z() - top; });
  auto v = MillableVolume::fromSdf(sdf, std::move(m));
  EXPECT_TRUE(v.ok()) << v.error().message();
  return std::move(*v);
}

Isometry3 place(const Vec3& t) {
  Isometry3 p = Isometry3::Identity();
  p.translation() = t;
  return p;
}

double capVolume(double r, double depth) { return std::numbers::pi * depth * depth * (3 * r - depth) / 3.0; }

double angleDeg(const Vec3& a, const Vec3& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / std::numbers::pi;
}

TEST(MillableVolume, OccupancyIsThePartialVolumeOfTheCells) {
  // A plane at a sub-voxel height: the material is exactly the grid's area
  // times the depth below the plane (partial volume of a plane is exact).
  const double top = 0.37 * kH;
  const MillableVolume bone = slab(top);
  const double area = std::pow(40 * kH, 2),
               depth = top + 20.5 * kH;  // the lowest cells' bottom face is at −20.5 h
  EXPECT_NEAR(bone.materialVolume(), area * depth, 1e-5 * area * depth);
  EXPECT_NEAR(bone.occupancy(20, 20, 20), 0.5 + 0.37, 1e-4);
  EXPECT_DOUBLE_EQ(bone.occupancy(-1, 0, 0), 0.0);
  auto asVolume = bone.occupancyVolume();
  ASSERT_TRUE(asVolume.ok());
  EXPECT_TRUE(asVolume->indexToWorld().isApprox(
      field(1, Vec3::Constant(-20 * kH), [](const Vec3&) { return 0.0; }).indexToWorld()));
  for (int k : {0, 19, 20, 21, 39}) EXPECT_NEAR(asVolume->value(7, 3, k), bone.occupancy(7, 3, k), 1e-7) << k;
}

TEST(MillableVolume, IntensityFollowsTheCtPartialVolumeLaw) {
  const Volume ct = field(8, Vec3::Zero(), [](const Vec3& p) { return -100.0 + 1.0e6 * p.x(); });  // HU ramp
  auto bone = MillableVolume::fromIntensity(ct, 0.0, 1000.0);
  ASSERT_TRUE(bone.ok());
  for (int i = 0; i < 8; ++i) {
    const double hu = -100.0 + 1.0e6 * i * kH;
    EXPECT_NEAR(bone->occupancy(i, 3, 3), std::clamp(hu / 1000.0, 0.0, 1.0), 1e-4) << i;
  }
}

TEST(MillableVolume, SphereOverlapIsTheSphericalCap) {
  const double r = 1.5e-3;
  for (double depth : {0.4e-3, 0.8e-3, 1.3e-3}) {
    const MillableVolume bone = slab(0.13 * kH);
    const double got =
        bone.overlap(MillingTool::sphere(r), place(Vec3(0.31 * kH, -0.22 * kH, 0.13 * kH + r - depth)));
    EXPECT_NEAR(got, capVolume(r, depth), 0.03 * capVolume(r, depth)) << depth;
  }
}

TEST(MillableVolume, LongToolsTiltedAnyWayOverlapWhatEveryCellSays) {
  // The cell walk visits only the tool's oriented box within its ball; the
  // overlap must still be the sum over every cell of the grid:
  // Σ max(0, o + K − 1)·V with K = clamp(1/2 − s/h) from the tool's own distance.
  const MillableVolume bone = slab(0.1 * kH);
  const double v = kH * kH * kH;
  for (const MillingTool& tool :
       {MillingTool::cylinder(0.3e-3, 1.8e-3), MillingTool::box(Vec3(1.6e-3, 0.2e-3, 0.5e-3))})
    for (const Vec3& axis : {Vec3(1, 0, 0), Vec3(1, 2, 3), Vec3(-2, 1, 0.5)}) {
      Isometry3 pose = place(Vec3(0.2e-3, -0.1e-3, 0.4e-3));
      pose.linear() = AngleAxis(0.7, axis.normalized()).toRotationMatrix();
      double brute = 0.0;
      for (int k = 0; k < 40; ++k)
        for (int j = 0; j < 40; ++j)
          for (int i = 0; i < 40; ++i) {
            const Vec3 p = pose.inverse() * (bone.indexToWorld() * Vec3(i, j, k));
            Vec3 g;
            const double cover = std::clamp(0.5 - tool.distance(p, g) / kH, 0.0, 1.0);
            brute += std::max(0.0, bone.occupancy(i, j, k) + cover - 1.0) * v;
          }
      EXPECT_GT(brute, 0.0);
      EXPECT_NEAR(bone.overlap(tool, pose), brute, 1e-9 * brute) << axis.transpose();
    }
}

TEST(MillableVolume, ContactNormalIsTheSurfaceNormalOnPlanesAndSpheres) {
  const MillingTool ball = MillingTool::sphere(1e-3);
  const MillableVolume flat = slab(0.0);
  for (double dx : {0.0, 0.17, 0.5, 0.71})
    for (double dy : {0.0, 0.33, 0.5}) {
      const Vec3 n = flat.contactNormal(ball, place(Vec3(dx * kH, dy * kH, 1e-3 + 0.1 * kH)), 2 * kH);
      EXPECT_LT(angleDeg(n, Vec3::UnitZ()), 0.5) << dx << " " << dy;
    }
  // A ball of bone (radius 3 mm): the normal is the line of centres.
  const Volume sdf = field(40, Vec3::Constant(-20 * kH), [](const Vec3& p) { return p.norm() - 3e-3; });
  auto ball3 = MillableVolume::fromSdf(sdf);
  ASSERT_TRUE(ball3.ok());
  for (const Vec3& dir : {Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(0.3, -0.5, 0.8), Vec3(-0.2, 0.1, -1)}) {
    const Vec3 u = dir.normalized();
    const Vec3 n = ball3->contactNormal(ball, place(u * (3e-3 + 1e-3 + 0.1 * kH)), 2 * kH);
    EXPECT_LT(angleDeg(n, u), 1.0) << dir.transpose();
  }
  EXPECT_EQ(flat.contactNormal(ball, place(Vec3(0, 0, 4e-3)), 2 * kH), Vec3::Zero());
}

TEST(MillableVolume, MillingLeavesTheToolsShapeAtSubVoxelPrecision) {
  MillableVolume bone = slab(0.0);
  const double r = 1.2e-3;
  const Vec3 c(0.3 * kH, 0.1 * kH, 0.4e-3);
  const double before = bone.materialVolume();
  const MillResult cut = bone.mill(MillingTool::sphere(r), place(c), 1e9);  // enough to take all it reaches
  const double cap = capVolume(r, r - c.z());
  EXPECT_NEAR(cut.removed, cap, 0.03 * cap);
  EXPECT_NEAR(before - bone.materialVolume(), cut.removed, 1e-12);
  EXPECT_NEAR(bone.removedVolume(0), cut.removed, 1e-15);
  EXPECT_LT(bone.overlap(MillingTool::sphere(r), place(c)), 1e-4 * cap);  // a tool fits the hole it cut
  // The cavity's 0.5 level is the sphere: inside R − h/2 at most half full,
  // beyond R + h/2 untouched.
  int inside = 0;
  for (int k = 0; k < 40; ++k)
    for (int j = 0; j < 40; ++j)
      for (int i = 0; i < 40; ++i) {
        const Vec3 p = Vec3(i - 20, j - 20, k - 20) * kH;
        const double d = (p - c).norm(), o = bone.occupancy(i, j, k),
                     was = std::clamp(0.5 - p.z() / kH, 0.0, 1.0);
        if (d < r - 0.5 * kH && was > 0.5) {
          EXPECT_LE(o, 0.5) << i << " " << j << " " << k;
          ++inside;
        }
        if (d > r + 0.5 * kH) {
          EXPECT_NEAR(o, was, 1e-4) << i << " " << j << " " << k;
        }
      }
  EXPECT_GT(inside, 40);  // the cap of radius R − h/2 below z = 0 holds about 60 centres
}

TEST(MillableVolume, RemovalFollowsArchardsLaw) {
  // A tick's work (1 N at 10 m/s for 1 ms, k = 0.1): nothing is capped, so
  // the removal is W/H — to the 1/65535-of-a-cell rounding of each voxel —
  // and doubles with the work and halves with the hardness.
  const MillingTool t = MillingTool::sphere(1e-3);
  const Isometry3 p = place(Vec3(0, 0, 0.6e-3));
  const double w = 1e-3;  // J
  MillableVolume soft = slab(0.0, {.name = "bone", .hardness = 0.4e9});
  MillableVolume hard = slab(0.0, {.name = "bone", .hardness = 0.8e9});
  MillableVolume twice = slab(0.0, {.name = "bone", .hardness = 0.4e9});
  const double a = soft.mill(t, p, w).removed, b = hard.mill(t, p, w).removed,
               c = twice.mill(t, p, 2 * w).removed;
  EXPECT_NEAR(a, w / 0.4e9, 5e-3 * a);
  EXPECT_NEAR(b, 0.5 * a, 5e-3 * a);
  EXPECT_NEAR(c, 2.0 * a, 5e-3 * a);
  // Nothing where the tool never was, nothing for non-positive work.
  EXPECT_EQ(soft.mill(t, place(Vec3(0, 0, 2e-3)), 1.0).removed, 0.0);
  EXPECT_EQ(soft.mill(t, p, -1.0).voxels, 0);
  EXPECT_EQ(soft.mill(t, p, std::nan("")).voxels, 0);
}

TEST(MillableVolume, ChangedBlocksAreListedOnceAndTheirSurfacesTileTheWhole) {
  MillableVolume bone = slab(0.0);
  EXPECT_TRUE(bone.changedBlocks().empty());
  const MillingTool t = MillingTool::cylinder(0.6e-3, 1.5e-3);
  for (int s = 0; s < 20; ++s) bone.mill(t, place(Vec3(-1.5e-3 + s * 0.15e-3, 0.0, 0.2e-3)), 1e9);
  const auto changed = bone.changedBlocks();
  const std::set<std::uint32_t> unique(changed.begin(), changed.end());
  EXPECT_EQ(unique.size(), changed.size());
  // Exactly the blocks whose piece holds a voxel below its original
  // occupancy: block b's piece spans voxels [8b, 8b + 8] on each axis.
  const MillableVolume fresh = slab(0.0);
  std::set<std::uint32_t> expected;
  const auto blocksOf = [](int i) {
    std::vector<int> b{i / 8};
    if (i % 8 == 0 && i > 0) b.push_back(i / 8 - 1);
    return b;
  };
  for (int k = 0; k < 40; ++k)
    for (int j = 0; j < 40; ++j)
      for (int i = 0; i < 40; ++i)
        if (bone.occupancy(i, j, k) < fresh.occupancy(i, j, k))
          for (int bk : blocksOf(k))
            for (int bj : blocksOf(j))
              for (int bi : blocksOf(i)) expected.insert(static_cast<std::uint32_t>(bi + 5 * (bj + 5 * bk)));
  EXPECT_EQ(unique, expected);
  bone.clearChanges();
  EXPECT_TRUE(bone.changedBlocks().empty());

  // Every block's piece together: the surface of the whole grid with a layer
  // of empty cells around it (the pieces close the bone at the grid's border).
  std::vector<std::uint32_t> all(125);
  for (std::uint32_t b = 0; b < 125; ++b) all[b] = b;
  auto pieces = bone.blockSurfaces(all);
  ASSERT_TRUE(pieces.ok()) << pieces.error().message();
  double pieceArea = 0.0;
  std::size_t pieceTriangles = 0;
  for (const Mesh& m : *pieces) {
    pieceArea += m.surfaceArea();
    pieceTriangles += m.triangles.size();
  }
  const Volume padded = field(42, Vec3::Constant(-21 * kH), [&bone](const Vec3& p) {
    const Vec3 ijk = p / kH + Vec3::Constant(20.0);
    return bone.occupancy(static_cast<int>(std::lround(ijk.x())), static_cast<int>(std::lround(ijk.y())),
                          static_cast<int>(std::lround(ijk.z())));
  });
  auto whole = extractIsosurface(padded, {.iso = 0.5, .threads = 1});
  ASSERT_TRUE(whole.ok());
  EXPECT_EQ(pieceTriangles, whole->triangles.size());
  EXPECT_NEAR(pieceArea, whole->surfaceArea(), 1e-9 * pieceArea);
  EXPECT_FALSE(bone.blockSurfaces(std::vector<std::uint32_t>{125}).ok());

  // A renderer that swaps in just the changed pieces after more milling (a
  // path across the block faces at y = ±1 mm, its bottom grazing the face
  // at z = −1 mm, so only the first layer of the blocks above that face
  // changes there) holds the same surface as meshing every block again.
  std::vector<Mesh> held = std::move(*pieces);
  for (int s = 0; s < 20; ++s)
    bone.mill(MillingTool::sphere(0.7e-3), place(Vec3(0.1e-3, -1.5e-3 + s * 0.15e-3, -0.3e-3)), 1e9);
  const std::vector<std::uint32_t> swap(bone.changedBlocks().begin(), bone.changedBlocks().end());
  auto fresher = bone.blockSurfaces(swap);
  ASSERT_TRUE(fresher.ok());
  for (std::size_t n = 0; n < swap.size(); ++n) held[swap[n]] = std::move((*fresher)[n]);
  auto again = bone.blockSurfaces(all);
  ASSERT_TRUE(again.ok());
  for (std::uint32_t b = 0; b < 125; ++b) {
    EXPECT_EQ(held[b].triangles.size(), (*again)[b].triangles.size()) << "block " << b;
    EXPECT_NEAR(held[b].surfaceArea(), (*again)[b].surfaceArea(), 1e-12) << "block " << b;
  }
}

// The drawn surface of a ball of bone, also with a steeper ramp (a CT read
// with "full" below its cortical value: 1.3 times as steep), shades close
// to the curve it is. Central differences of the clamped one-voxel ramp
// tilted the normals by up to 17.6° (24.8° steeper) where the surface
// crosses voxel layers — rings on a skull; the Gaussian-smoothed gradient
// leaves 4.1° (7.2°), the rest being the ramp's kinks between samples. The
// vertices stay where marching cubes puts them on the clamped ramp.
TEST(MillableVolume, TheDrawnSurfaceOfACurvedBoneShadesAsItsCurve) {
  const double radius = 3.1e-3;  // 12.4 voxels
  const Vec3 centre(0.3 * kH, -0.2 * kH, 0.1 * kH);
  for (double slope : {1.0, 1.3}) {
    const Volume sdf = field(40, Vec3::Constant(-20 * kH), [&](const Vec3& p) {
      // o = clamp(1/2 − slope·d/h): a ramp `slope` times as steep.
      return slope * ((p - centre).norm() - radius);
    });
    auto ball = MillableVolume::fromSdf(sdf);
    ASSERT_TRUE(ball.ok());
    std::vector<std::uint32_t> all(125);
    for (std::uint32_t b = 0; b < 125; ++b) all[b] = b;
    auto pieces = ball->blockSurfaces(all);
    ASSERT_TRUE(pieces.ok()) << pieces.error().message();
    double worstNormal = 0.0, worstRadius = 0.0;
    std::size_t vertices = 0;
    for (const Mesh& m : *pieces) {
      ASSERT_EQ(m.normals.size(), m.positions.size());
      for (std::size_t v = 0; v < m.positions.size(); ++v) {
        const Vec3 r = m.positions[v] - centre;
        worstNormal = std::max(worstNormal, angleDeg(m.normals[v], r));
        worstRadius = std::max(worstRadius, std::abs(r.norm() - radius));
        ++vertices;
      }
    }
    EXPECT_GT(vertices, 2000u);
    EXPECT_LT(worstNormal, slope == 1.0 ? 5.0 : 8.0) << "slope " << slope;
    // Linear interpolation on the clamped ramp: 0.081 and 0.142 voxel measured.
    EXPECT_LT(worstRadius, (slope == 1.0 ? 0.1 : 0.16) * kH) << "slope " << slope;
  }
}

TEST(MillableVolume, ForbiddenMaterialsAreAccounted) {
  MillableVolume bone = slab(0.0);
  Volume labels = field(40, Vec3::Constant(-20 * kH), [](const Vec3& p) { return p.x() > 0.0 ? 1.0 : 0.0; });
  ASSERT_TRUE(
      bone.setMaterials({{.name = "bone"}, {.name = "nerve", .hardness = 0.1e9, .forbidden = true}}, &labels)
          .ok());
  const MillResult cut = bone.mill(MillingTool::sphere(1e-3), place(Vec3(0.5 * kH, 0, 0.5e-3)),
                                   1e9);  // x = 0 splits the cells evenly
  EXPECT_GT(cut.removedForbidden, 0.0);
  EXPECT_NEAR(cut.removedForbidden, bone.removedVolume(1), 1e-15);
  EXPECT_NEAR(cut.removed, bone.removedVolume(0) + bone.removedVolume(1), 1e-15);
  EXPECT_NEAR(bone.removedVolume(0), bone.removedVolume(1), 1e-3 * cut.removed);
}

TEST(MillableVolume, TheSurfaceShowsTheMaterialItCutsInto) {
  // Enamel (0) over dentin (1) below z = −0.75 mm: a hole down to −1.5 mm
  // shows dentin on its floor and lower wall, enamel on top and above.
  MillableVolume tooth = slab(0.0);
  Volume labels =
      field(40, Vec3::Constant(-20 * kH), [](const Vec3& p) { return p.z() < -0.75e-3 ? 1.0 : 0.0; });
  ASSERT_TRUE(
      tooth
          .setMaterials({{.name = "enamel", .hardness = 3e9}, {.name = "dentin", .hardness = 0.6e9}}, &labels)
          .ok());
  tooth.mill(MillingTool::cylinder(0.8e-3, 1.5e-3), place(Vec3(0, 0, 0)), 1e9);
  std::vector<std::uint32_t> all(125);
  for (std::uint32_t b = 0; b < 125; ++b) all[b] = b;
  const std::vector<Vec4f> colors{Vec4f(1, 1, 1, 1), Vec4f(1, 0.5f, 0, 1)};
  auto pieces = tooth.blockSurfaces(all, colors);
  ASSERT_TRUE(pieces.ok()) << pieces.error().message();
  std::size_t dentinSeen = 0, wrong = 0;
  for (const Mesh& m : *pieces) {
    ASSERT_EQ(m.colors.size(), m.positions.size());
    for (std::size_t v = 0; v < m.positions.size(); ++v) {
      const double z = m.positions[v].z();
      const bool dentin = m.colors[v] == colors[1];
      dentinSeen += dentin;
      // Away from the interface (a voxel either side), the colour is the layer's.
      if ((z < -0.75e-3 - kH && !dentin) || (z > -0.75e-3 + kH && dentin)) ++wrong;
    }
  }
  EXPECT_GT(dentinSeen, 100u);
  EXPECT_EQ(wrong, 0u);
  // One colour for two materials is refused.
  EXPECT_FALSE(tooth.blockSurfaces(all, std::span<const Vec4f>(colors.data(), 1)).ok());
}

TEST(MillableVolume, ASawCutMakesFragmentsWithTheirMassProperties) {
  // A 6 × 3 × 2 mm bar sawn across at x = 0.6 mm by a 0.4 mm blade.
  const Vec3 half(3e-3, 1.5e-3, 1e-3);
  const Volume sdf = field(40, Vec3::Constant(-20 * kH) + Vec3::Constant(0.5 * kH), [&half](const Vec3& p) {
    const Vec3 q = p.cwiseAbs() - half;
    return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
  });
  auto made = MillableVolume::fromSdf(sdf);
  ASSERT_TRUE(made.ok());
  MillableVolume bone = std::move(*made);
  auto whole = bone.fragments();
  ASSERT_TRUE(whole.ok()) << whole.error().message();
  ASSERT_EQ(whole->fragments.size(), 1u);
  EXPECT_NEAR(whole->fragments[0].volume, 36e-9, 0.01 * 36e-9);
  EXPECT_LT(whole->fragments[0].centroid.norm(), 1e-6);

  bone.mill(MillingTool::box(Vec3(0.2e-3, 3e-3, 3e-3)), place(Vec3(0.6e-3, 0, 0)), 1e9);
  auto sawn = bone.fragments();
  ASSERT_TRUE(sawn.ok());
  ASSERT_EQ(sawn->fragments.size(), 2u);
  // Left 3.4 mm long, right 2.2 mm: largest first.
  const double lengths[2] = {3.4e-3, 2.2e-3}, centres[2] = {-1.3e-3, 1.9e-3};
  for (int f = 0; f < 2; ++f) {
    const BoneFragment& g = sawn->fragments[static_cast<std::size_t>(f)];
    const double l = lengths[f], v = l * 3e-3 * 2e-3;
    EXPECT_NEAR(g.volume, v, 0.02 * v) << f;
    EXPECT_NEAR(g.centroid.x(), centres[f], 0.25 * kH) << f;
    EXPECT_NEAR(g.centroid.y(), 0.0, 1e-6) << f;
    // A box's second moments, V/12·(b² + c²) about each axis.
    const Vec3 expected = v / 12.0 * Vec3(9e-6 + 4e-6, l * l + 4e-6, l * l + 9e-6);
    for (int axis = 0; axis < 3; ++axis)
      EXPECT_NEAR(g.inertia(axis, axis), expected[axis], 0.04 * expected[axis]) << f << " " << axis;
    EXPECT_NEAR(g.inertia(0, 1), 0.0, 1e-3 * expected[0]);
  }
  std::size_t labelled = 0;
  for (std::size_t v = 0; v < sawn->labels.voxelCount(); ++v) labelled += sawn->labels.valueAt(v) == 1.0;
  EXPECT_EQ(labelled, sawn->fragments[0].cells);

  // The smaller piece as bone placement's moving fragment.
  auto piece = bone.fragmentOccupancy(*sawn, 1);
  ASSERT_TRUE(piece.ok());
  double sum = 0.0;
  for (std::size_t v = 0; v < piece->voxelCount(); ++v) sum += piece->valueAt(v);
  EXPECT_NEAR(sum * bone.voxelVolume(), sawn->fragments[1].volume,
              1e-6 * sum * bone.voxelVolume());  // F32 values
  EXPECT_TRUE(ImplicitSphereTree::create(*piece, 0.5).ok());
  EXPECT_FALSE(bone.fragmentOccupancy(*sawn, 2).ok());
}

TEST(MillableVolume, BadInputIsNamed) {
  const Volume sdf = field(4, Vec3::Zero(), [](const Vec3& p) { return p.z(); });
  auto e = MillableVolume::fromIntensity(sdf, 1.0, 1.0);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().where.find("empty, full"), std::string::npos);
  Volume bad = sdf;
  bad.setValue(1, 2, 3, std::nan(""));
  auto n = MillableVolume::fromSdf(bad);
  ASSERT_FALSE(n.ok());
  EXPECT_NE(n.error().where.find("voxel (1, 2, 3)"), std::string::npos);
  auto bone = MillableVolume::fromSdf(sdf);
  ASSERT_TRUE(bone.ok());
  Volume labels = field(4, Vec3::Zero(), [](const Vec3&) { return 2.0; });
  auto s = bone->setMaterials({{.name = "bone"}, {.name = "dura"}}, &labels);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message().find("label 2"), std::string::npos);
  s = bone->setMaterials({{.name = "bone"}, {.name = "bone"}});
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().where.find("materials[1].name"), std::string::npos);
  s = bone->setMaterials({{.name = "bone", .hardness = 0.0}});
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().where.find("hardness"), std::string::npos);
  EXPECT_FALSE(MillingTool::sphere(-1.0).validate("tool").ok());
  EXPECT_FALSE(MillingTool::cylinder(1e-3, 0.0).validate("tool").ok());
  EXPECT_FALSE(MillingTool::voxels(nullptr).validate("tool").ok());
}

}  // namespace millable_test
}  // namespace dm
