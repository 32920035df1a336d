// OpenVDB I/O: sparse round trips of analytic fields, narrow-band level sets
// from voxelizeMesh(), bad files; and the Colin27 skin voxelized (the
// patient-model pipeline: NIfTI -> isosurface -> occupancy).
#include <dm/core/filesystem.hpp>
#include <dm/io/nifti.hpp>
#include <dm/io/vdb.hpp>
#include <dm/math/convex_hull.hpp>
#include <dm/math/isosurface.hpp>
#include <dm/math/mass_properties.hpp>
#include <dm/math/voxelize.hpp>

#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace {

namespace fs = std::filesystem;
using dm::Vec3;

/// A per-test scratch file path, removed afterwards.
class ScratchFile {
 public:
  explicit ScratchFile(const std::string& name)
      : path_(fs::temp_directory_path() / ("dm_vdb_test_" + std::to_string(::getpid()) + "_" + name)) {}
  ~ScratchFile() {
    std::error_code ec;
    fs::remove(path_, ec);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

/// A rotated, scaled, translated affine with distinct spacings.
dm::Affine3 tiltedAffine(double h) {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = dm::AngleAxis(0.4, Vec3(1, -2, 0.5).normalized()).toRotationMatrix() *
               Vec3(h, 1.25 * h, 0.8 * h).asDiagonal();
  a.translation() = Vec3(-0.031, 0.0127, 0.2);
  return a;
}

/// Volume of `type` with f(world centre) at every voxel.
template <class F>
dm::Volume analyticVolume(const dm::Vec3i& dims, dm::VoxelType type, const dm::Affine3& a, F&& f) {
  auto v = dm::Volume::create(dims, type, a).value();
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i) v.setValue(i, j, k, f(a * Vec3(i, j, k)));
  return v;
}

std::size_t activeVoxels(const std::string& description) {
  // "name (type, class, N active voxels)"
  const auto count = description.rfind(", ");
  EXPECT_NE(description.find("active voxels", count), std::string::npos) << description;
  return std::stoull(description.substr(count + 2));
}

TEST(Vdb, FogRoundTripKeepsValuesAffineAndSparsity) {
  const double h = 0.002, r = 0.012;
  const dm::Affine3 a = tiltedAffine(h);
  const Vec3 centre = a * Vec3(15, 12, 20);
  // A density ball: 1 at the centre, 0 beyond r, so most voxels are background.
  const dm::Volume fog = analyticVolume({30, 24, 40}, dm::VoxelType::F32, a, [&](const Vec3& p) {
    return std::max(0.0, 1.0 - (p - centre).norm() / r);
  });
  std::size_t nonzero = 0;
  for (std::size_t n = 0; n < fog.voxelCount(); ++n) nonzero += fog.valueAt(n) != 0;
  ASSERT_GT(nonzero, 100u);
  ASSERT_LT(nonzero, fog.voxelCount() / 4);

  ScratchFile file("fog.vdb");
  ASSERT_TRUE(dm::writeVdb(fog, file.path(), {.gridName = "ball"}));
  auto grids = dm::listVdbGrids(file.path());
  ASSERT_TRUE(grids) << grids.error();
  ASSERT_EQ(grids->size(), 1u);
  EXPECT_EQ((*grids)[0].rfind("ball (float", 0), 0u) << (*grids)[0];
  EXPECT_EQ(activeVoxels((*grids)[0]), nonzero) << "only non-background voxels are stored";

  auto back = dm::readVdb(file.path());
  ASSERT_TRUE(back) << back.error();
  EXPECT_EQ(back->type(), dm::VoxelType::F32);
  ASSERT_EQ(back->dims(), fog.dims());
  EXPECT_LT((back->indexToWorld().matrix() - a.matrix()).cwiseAbs().maxCoeff(), 1e-12);
  for (std::size_t n = 0; n < fog.voxelCount(); ++n) ASSERT_EQ(back->valueAt(n), fog.valueAt(n)) << n;

  // With a tolerance, small densities are dropped (read back as the background 0).
  ASSERT_TRUE(dm::writeVdb(fog, file.path(), {.gridName = "ball", .tolerance = 0.5}));
  auto coarse = dm::readVdb(file.path(), {.gridName = "ball"});
  ASSERT_TRUE(coarse) << coarse.error();
  ASSERT_EQ(coarse->dims(), fog.dims());
  for (std::size_t n = 0; n < fog.voxelCount(); ++n)
    ASSERT_EQ(coarse->valueAt(n), fog.valueAt(n) > 0.5 ? fog.valueAt(n) : 0.0) << n;
}

TEST(Vdb, DoubleVolumesStayDouble) {
  const dm::Volume v = analyticVolume({8, 9, 10}, dm::VoxelType::F64, tiltedAffine(1e-3),
                                      [](const Vec3& p) { return std::sin(1000 * p.x()) + 1e-12 * p.y(); });
  ScratchFile file("double.vdb");
  ASSERT_TRUE(dm::writeVdb(v, file.path()));
  auto back = dm::readVdb(file.path());
  ASSERT_TRUE(back) << back.error();
  EXPECT_EQ(back->type(), dm::VoxelType::F64);
  for (std::size_t n = 0; n < v.voxelCount(); ++n) ASSERT_EQ(back->valueAt(n), v.valueAt(n));
}

TEST(Vdb, LevelSetKeepsTheNarrowBandOnly) {
  const double h = 0.001, r = 0.015;
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() *= h;
  a.translation() = Vec3::Constant(-0.02);
  const dm::Volume sdf =
      analyticVolume({41, 41, 41}, dm::VoxelType::F32, a, [&](const Vec3& p) { return p.norm() - r; });
  const double halfWidth = 3.0, background = halfWidth * h;
  std::size_t band = 0;
  for (std::size_t n = 0; n < sdf.voxelCount(); ++n)
    band += std::abs(static_cast<float>(sdf.valueAt(n))) < static_cast<float>(background);

  ScratchFile file("sphere_ls.vdb");
  ASSERT_TRUE(
      dm::writeVdb(sdf, file.path(), {.gridName = "sphere", .levelSet = true, .halfWidthVoxels = halfWidth}));
  auto grids = dm::listVdbGrids(file.path());
  ASSERT_TRUE(grids) << grids.error();
  ASSERT_EQ(grids->size(), 1u);
  EXPECT_NE((*grids)[0].find("level set"), std::string::npos) << (*grids)[0];
  EXPECT_EQ(activeVoxels((*grids)[0]), band);

  auto back = dm::readVdb(file.path(), {.gridName = "sphere"});
  ASSERT_TRUE(back) << back.error();
  ASSERT_EQ(back->dims(), sdf.dims());
  for (std::size_t n = 0; n < sdf.voxelCount(); ++n) {
    const auto d = static_cast<float>(sdf.valueAt(n));
    // In the band: the value; beyond: ±background, signed by the flood fill.
    const double expected = std::abs(d) < background ? d : std::copysign(background, d);
    ASSERT_NEAR(back->valueAt(n), expected, 1e-7) << n;
  }
}

TEST(Vdb, VoxelizedLevelSetMatchesTheAnalyticSphere) {
  // A convex polyhedron inscribed in a sphere, voxelized to an SDF and written as a level set.
  const double r = 0.02, h = 0.001;
  std::vector<Vec3> pts;
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  constexpr int kPoints = 2000;
  for (int i = 0; i < kPoints; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / kPoints, rho = std::sqrt(1 - z * z);
    pts.push_back(r * Vec3(rho * std::cos(golden * i), rho * std::sin(golden * i), z));
  }
  const dm::Mesh mesh = dm::convexHull(pts).value();
  double inradius = r;
  for (std::size_t t = 0; t < mesh.triangleCount(); ++t)
    inradius = std::min(inradius, mesh.faceNormal(t).dot(mesh.positions[mesh.triangles[t][0]]));
  const double tessellation = r - inradius;

  auto sdf = dm::voxelizeMesh(mesh, {.voxelSize = h, .signedDistance = true, .bandWidth = 3 * h});
  ASSERT_TRUE(sdf) << sdf.error();
  ScratchFile file("voxelized_ls.vdb");
  ASSERT_TRUE(dm::writeVdb(*sdf, file.path(), {.gridName = "surface", .levelSet = true}));
  auto back = dm::readVdb(file.path());
  ASSERT_TRUE(back) << back.error();
  ASSERT_EQ(back->dims(), sdf->dims());
  EXPECT_LT((back->indexToWorld().matrix() - sdf->indexToWorld().matrix()).cwiseAbs().maxCoeff(), 1e-15);
  const double background = 3 * h;
  double maxErr = 0;
  std::size_t wrongSign = 0;
  const dm::Vec3i d = back->dims();
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i) {
        const Vec3 p = back->indexToWorld() * Vec3(i, j, k);
        const double exact = p.norm() - r, got = back->value(i, j, k);
        if (std::abs(exact) > tessellation) wrongSign += (got < 0) != (exact < 0);
        maxErr = std::max(maxErr, std::abs(got - std::clamp(exact, -background, background)));
      }
  EXPECT_EQ(wrongSign, 0u);
  EXPECT_LT(maxErr, tessellation + 1e-6) << "tessellation error " << tessellation;
}

TEST(Vdb, RejectsBadFiles) {
  auto missing = dm::readVdb("/nonexistent/dir/none.vdb");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, dm::ErrorCode::NotFound);
  EXPECT_FALSE(dm::listVdbGrids("/nonexistent/dir/none.vdb"));

  ScratchFile text("text.vdb");
  { std::ofstream(text.path()) << "this is not a VDB file, just some text that is long enough\n"; }
  auto notVdb = dm::readVdb(text.path());
  ASSERT_FALSE(notVdb);
  EXPECT_EQ(notVdb.error().code, dm::ErrorCode::Parse);
  EXPECT_NE(notVdb.error().where.find(text.path().string()), std::string::npos) << notVdb.error();

  // A valid file cut short at several places: an error, never a crash.
  const dm::Volume v =
      analyticVolume({20, 20, 20}, dm::VoxelType::F32, tiltedAffine(1e-3),
                     [](const Vec3& p) { return std::cos(500 * p.x()) * std::sin(300 * p.z()); });
  ScratchFile good("good.vdb");
  ASSERT_TRUE(dm::writeVdb(v, good.path(), {.gridName = "wave"}));
  auto bytes = dm::readFile(good.path());
  ASSERT_TRUE(bytes) << bytes.error();
  ScratchFile cut("cut.vdb");
  for (double fraction : {0.01, 0.05, 0.3, 0.6, 0.95}) {
    const auto n = static_cast<std::size_t>(fraction * static_cast<double>(bytes->size()));
    {
      std::ofstream out(cut.path(), std::ios::binary);
      out.write(reinterpret_cast<const char*>(bytes->data()), static_cast<std::streamsize>(n));
    }
    auto r = dm::readVdb(cut.path());
    EXPECT_FALSE(r) << "cut at " << n << " of " << bytes->size();
    auto m = dm::parseVdb(std::span(bytes->data(), n), "cut");
    EXPECT_FALSE(m) << "cut at " << n << " of " << bytes->size();
  }
  // The whole file parses from memory too, to the same volume.
  auto mem = dm::parseVdb(*bytes, "good");
  ASSERT_TRUE(mem) << mem.error();
  for (std::size_t n = 0; n < v.voxelCount(); ++n) ASSERT_EQ(mem->valueAt(n), v.valueAt(n));

  auto unknown = dm::readVdb(good.path(), {.gridName = "density"});
  ASSERT_FALSE(unknown);
  EXPECT_EQ(unknown.error().code, dm::ErrorCode::NotFound);
  EXPECT_NE(unknown.error().hint.find("wave"), std::string::npos) << unknown.error();

  auto tooBig = dm::readVdb(good.path(), {.maxBytes = 20 * 20 * 20 * 4 - 1});
  ASSERT_FALSE(tooBig);
  EXPECT_EQ(tooBig.error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_TRUE(dm::readVdb(good.path(), {.maxBytes = 20 * 20 * 20 * 4}));

  // Writing: bad options and an unwritable place fail cleanly.
  EXPECT_FALSE(dm::writeVdb(v, "/nonexistent/dir/out.vdb"));
  EXPECT_FALSE(dm::writeVdb(v, good.path(), {.gridName = ""}));
  EXPECT_FALSE(dm::writeVdb(v, good.path(), {.levelSet = true, .halfWidthVoxels = 0}));
  EXPECT_FALSE(dm::writeVdb(dm::Volume::create({2, 2, 2}, dm::VoxelType::U8).value(), good.path(),
                            {.levelSet = true}));
  EXPECT_FALSE(dm::writeVdb(dm::Volume{}, good.path()));
}

// The offset of `text` in `bytes` (the first), or npos.
std::size_t findBytes(const std::vector<std::byte>& bytes, const std::string& text) {
  const auto* b = reinterpret_cast<const char*>(bytes.data());
  return std::string_view(b, bytes.size()).find(text);
}

TEST(Vdb, ADeclaredBoxOverTheBudgetIsRefusedBeforeTheTreeIsRead) {
  const dm::Volume v = analyticVolume({12, 10, 8}, dm::VoxelType::F32, tiltedAffine(1e-3),
                                      [](const Vec3& p) { return 1.0 + std::cos(400 * p.x()); });
  ScratchFile good("declared.vdb");
  ASSERT_TRUE(dm::writeVdb(v, good.path(), {.gridName = "fog"}));
  auto bytes = dm::readFile(good.path());
  ASSERT_TRUE(bytes) << bytes.error();
  // The metadata entry writeVdb records: name, type "vec3i", size 12, then
  // the three int32 of the dense box's upper corner; and the transform's
  // type name, which follows the grid's metadata.
  const std::size_t entry = findBytes(*bytes, "dm_dense_max");
  ASSERT_NE(entry, std::string::npos);
  const std::size_t value = entry + std::strlen("dm_dense_max") + 4 + std::strlen("vec3i") + 4;
  std::int32_t corner[3];
  std::memcpy(corner, bytes->data() + value, sizeof corner);
  ASSERT_EQ(corner[0], 11);
  ASSERT_EQ(corner[2], 7);
  const std::size_t transform = findBytes(*bytes, "Map");
  ASSERT_NE(transform, std::string::npos);
  ASSERT_GT(transform, value);
  // Cut the file inside the grid's transform: no tree can be read from it.
  std::vector<std::byte> cut(bytes->begin(), bytes->begin() + static_cast<std::ptrdiff_t>(transform + 8));
  auto truncated = dm::parseVdb(cut, "cut.vdb");
  ASSERT_FALSE(truncated);
  EXPECT_EQ(truncated.error().code, dm::ErrorCode::Parse) << truncated.error();
  // The same cut file declaring a 4000^3 box: refused from the declaration,
  // over the budget, naming the grid — before the tree it does not have.
  const std::int32_t huge[3] = {3999, 3999, 3999};
  std::memcpy(cut.data() + value, huge, sizeof huge);
  auto declared = dm::parseVdb(cut, "cut.vdb");
  ASSERT_FALSE(declared);
  EXPECT_EQ(declared.error().code, dm::ErrorCode::InvalidArgument) << declared.error();
  EXPECT_NE(declared.error().what.find("declared box 4000 x 4000 x 4000"), std::string::npos)
      << declared.error();
  EXPECT_NE(declared.error().where.find("grid \"fog\""), std::string::npos) << declared.error();
  // The whole file declaring it: the same refusal; with a budget that holds
  // the declared box, it reads (the declaration widens the dense box).
  std::vector<std::byte> whole = *bytes;
  const std::int32_t wider[3] = {15, 10, 9};
  std::memcpy(whole.data() + value, huge, sizeof huge);
  EXPECT_FALSE(dm::parseVdb(whole, "whole.vdb"));
  std::memcpy(whole.data() + value, wider, sizeof wider);
  auto read = dm::parseVdb(whole, "whole.vdb", {.maxBytes = 16 * 11 * 10 * 4});
  ASSERT_TRUE(read) << read.error();
  EXPECT_EQ(read->dims(), dm::Vec3i(16, 11, 10));
  EXPECT_FALSE(dm::parseVdb(whole, "whole.vdb", {.maxBytes = 16 * 11 * 10 * 4 - 1}));
}

TEST(Vdb, Colin27SkinVoxelizesToItsMeshVolume) {
  auto path = dm::FileSystem::global().resolve("mricron:ch2.nii.gz");
  ASSERT_TRUE(path) << path.error() << " (scripts/setup.sh installs mricron-data)";
  auto head = dm::readNifti(*path);
  ASSERT_TRUE(head) << head.error();
  auto skin = dm::extractIsosurface(*head, {.iso = 40.5, .computeNormals = false, .closeBorders = true});
  ASSERT_TRUE(skin) << skin.error();
  auto mass = dm::computeMassProperties(*skin);
  ASSERT_TRUE(mass) << mass.error();

  const double h = 0.002;
  auto occ = dm::voxelizeMesh(*skin, {.voxelSize = h});
  ASSERT_TRUE(occ) << occ.error();
  std::size_t inside = 0;
  const auto* bits = occ->data<std::uint8_t>();
  for (std::size_t n = 0; n < occ->voxelCount(); ++n) inside += bits[n];
  const double occupied = static_cast<double>(inside) * h * h * h;
  EXPECT_NEAR(occupied, mass->volume, 0.03 * mass->volume) << "mesh volume " << mass->volume << " m^3";
}

}  // namespace

// The isolated readers (the helper program, the default, and a forked
// child) return the same volume as the in-process one, and a truncated
// stream comes back as an Error. Run first in its own process (as ctest
// does), before any worker threads exist: a fork is only safe there.
TEST(Vdb, IsolatedReadMatchesAndFailsCleanly) {
  const char* root = std::getenv("DM_SOURCE_DIR");
  if (!root) GTEST_SKIP() << "DM_SOURCE_DIR is not set (ctest sets it)";
  const std::filesystem::path seed = std::filesystem::path(root) / "Tests/fuzz/corpus/vdb_fuzz/fog.vdb";
  auto bytes = dm::readFile(seed);
  ASSERT_TRUE(bytes) << bytes.error();
  dm::VdbReadOptions trusted;
  trusted.isolation = dm::Isolation::InProcess;
  auto direct = dm::parseVdb(*bytes, seed.string(), trusted);
  ASSERT_TRUE(direct) << direct.error();
  for (const dm::Isolation isolation : {dm::Isolation::Helper, dm::Isolation::Fork}) {
    SCOPED_TRACE(dm::toString(isolation));
    dm::VdbReadOptions iso;
    iso.isolation = isolation;
    iso.timeoutSeconds = 30;
    auto isolated = dm::parseVdb(*bytes, seed.string(), iso);
    ASSERT_TRUE(isolated) << isolated.error();
    EXPECT_EQ(isolated->dims(), dm::Vec3i(9, 9, 9));
    auto cut = dm::parseVdb(std::span(bytes->data(), bytes->size() / 2), "half.vdb", iso);
    ASSERT_FALSE(cut);
    EXPECT_FALSE(cut.error().what.empty());
    EXPECT_TRUE(direct->indexToWorld().isApprox(isolated->indexToWorld(), 0.0));
    for (std::size_t i = 0; i < direct->voxelCount(); ++i)
      ASSERT_EQ(direct->valueAt(i), isolated->valueAt(i));
  }
}
