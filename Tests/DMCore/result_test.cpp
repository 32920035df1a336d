#include <dm/core/result.hpp>

#include <gtest/gtest.h>

#include <memory>
#include <sstream>

namespace {

dm::Result<int> parsePositive(int x) {
  if (x <= 0)
    return dm::fail(dm::ErrorCode::InvalidArgument, "value must be > 0, got " + std::to_string(x),
                    "config.json: /rate_hz", "use a positive rate");
  return x;
}

TEST(Result, CarriesValueOrError) {
  auto good = parsePositive(5);
  ASSERT_TRUE(good);
  EXPECT_EQ(*good, 5);
  auto bad = parsePositive(-1);
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_EQ(bad.error().message(),
            "config.json: /rate_hz: invalid argument: value must be > 0, got -1 (use a positive rate)");
  EXPECT_EQ(bad.valueOr(7), 7);
}

TEST(Result, MoveOnlyValues) {
  dm::Result<std::unique_ptr<int>> r = std::make_unique<int>(3);
  ASSERT_TRUE(r);
  std::unique_ptr<int> p = std::move(r).value();
  EXPECT_EQ(*p, 3);
}

TEST(Result, StatusAndWithin) {
  dm::Status s = dm::ok();
  EXPECT_TRUE(s);
  dm::Status f = dm::fail(dm::ErrorCode::Parse, "unexpected token", "byte 12");
  ASSERT_FALSE(f);
  auto outer = f.error().within("scene.json");
  EXPECT_EQ(outer.where, "scene.json: byte 12");
  std::ostringstream os;
  os << outer;
  EXPECT_NE(os.str().find("unexpected token"), std::string::npos);
}

TEST(ResultDeathTest, ValueOfErrorAborts) {
  auto bad = parsePositive(0);
  EXPECT_DEATH((void)bad.value(), "value must be > 0");
}

TEST(ResultDeathTest, DemandAborts) {
  EXPECT_DEATH(DM_DEMAND(1 + 1 == 3, "arithmetic"), "DM_DEMAND\\(1 \\+ 1 == 3\\) failed: arithmetic");
}

}  // namespace
