#include <dm/core/config.hpp>

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

namespace {

TEST(Config, SyntaxErrorNamesLineColumnAndByte) {
  auto c = dm::Config::parse("{\n  \"a\": 1,\n  \"b\" 2\n}", "scene.json");
  ASSERT_FALSE(c);
  EXPECT_EQ(c.error().code, dm::ErrorCode::Parse);
  EXPECT_NE(c.error().what.find("line 3"), std::string::npos) << c.error();
  EXPECT_NE(c.error().where.find("scene.json: byte"), std::string::npos) << c.error();
}

TEST(Config, MissingFileNamesPath) {
  auto c = dm::Config::load("/nonexistent/dir/scene.json");
  ASSERT_FALSE(c);
  EXPECT_EQ(c.error().code, dm::ErrorCode::NotFound);
  EXPECT_EQ(c.error().where, "/nonexistent/dir/scene.json");
}

TEST(Config, TypedAccessWithPathsInEveryError) {
  auto c = dm::Config::parse(R"({
    "haptics": { "rate_hz": -5, "renderer": "godobjekt", "device": 3 },
    "render": { "camera": { "distance": 0.5, "up": [0, 1] } },
    "objects": [ { "name": "skin" }, { "nmae": "bone" } ],
    "rate_Hz": 10
  })",
                             "scene.json");
  ASSERT_TRUE(c) << c.error();
  dm::ConfigReader r = c->reader();
  auto h = r.child("haptics", true);
  EXPECT_EQ(h.number("rate_hz", {.min = 100, .max = 10000}, 1000.0), 1000.0);
  EXPECT_EQ(h.oneOf("renderer", {"godobject", "pointshell"}, std::string("godobject")), "godobject");
  EXPECT_EQ(h.string("device", std::string("none")), "none");
  auto cam = r.child("render").child("camera");
  EXPECT_DOUBLE_EQ(cam.number("distance", {.min = 0}), 0.5);
  (void)cam.numbers("up", 3, std::vector<double>{0, 0, 1});
  auto objs = r.child("objects");
  ASSERT_TRUE(objs.isArray());
  EXPECT_EQ(objs.at(0).string("name"), "skin");
  (void)objs.at(1).string("name");
  objs.at(1).knownKeys({"name", "mesh"});
  r.knownKeys({"haptics", "render", "objects", "devices"});
  (void)r.child("physics", true);

  const auto& errs = r.errors();
  auto findErr = [&](const std::string& where) -> const dm::Error* {
    for (const auto& e : errs)
      if (e.where == "scene.json: " + where) return &e;
    return nullptr;
  };
  ASSERT_TRUE(findErr("/haptics/rate_hz"));
  EXPECT_NE(findErr("/haptics/rate_hz")->what.find("-5 is outside [100, 10000]"), std::string::npos);
  ASSERT_TRUE(findErr("/haptics/renderer"));
  EXPECT_EQ(findErr("/haptics/renderer")->hint, "did you mean \"godobject\"?");
  ASSERT_TRUE(findErr("/haptics/device"));
  EXPECT_NE(findErr("/haptics/device")->what.find("expected a string, got number 3"), std::string::npos);
  ASSERT_TRUE(findErr("/render/camera/up"));
  ASSERT_TRUE(findErr("/objects/1/name"));
  ASSERT_TRUE(findErr("/objects/1/nmae"));
  EXPECT_EQ(findErr("/objects/1/nmae")->hint, "did you mean \"name\"?");
  ASSERT_TRUE(findErr("/rate_Hz"));
  ASSERT_TRUE(findErr("/physics"));
  EXPECT_EQ(errs.size(), 8u);
  auto s = r.status();
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().what.find("and 7 more problems"), std::string::npos);
}

TEST(Config, ValidDocumentHasOkStatus) {
  auto c = dm::Config::parse(R"({"a": 2, "b": true, "c": "x", "v": [1, 2, 3]})");
  ASSERT_TRUE(c);
  auto r = c->reader();
  EXPECT_EQ(r.integer("a", {.min = 0, .max = 5}), 2);
  EXPECT_TRUE(r.boolean("b"));
  EXPECT_EQ(r.oneOf("c", {"x", "y"}), "x");
  EXPECT_EQ(r.numbers("v", 3), (std::vector<double>{1, 2, 3}));
  r.knownKeys({"a", "b", "c", "v"});
  EXPECT_TRUE(r.status());
}

TEST(Config, JsonPointerEscapesKeys) {
  auto c = dm::Config::parse(R"({"a/b": {"c~d": "oops"}})");
  ASSERT_TRUE(c);
  auto r = c->reader();
  (void)r.child("a/b").number("c~d");
  ASSERT_EQ(r.errors().size(), 1u);
  EXPECT_EQ(r.errors()[0].where, "<string>: /a~1b/c~0d");
}

TEST(Config, EditDistance) {
  EXPECT_EQ(dm::editDistance("kitten", "sitting"), 3u);
  EXPECT_EQ(dm::editDistance("", "abc"), 3u);
  EXPECT_EQ(dm::closestMatch("rate_Hz", {"rate_hz", "device"}), "rate_hz");
  EXPECT_EQ(dm::closestMatch("zzzzzz", {"rate_hz", "device"}), "");
}

}  // namespace

TEST(Config, NumberBeyondDoubleIsAParseErrorNotAnException) {
  auto c = dm::Config::parse(R"({"a": [1e400]})", "big.json");
  ASSERT_FALSE(c);
  EXPECT_EQ(c.error().code, dm::ErrorCode::Parse);
  EXPECT_EQ(c.error().where, "big.json");
}

TEST(Config, BadArrayElementPointsAtTheElement) {
  auto c = dm::Config::parse(R"({"pose": {"position": [0, "x", 1]}})", "scene.json");
  ASSERT_TRUE(c);
  dm::ConfigReader r = c->reader();
  (void)r.child("pose").numbers("position", 3);
  auto s = r.status();
  ASSERT_FALSE(s);
  EXPECT_EQ(s.error().where, "scene.json: /pose/position/1");
}
