// HapticMaterial validation: every bad field is refused by name.
#include "../common/alloc_counter.hpp"

#include <dm/haptics/renderer.hpp>

#include <gtest/gtest.h>

#include <limits>

namespace dm {
namespace {

TEST(HapticMaterial, DefaultsAndSensibleValuesAreValid) {
  EXPECT_TRUE(HapticMaterial{}.validate("m").ok());
  EXPECT_TRUE((HapticMaterial{.stiffness = 500, .damping = 1, .staticFriction = 0.5, .dynamicFriction = 0.3})
                  .validate("m")
                  .ok());
}

TEST(HapticMaterial, BadFieldsAreNamed) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  struct Case {
    HapticMaterial m;
    const char* field;
  };
  const Case cases[] = {
      {{.stiffness = 0}, "stiffness"},
      {{.stiffness = nan}, "stiffness"},
      {{.damping = -1}, "damping"},
      {{.staticFriction = -0.1}, "staticFriction"},
      {{.staticFriction = 0.2, .dynamicFriction = 0.3}, "dynamicFriction"},
      {{.dynamicFriction = nan}, "dynamicFriction"},
  };
  for (const Case& c : cases) {
    const Status s = c.m.validate("scene.json:/objects/0/material");
    ASSERT_FALSE(s.ok()) << c.field;
    EXPECT_EQ(s.error().code, ErrorCode::InvalidArgument);
    EXPECT_NE(s.error().where.find(c.field), std::string::npos) << s.error().where;
    EXPECT_NE(s.error().where.find("scene.json:/objects/0/material"), std::string::npos);
  }
}

TEST(IsRigidPose, AcceptsRotationsAndRefusesScalesShearsMirrorsAndNaN) {
  Isometry3 p = Isometry3::Identity();
  p.linear() = AngleAxis(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  p.translation() = Vec3(1, -2, 3);
  EXPECT_TRUE(isRigidPose(p));
  Isometry3 scaled = p;
  scaled.linear() *= 1.01;
  EXPECT_FALSE(isRigidPose(scaled));
  Isometry3 mirrored = p;
  mirrored.linear().col(0) *= -1.0;
  EXPECT_FALSE(isRigidPose(mirrored));
  Isometry3 sheared = Isometry3::Identity();
  sheared.linear()(0, 1) = 0.1;
  EXPECT_FALSE(isRigidPose(sheared));
  Isometry3 nan = p;
  nan.translation().x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(isRigidPose(nan));
}

TEST(AllocCounter, CountsAllocationsOnFlaggedThreadsOnly) {
  const auto before = test::countedAllocations();
  test::tCountAllocations = true;
  test::allocateOnce();
  test::tCountAllocations = false;
  test::allocateOnce();  // not counted
  EXPECT_EQ(test::countedAllocations(), before + 1);
}

}  // namespace
}  // namespace dm
