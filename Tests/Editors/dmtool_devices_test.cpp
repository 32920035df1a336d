// dmtool devices: lists built-in drivers and plugins with their status,
// refuses a crashing and a wrong-ABI plugin without going down, opens a
// driver with --open / --only, and lists a vendor driver whose library is
// missing as unavailable with the reason.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <dlfcn.h>

#include <string>

#include "../common/build_paths.hpp"
#include "dmtool_run.hpp"

namespace {

using dmtool_test::describe;
using dmtool_test::parseJson;
using dmtool_test::runTool;
using nlohmann::json;

const json* findBy(const json& list, const char* key, const std::string& value) {
  for (const json& e : list)
    if (e.contains(key) && e[key] == value) return &e;
  return nullptr;
}

TEST(DmtoolDevices, ListsTheBuiltInDrivers) {
  const auto r = runTool({"devices", "--json"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  const json j = parseJson(r);
  const json* sim = findBy(j["drivers"], "name", "sim-haptic");
  ASSERT_NE(sim, nullptr) << r.out;
  EXPECT_EQ((*sim)["kind"], "haptic-device");
  const json* plugin = findBy(j["plugins"], "name", "sim-haptic");
  ASSERT_NE(plugin, nullptr);
  EXPECT_EQ((*plugin)["status"], "built-in");
}

TEST(DmtoolDevices, OpensOneDriverAndFailsForAMissingOne) {
  const auto r = runTool({"devices", "--only", "sim-haptic", "--open", "--json"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  const json j = parseJson(r);
  ASSERT_EQ(j["drivers"].size(), 1u);
  EXPECT_EQ(j["drivers"][0]["open"]["status"], "ok");
  EXPECT_EQ(j["drivers"][0]["open"]["max_force_N"], 8.0);
  const auto missing = runTool({"devices", "--only", "phantom-omni"});
  EXPECT_EQ(missing.exitCode, 1) << describe(missing);
  EXPECT_NE(missing.err.find("phantom-omni"), std::string::npos);
  // replay-haptic needs a file: --open reports why and --only fails.
  const auto replay = runTool({"devices", "--only", "replay-haptic", "--open"});
  EXPECT_EQ(replay.exitCode, 1) << describe(replay);
  EXPECT_NE(replay.out.find("'file' is required"), std::string::npos) << replay.out;
}

// A vendor driver without its vendor's library (none is installed here; the
// test says so if one is): listed, unavailable with the reason, and
// opening it fails saying what to install, without a crash.
TEST(DmtoolDevices, AVendorDriverWithoutItsLibraryIsListedAsUnavailable) {
  if (void* real = ::dlopen("libHD.so", RTLD_NOW | RTLD_LOCAL)) {
    ::dlclose(real);
    GTEST_SKIP() << "OpenHaptics is installed on this machine";
  }
  const auto r = runTool({"devices", "--json"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  const json j = parseJson(r);
  const json* hd = findBy(j["drivers"], "name", "openhaptics-hd");
  ASSERT_NE(hd, nullptr) << r.out;
  EXPECT_EQ((*hd)["kind"], "haptic-device");
  EXPECT_EQ((*hd)["available"], false);
  EXPECT_NE((*hd)["unavailable_reason"].get<std::string>().find("install OpenHaptics"), std::string::npos);
  if (void* dhd = ::dlopen("libdhd.so", RTLD_NOW | RTLD_LOCAL)) {
    ::dlclose(dhd);
  } else {
    const json* fd = findBy(j["drivers"], "name", "force-dimension-dhd");
    ASSERT_NE(fd, nullptr) << r.out;
    EXPECT_EQ((*fd)["available"], false);
    EXPECT_NE((*fd)["unavailable_reason"].get<std::string>().find("Force Dimension SDK"), std::string::npos);
  }
  const auto text = runTool({"devices", "--only", "openhaptics-hd", "--open"});
  EXPECT_EQ(text.exitCode, 1) << describe(text);
  EXPECT_NE(text.out.find("unavailable: cannot load the OpenHaptics HD library"), std::string::npos)
      << text.out;
  EXPECT_NE(text.out.find("cannot open with defaults"), std::string::npos) << text.out;
}

TEST(DmtoolDevices, RefusesCrashingAndWrongAbiPluginsAndCarriesOn) {
  const std::string dir = dm::test::besideExecutable(DM_TEST_DRIVER_DIR);
  const auto r = runTool({"devices", "--json", "--plugin-dir", dir + "/crash_init_driver", "--plugin-dir",
                          dir + "/wrong_abi_driver"});
  ASSERT_EQ(r.exitCode, 0) << describe(r);
  const json j = parseJson(r);
  int refused = 0;
  for (const json& p : j["plugins"]) {
    if (p["status"] != "refused") continue;
    ++refused;
    const std::string error = p["error"];
    const std::string path = p["path"];
    if (path.find("crash_init") != std::string::npos) {
      EXPECT_NE(error.find("SIGABRT"), std::string::npos) << error;
    }
    if (path.find("wrong_abi") != std::string::npos) {
      EXPECT_NE(error.find("ABI"), std::string::npos) << error;
    }
  }
  EXPECT_EQ(refused, 2) << r.out;
  EXPECT_NE(findBy(j["drivers"], "name", "sim-haptic"), nullptr);  // the good drivers are still there
  const auto bad = runTool({"devices", "--plugin-dir", "/nonexistent/plugins"});
  EXPECT_EQ(bad.exitCode, 1) << describe(bad);
  EXPECT_NE(bad.err.find("/nonexistent/plugins"), std::string::npos);
}

}  // namespace
