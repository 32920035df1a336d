// The patient-model pipeline end to end on real data: Colin27 loads with its
// sform, and its skin isosurface is a closed manifold lying where the scan
// puts it in world coordinates.
#include <dm/core/filesystem.hpp>
#include <dm/io/nifti.hpp>
#include <dm/math/isosurface.hpp>
#include <dm/math/mesh_topology.hpp>

#include <gtest/gtest.h>

#include <limits>

namespace {

TEST(PatientModel, Colin27SkinIsClosedManifoldAndPlacedByTheSform) {
  auto path = dm::FileSystem::global().resolve("mricron:ch2.nii.gz");
  ASSERT_TRUE(path) << path.error() << " (scripts/setup.sh installs mricron-data)";
  auto vol = dm::readNifti(*path);
  ASSERT_TRUE(vol) << vol.error();
  constexpr double kIso = 40.5;  // between integer levels: no vertex lands exactly on a voxel
  auto skin = dm::extractIsosurface(*vol, {.iso = kIso, .closeBorders = true});
  ASSERT_TRUE(skin) << skin.error();
  const dm::MeshTopology topo = dm::analyzeTopology(*skin);
  EXPECT_TRUE(topo.isClosed);
  EXPECT_TRUE(topo.isManifold);
  EXPECT_TRUE(topo.isOrientedConsistently);
  ASSERT_TRUE(topo.volume.has_value());
  // A head encloses a few litres: 1.5 L < V < 6 L (closed cavities count negatively).
  EXPECT_GT(*topo.volume, 1.5e-3);
  EXPECT_LT(*topo.volume, 6e-3);

  // Independent placement check: the index-space box of voxels above iso,
  // mapped through the sform, must match the mesh bounds within one voxel.
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  const dm::Vec3i d = vol->dims();
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i)
        if (vol->value(i, j, k) > kIso) {
          lo = lo.cwiseMin(dm::Vec3(i, j, k));
          hi = hi.cwiseMax(dm::Vec3(i, j, k));
        }
  dm::Aabb expected;
  for (int c = 0; c < 8; ++c)
    expected.extend(vol->indexToWorld() * dm::Vec3((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(),
                                                   (c & 4) ? hi.z() : lo.z()));
  const dm::Aabb got = skin->bounds();
  const double voxel = vol->spacing().maxCoeff();
  EXPECT_LT((got.min() - expected.min()).cwiseAbs().maxCoeff(), voxel) << got.min().transpose();
  EXPECT_LT((got.max() - expected.max()).cwiseAbs().maxCoeff(), voxel) << got.max().transpose();
  // Colin27's sform puts the head around the MNI origin, in metres: x spans about ±90 mm.
  EXPECT_NEAR(got.min().x(), -0.090, 0.005);
  EXPECT_NEAR(got.max().x(), 0.090, 0.005);
}

}  // namespace
