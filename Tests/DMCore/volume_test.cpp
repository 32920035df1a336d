#include <dm/core/units.hpp>
#include <dm/core/volume.hpp>

#include <gtest/gtest.h>

#include <cmath>

namespace {

dm::Affine3 mmAffine() {
  // 2 mm x 1 mm x 3 mm voxels, rotated 90° about z, origin at (10, -5, 2) mm.
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = dm::AngleAxis(M_PI / 2, dm::Vec3::UnitZ()).toRotationMatrix() *
               dm::Vec3(2, 1, 3).asDiagonal() * dm::units::mm;
  a.translation() = dm::Vec3(10, -5, 2) * dm::units::mm;
  return a;
}

// volumeSlice: each axis's picture holds exactly the voxels of that slice,
// the second remaining axis's highest index in the top row, values windowed.
TEST(Volume, SlicesAreTheRightVoxelsTheRightWayUp) {
  auto v = dm::Volume::create(dm::Vec3i(4, 5, 6), dm::VoxelType::U16);
  ASSERT_TRUE(v);
  for (int k = 0; k < 6; ++k)
    for (int j = 0; j < 5; ++j)
      for (int i = 0; i < 4; ++i) v->setValue(i, j, k, 100 * i + 10 * j + k);
  const double lo = 0, hi = 255;  // values up to 345: clamped above 255
  auto axial = dm::volumeSlice(*v, 2, 3, lo, hi);  // i across, j up
  ASSERT_TRUE(axial) << axial.error();
  EXPECT_EQ(axial->width(), 4);
  EXPECT_EQ(axial->height(), 5);
  EXPECT_EQ(axial->at<std::uint8_t>(1, 0), 100 + 40 + 3);  // top row: j = 4
  EXPECT_EQ(axial->at<std::uint8_t>(0, 4), 3);             // bottom row: j = 0
  EXPECT_EQ(axial->at<std::uint8_t>(3, 4), 255);           // 303, clamped
  auto coronal = dm::volumeSlice(*v, 1, 2, lo, hi);  // i across, k up
  ASSERT_TRUE(coronal);
  EXPECT_EQ(coronal->width(), 4);
  EXPECT_EQ(coronal->height(), 6);
  EXPECT_EQ(coronal->at<std::uint8_t>(1, 0), 100 + 20 + 5);
  auto sagittal = dm::volumeSlice(*v, 0, 99, lo, 1000);  // clamped to i = 3; j across, k up
  ASSERT_TRUE(sagittal);
  EXPECT_EQ(sagittal->width(), 5);
  EXPECT_EQ(sagittal->height(), 6);
  EXPECT_EQ(sagittal->at<std::uint8_t>(2, 5), static_cast<int>(255.0 * (300 + 20 + 0) / 1000));
  EXPECT_FALSE(dm::volumeSlice(*v, 3, 0, lo, hi));
  EXPECT_FALSE(dm::volumeSlice(*v, 2, 0, 5, 5));
  EXPECT_FALSE(dm::volumeSlice(dm::Volume{}, 2, 0, lo, hi));
}

TEST(Volume, AffineSpacingAndBounds) {
  auto v = dm::Volume::create({4, 5, 6}, dm::VoxelType::I16, mmAffine());
  ASSERT_TRUE(v) << v.error();
  EXPECT_EQ(v->voxelCount(), 120u);
  EXPECT_EQ(v->byteSize(), 240u);
  EXPECT_TRUE(v->spacing().isApprox(dm::Vec3(2, 1, 3) * 1e-3));
  const dm::Vec3 w = v->indexToWorld() * dm::Vec3(1, 0, 0);
  EXPECT_TRUE(w.isApprox(dm::Vec3(0.010, -0.003, 0.002), 1e-12));
  EXPECT_TRUE((v->worldToIndex() * w).isApprox(dm::Vec3(1, 0, 0)));
  const auto b = v->worldBounds();
  EXPECT_NEAR(b.sizes().x(), 4e-3, 1e-15);  // 4 voxels of 1 mm along j mapped to -x
  EXPECT_NEAR(b.sizes().y(), 6e-3, 1e-15);
  EXPECT_NEAR(b.sizes().z(), 15e-3, 1e-15);
}

TEST(Volume, TrilinearSamplingReproducesLinearField) {
  auto v = dm::Volume::create({5, 6, 7}, dm::VoxelType::F64, mmAffine());
  ASSERT_TRUE(v);
  auto f = [](double i, double j, double k) { return 3 * i - 2 * j + 0.5 * k + 7; };
  for (int k = 0; k < 7; ++k)
    for (int j = 0; j < 6; ++j)
      for (int i = 0; i < 5; ++i) v->setValue(i, j, k, f(i, j, k));
  EXPECT_NEAR(v->sampleIndex({1.25, 2.5, 3.75}), f(1.25, 2.5, 3.75), 1e-12);
  const dm::Vec3 p = v->indexToWorld() * dm::Vec3(3.5, 0.2, 5.9);
  EXPECT_NEAR(v->sampleWorld(p), f(3.5, 0.2, 5.9), 1e-9);
  // Gradient in world units: d/dworld = A^{-T} d/dindex.
  const dm::Vec3 g = v->gradientWorld(2, 2, 2);
  const dm::Vec3 expected = v->worldToIndex().linear().transpose() * dm::Vec3(3, -2, 0.5);
  EXPECT_TRUE(g.isApprox(expected, 1e-9));
  auto [lo, hi] = v->range();
  EXPECT_DOUBLE_EQ(lo, f(0, 5, 0));
  EXPECT_DOUBLE_EQ(hi, f(4, 0, 6));
}

TEST(Volume, IntegerStoresRoundAndSaturate) {
  auto v = dm::Volume::create({2, 1, 1}, dm::VoxelType::U8);
  ASSERT_TRUE(v);
  v->setValue(0, 0, 0, 300.0);
  v->setValue(1, 0, 0, 41.6);
  EXPECT_EQ(v->value(0, 0, 0), 255);
  EXPECT_EQ(v->data<std::uint8_t>()[1], 42);
}

TEST(Volume, RejectsBadGeometryWithClearErrors) {
  auto a = dm::Volume::create({0, 10, 10}, dm::VoxelType::U8);
  ASSERT_FALSE(a);
  EXPECT_NE(a.error().what.find("must all be positive"), std::string::npos);
  auto b = dm::Volume::create({100000, 100000, 100000}, dm::VoxelType::F64);
  ASSERT_FALSE(b);
  EXPECT_NE(b.error().what.find("exceed the limit"), std::string::npos);
  dm::Affine3 singular = dm::Affine3::Identity();
  singular.linear()(2, 2) = 0;
  EXPECT_FALSE(dm::Volume::create({2, 2, 2}, dm::VoxelType::U8, singular));
  dm::Affine3 nan = dm::Affine3::Identity();
  nan.translation().x() = std::nan("");
  auto c = dm::Volume::create({2, 2, 2}, dm::VoxelType::U8, nan);
  ASSERT_FALSE(c);
  EXPECT_NE(c.error().what.find("NaN"), std::string::npos);
}

}  // namespace
