// Device path CSV: values, interpolation, round trip, and every class of bad
// input refused with its line, column and field.
#include <dm/io/device_path.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace dm {
namespace {

TEST(DevicePath, ParsesPositionsWithHeaderCommentsAndCrlf) {
  const auto p = parseDevicePathCsv(
      "# pressed into a plane\r\nt, x, y, z\r\n\r\n0,0,0,0.01\r\n0.5,1e-3,-2e-3,+0.0\r\n", "press.csv");
  ASSERT_TRUE(p.ok()) << p.error().message();
  ASSERT_EQ(p->samples.size(), 2u);
  EXPECT_FALSE(p->hasOrientation);
  EXPECT_EQ(p->samples[1].t, 0.5);
  EXPECT_EQ(p->samples[1].position, Vec3(1e-3, -2e-3, 0.0));
  EXPECT_TRUE(p->samples[1].orientation.isApprox(Quat::Identity()));
}

TEST(DevicePath, NormalisesQuaternionsAndInterpolates) {
  const double s = std::sqrt(0.5);
  const auto p = parseDevicePathCsv("0,0,0,0,2,0,0,0\n1,1,0,0," + std::to_string(s) + ",0,0," +
                                    std::to_string(s) + "\n");
  ASSERT_TRUE(p.ok()) << p.error().message();
  EXPECT_TRUE(p->hasOrientation);
  EXPECT_NEAR(p->samples[0].orientation.norm(), 1.0, 1e-15);
  const Pose mid = p->at(0.5);
  EXPECT_NEAR(mid.p.x(), 0.5, 1e-15);
  // Half of a 90-degree turn about z.
  EXPECT_NEAR(AngleAxis(mid.q).angle(), M_PI / 4, 1e-6);
  EXPECT_EQ(p->at(-1.0).p, Vec3::Zero());  // held before the start
  EXPECT_EQ(p->at(7.0).p, Vec3(1, 0, 0));  // and after the end
}

TEST(DevicePath, FormatRoundTrips) {
  DevicePath path;
  path.hasOrientation = true;
  for (int i = 0; i < 50; ++i) {
    const double t = 0.001 * i + 1.0 / 3.0;
    path.samples.push_back({t, Vec3(std::sin(t), std::cos(3 * t), 1e-7 * i),
                            Quat(AngleAxis(0.1 * i, Vec3(1, 2, 3).normalized()))});
  }
  const auto back = parseDevicePathCsv(formatDevicePathCsv(path));
  ASSERT_TRUE(back.ok()) << back.error().message();
  ASSERT_EQ(back->samples.size(), path.samples.size());
  for (std::size_t i = 0; i < path.samples.size(); ++i) {
    EXPECT_EQ(back->samples[i].t, path.samples[i].t);
    EXPECT_EQ(back->samples[i].position, path.samples[i].position);
    EXPECT_TRUE(back->samples[i].orientation.coeffs().isApprox(path.samples[i].orientation.coeffs(), 1e-15));
  }
}

TEST(DevicePath, BadInputNamesLineColumnAndField) {
  struct Case {
    const char* text;
    const char* where;  // expected "source:line:column"
    const char* words;  // expected in the message
  };
  const Case cases[] = {
      {"", "p.csv", "no samples"},
      {"t,x,y\n", "p.csv:1:1", "header has 3"},
      {"t,x,y,w\n", "p.csv:1:7", "'w'"},
      {"0,0,0\n", "p.csv:1:1", "3 fields"},
      {"0,0,0,0\n1,0,0,0,1,0,0,0\n", "p.csv:2:1", "4 columns"},
      {"0,0,0,0,0,0,0,0,0\n", "p.csv:1:1", "or more"},
      {"0,0,abc,0\n", "p.csv:1:5", "field 'y'"},
      {"0,0,nan,0\n", "p.csv:1:5", "not a finite"},
      {"0,0,1e999,0\n", "p.csv:1:5", "not a finite"},
      {"0,0,,0\n", "p.csv:1:5", "field 'y'"},
      {"0,0,0,0\n\n0,1,1,1\n", "p.csv:3:1", "does not increase"},
      {"0,0,0,0,0,0,0,0\n", "p.csv:1:9", "zero length"},
      {"0,0,0,0\nt,x,y,z\n", "p.csv:2:1", "field 't'"},
  };
  for (const Case& c : cases) {
    const auto p = parseDevicePathCsv(c.text, "p.csv");
    ASSERT_FALSE(p.ok()) << c.text;
    EXPECT_EQ(p.error().where, c.where) << c.text << " -> " << p.error().message();
    EXPECT_NE(p.error().what.find(c.words), std::string::npos) << c.text << " -> " << p.error().message();
  }
}

TEST(DevicePath, SampleLimitIsEnforced) {
  const auto p = parseDevicePathCsv("0,0,0,0\n1,0,0,0\n2,0,0,0\n", "p.csv", {.maxSamples = 2});
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error().code, ErrorCode::InvalidArgument);
  EXPECT_EQ(p.error().where, "p.csv:3:1");
}

TEST(DevicePath, MissingFileIsNamed) {
  const auto p = readDevicePathCsv("/nonexistent/dir/path.csv");
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.error().message().find("/nonexistent/dir/path.csv"), std::string::npos);
}

}  // namespace
}  // namespace dm
