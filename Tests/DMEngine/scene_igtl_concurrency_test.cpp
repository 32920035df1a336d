// A scene streamed over OpenIGTLink while it runs on real-time threads: the
// haptics engine (streamed sample), physics (network poses), the igtl
// engine's thread, its network thread and a client's all share data. Run
// under TSan in CI: any unsynchronised access between them is a failure.
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#ifdef DM_TEST_WITH_NETWORK
#include <dm/network/igtl_session.hpp>
#include <dm/network/io_thread.hpp>

#include <atomic>
#include <chrono>
#include <thread>
#endif

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_igtl_concurrency_test {

#ifdef DM_TEST_WITH_NETWORK

TEST(SceneIgtlRealTime, AClientReceivesTheToolForceAndBoxWhileTheEnginesRun) {
  dm::SceneDesc scene = scene_run::bundledScene("box_push.json");
  dm::SceneIgtlEngine g;
  g.listen = "127.0.0.1:0";
  g.tool = "ToolToScene";
  g.force = "Force";
  g.bodies = true;
  g.waitForClients = 1;
  g.waitTimeout = 20;
  scene.engines.igtl = g;
  const dm::test::TempDir dir("igtl_rt");
  const dm::SceneRunOptions options{.mode = dm::RunMode::RealTime, .duration = 1.5, .outDir = dir.path()};
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  ASSERT_TRUE((*rt)->prepare(options));

  std::atomic<int> tools{0}, boxes{0}, forces{0};
  dm::IoThread net;
  ASSERT_TRUE(net.start());
  dm::IgtlHandlers h;
  h.onTransform = [&](dm::ConnectionId, const dm::igtl::MessageView& m, const dm::Affine3&) {
    (m.header.deviceName == "box" ? boxes : tools).fetch_add(1);
  };
  h.onSensor = [&](dm::ConnectionId, const dm::igtl::MessageView&, const dm::igtl::SensorInfo& s) {
    if (s.unit == dm::igtl::kUnitNewton && s.data.size() == 3) forces.fetch_add(1);
  };
  auto client = dm::IgtlClient::connect(net, {.tcp = {.peer = {"127.0.0.1", (*rt)->igtlPort()}}}, h);
  ASSERT_TRUE(client) << client.error();
  auto r = (*rt)->run(options);
  ASSERT_TRUE(r) << r.error();
  (*client)->close();
  // 30 Hz for 1.5 s: about 45 of each (a sanitizer may slow the threads).
  EXPECT_GE(tools.load(), 10);
  EXPECT_GE(forces.load(), 10);
  EXPECT_GE(boxes.load(), 10);
  EXPECT_EQ(r->summary.at("igtl").at("clients"), 1);
}

#endif

}  // namespace scene_igtl_concurrency_test
