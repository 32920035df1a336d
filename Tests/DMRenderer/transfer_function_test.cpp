// TransferFunction: interpolation through the control points, range,
// validation messages, baking and opacity correction (no GL needed).
#include <dm/renderer/transfer_function.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace {

std::vector<dm::TfControlPoint> skinLike() {
  return {{0, {0, 0, 0, 0}},
          {40, {0.9, 0.1, 0.1, 0.0}},
          {60, {1.0, 0.8, 0.6, 0.9}},
          {120, {0.2, 0.9, 1.0, 0.3}},
          {255, {1, 1, 1, 1}}};
}

}  // namespace

TEST(TransferFunction, PassesThroughEveryControlPoint) {
  auto tf = dm::TransferFunction::create(skinLike());
  ASSERT_TRUE(tf) << tf.error();
  for (const dm::TfControlPoint& p : skinLike()) {
    const dm::Vec4 c = (*tf)(p.value);
    for (int ch = 0; ch < 4; ++ch)
      EXPECT_NEAR(c[ch], p.rgba[ch], 1e-12) << "value " << p.value << " ch " << ch;
  }
  // Outside the control range the end colours hold.
  EXPECT_NEAR((*tf)(-50).w(), 0.0, 1e-12);
  EXPECT_NEAR((*tf)(1000).x(), 1.0, 1e-12);
}

TEST(TransferFunction, StaysWithinUnitRangeEvenForOvershootingKinds) {
  // Natural cubic splines overshoot next to a sharp step; the channels must
  // still be clamped to [0, 1]. Check both kinds densely.
  const std::vector<dm::TfControlPoint> step = {
      {0, {0, 0, 0, 0}}, {1, {0, 0, 0, 0}}, {2, {1, 1, 1, 1}}, {3, {1, 1, 1, 1}}, {4, {0, 0, 0, 0}}};
  for (dm::SplineKind kind : {dm::SplineKind::Monotone, dm::SplineKind::Natural}) {
    auto tf = dm::TransferFunction::create(step, {.colorKind = kind, .alphaKind = kind});
    ASSERT_TRUE(tf) << tf.error();
    double lowest = 1, highest = 0;
    for (int i = -10; i <= 410; ++i) {
      const dm::Vec4 c = (*tf)(i / 100.0);
      for (int ch = 0; ch < 4; ++ch) {
        lowest = std::min(lowest, c[ch]);
        highest = std::max(highest, c[ch]);
      }
    }
    EXPECT_GE(lowest, 0.0);
    EXPECT_LE(highest, 1.0);
  }
  // The monotone kind does not leave a flat segment at all (no ringing).
  auto mono = dm::TransferFunction::create(step);
  ASSERT_TRUE(mono);
  for (int i = 0; i <= 100; ++i) EXPECT_EQ((*mono)(i / 100.0).w(), 0.0);
}

TEST(TransferFunction, ValidateNamesThePointAndChannel) {
  auto few = dm::TransferFunction::validate(std::vector<dm::TfControlPoint>{{0, {0, 0, 0, 0}}});
  ASSERT_FALSE(few);
  EXPECT_NE(few.error().what.find("1 control points"), std::string::npos) << few.error();

  auto unsorted = skinLike();
  unsorted[3].value = 50;  // below point 2's 60
  auto u = dm::TransferFunction::validate(unsorted);
  ASSERT_FALSE(u);
  EXPECT_NE(u.error().what.find("point 3"), std::string::npos) << u.error();
  EXPECT_NE(u.error().hint.find("sort"), std::string::npos);

  auto bright = skinLike();
  bright[2].rgba.w() = 1.2;
  auto b = dm::TransferFunction::validate(bright);
  ASSERT_FALSE(b);
  EXPECT_NE(b.error().what.find("point 2: alpha is 1.2"), std::string::npos) << b.error();

  auto negative = skinLike();
  negative[4].rgba.y() = -0.1;
  auto n = dm::TransferFunction::create(negative);
  ASSERT_FALSE(n);
  EXPECT_NE(n.error().what.find("point 4: green"), std::string::npos) << n.error();

  auto nanValue = skinLike();
  nanValue[1].value = std::nan("");
  EXPECT_FALSE(dm::TransferFunction::validate(nanValue));
  EXPECT_FALSE(dm::TransferFunction::create(skinLike(), {.opacityUnitLength = 0}));
}

TEST(TransferFunction, BakeSamplesEvenlyOverTheRange) {
  auto tf = dm::TransferFunction::create(skinLike());
  ASSERT_TRUE(tf);
  auto table = tf->bake(256, 0, 255);
  ASSERT_TRUE(table) << table.error();
  ASSERT_EQ(table->size(), 256u);
  for (int i : {0, 40, 60, 120, 200, 255}) {
    const dm::Vec4 ref = (*tf)(i);
    for (int ch = 0; ch < 4; ++ch) EXPECT_NEAR((*table)[static_cast<std::size_t>(i)][ch], ref[ch], 1e-6);
  }
  EXPECT_FALSE(tf->bake(1));
  EXPECT_FALSE(tf->bake(16, 5, 5));
  auto own = tf->bake(2);
  ASSERT_TRUE(own);
  EXPECT_NEAR((*own)[1].w(), 1.0, 1e-6);
}

TEST(TransferFunction, OpacityCorrectionComposesOverSubSteps) {
  // n samples of length L/n must absorb exactly like one slab of length L:
  // 1 - (1 - a_n)^n == a.
  const double a = 0.3, unit = 1e-3;
  for (int n : {1, 2, 5, 17}) {
    const double an = dm::TransferFunction::correctOpacity(a, unit / n, unit);
    EXPECT_NEAR(1.0 - std::pow(1.0 - an, n), a, 1e-12);
  }
  EXPECT_DOUBLE_EQ(dm::TransferFunction::correctOpacity(1.0, 1e-5, unit), 1.0);
  EXPECT_DOUBLE_EQ(dm::TransferFunction::correctOpacity(0.0, 1e-2, unit), 0.0);
  // Beer–Lambert: opacity over distance d with extinction -ln(1-a)/unit.
  const double d = 2.7e-3;
  EXPECT_NEAR(dm::TransferFunction::correctOpacity(a, d, unit), 1.0 - std::exp(std::log(1 - a) * d / unit),
              1e-12);
}

TEST(TransferFunction, MriPresetsAreValidAndTransparentAtBackground) {
  for (auto make :
       {&dm::TransferFunction::mriSkin, &dm::TransferFunction::mriBrain, &dm::TransferFunction::greyRamp}) {
    auto tf = make(0, 255);
    ASSERT_TRUE(tf) << tf.error();
    EXPECT_EQ((*tf)(0).w(), 0.0);
    EXPECT_GT((*tf)(255).w(), 0.0);
    EXPECT_FALSE(make(3, 3));
  }
}
