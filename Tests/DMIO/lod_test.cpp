// Levels of detail of a real anatomy surface: the Colin27 skin isosurface
// (mricron:ch2.nii.gz) simplified to 50 %, 20 % and 5 % of its triangles
// stays a closed, consistently oriented manifold of the same genus, keeps its
// enclosed volume, and reports a measured distance to the unsimplified skin.
// The scan is box-filtered to 3 mm (5 mm for the error-budget case) first so
// that the file runs in seconds; the 1 mm skin (1.3 M triangles) is the
// throughput case in the report.
#include <dm/core/filesystem.hpp>
#include <dm/io/nifti.hpp>
#include <dm/math/isosurface.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/math/simplify.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <utility>

namespace {

/// The Colin27 volume box-filtered by `f` in each axis (block means, F32),
/// placed at the centres of the blocks.
dm::Volume colin27(int f) {
  static const dm::Result<dm::Volume> vol = []() -> dm::Result<dm::Volume> {
    auto path = dm::FileSystem::global().resolve("mricron:ch2.nii.gz");
    if (!path) return path.error();
    return dm::readNifti(*path);
  }();
  EXPECT_TRUE(vol) << vol.error() << " (scripts/setup.sh installs mricron-data)";
  const dm::Vec3i d = vol->dims() / f;
  const dm::Affine3 a = vol->indexToWorld() * Eigen::Translation3d(dm::Vec3::Constant(0.5 * (f - 1))) *
                        Eigen::Scaling(static_cast<double>(f));
  auto out = dm::Volume::create(d, dm::VoxelType::F32, a);
  EXPECT_TRUE(out) << out.error();
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i) {
        double sum = 0;
        for (int c = 0; c < f * f * f; ++c)
          sum += vol->value(f * i + c % f, f * j + (c / f) % f, f * k + c / (f * f));
        out->setValue(i, j, k, sum / (f * f * f));
      }
  return std::move(*out);
}

TEST(Lod, Colin27SkinLevelsStayClosedManifoldsCloseToTheScan) {
  const dm::Volume vol = colin27(3);
  ASSERT_FALSE(vol.empty());
  auto skin = dm::extractIsosurface(vol, {.iso = 40.5, .computeNormals = false, .closeBorders = true});
  ASSERT_TRUE(skin) << skin.error();
  const dm::MeshTopology input = dm::analyzeTopology(*skin);
  ASSERT_TRUE(input.isClosed && input.isManifold && input.genus && input.volume);

  const std::array<double, 3> ratios = {0.5, 0.2, 0.05};
  auto lods = dm::buildLods(*skin, ratios);
  ASSERT_TRUE(lods) << lods.error();
  ASSERT_EQ(lods->size(), 4u);
  const double voxel = vol.spacing().maxCoeff();  // 3 mm
  for (std::size_t i = 1; i < lods->size(); ++i) {
    SCOPED_TRACE(i);
    const dm::MeshLod& lod = (*lods)[i];
    EXPECT_NEAR(lod.ratio, ratios[i - 1], 0.01);
    const dm::MeshTopology t = dm::analyzeTopology(lod.mesh);
    EXPECT_TRUE(t.isClosed);
    EXPECT_TRUE(t.isManifold);
    EXPECT_TRUE(t.isOrientedConsistently);
    EXPECT_EQ(t.degenerateTriangles, 0u);
    EXPECT_EQ(t.components, input.components);
    ASSERT_TRUE(t.genus && t.volume);
    EXPECT_EQ(*t.genus, *input.genus);
    EXPECT_NEAR(*t.volume / *input.volume, 1.0, 0.01);
    // The measured distance grows with the reduction and stays within a few
    // voxels even at 5 % (the largest deviations are at the ears and nostrils).
    EXPECT_GT(lod.maxDistance, 0.0);
    EXPECT_GE(lod.maxDistance, (*lods)[i - 1].maxDistance);
    EXPECT_LT(lod.maxDistance, 5.0 * voxel);
    std::printf("[ LOD %zu   ] %zu triangles (%.1f %%), max distance %.3f mm\n", i, lod.mesh.triangleCount(),
                100.0 * lod.ratio, lod.maxDistance * 1e3);
  }
}

TEST(Lod, Colin27SkinWithinAnErrorBudgetStaysWithinIt) {
  const dm::Volume vol = colin27(5);
  ASSERT_FALSE(vol.empty());
  auto skin = dm::extractIsosurface(vol, {.iso = 40.5, .computeNormals = false, .closeBorders = true});
  ASSERT_TRUE(skin) << skin.error();
  constexpr double kBudget = 1e-3;  // a fifth of a voxel
  dm::SimplifyReport report;
  auto out = dm::simplifyMesh(*skin, {.targetRatio = 0.02, .maxError = kBudget}, &report);
  ASSERT_TRUE(out) << out.error();
  EXPECT_LT(report.trianglesAfter, report.trianglesBefore / 2);
  EXPECT_GT(report.trianglesAfter, report.trianglesBefore / 50);  // the budget stopped it early
  // The budget holds at the points the simplifier checks (the report's
  // vertices, midpoints and centroids)...
  EXPECT_LE(report.maxDistance, kBudget * (1 + 1e-9));
  // ...and, up to the sampling of the original between those points (its
  // triangles here are ~3 mm, larger than the budget), at random points too.
  EXPECT_LE(dm::hausdorffDistance(*out, *skin, 8), kBudget * 1.25);
  const dm::MeshTopology t = dm::analyzeTopology(*out);
  EXPECT_TRUE(t.isClosed && t.isManifold && t.isOrientedConsistently);
  std::printf("[ budget  ] %zu -> %zu triangles within %.2f mm (reported %.3f mm)\n", report.trianglesBefore,
              report.trianglesAfter, kBudget * 1e3, report.maxDistance * 1e3);
}

}  // namespace
