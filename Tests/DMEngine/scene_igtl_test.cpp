// A running scene watched over OpenIGTLink, as 3D Slicer or PLUS would: the
// reference OpenIGTLink library (1.11) connects to the scene's "igtl" engine
// and unpacks, CRC checked, what it streams — the tool and handle
// TRANSFORMs, the force SENSOR, the pushed box's TRANSFORM and the rendered
// frames as IMAGE — and each value is compared with what the run itself
// wrote (forces.csv, summary.json) at the same scene time.
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

#ifdef DM_TEST_WITH_IGTL
#include <igtlClientSocket.h>
#include <igtlImageMessage.h>
#include <igtlMessageHeader.h>
#include <igtlSensorMessage.h>
#include <igtlTransformMessage.h>

#include <map>
#include <thread>
#endif

namespace scene_igtl_test {

using nlohmann::json;

// The box-push scene streamed: tool, handle, force, the box, frames.
dm::SceneDesc streamedBoxPush(bool render) {
  dm::SceneDesc scene = scene_run::bundledScene("box_push.json");
  if (render)
    scene.engines.render = dm::SceneRenderEngine{.rateHz = 30, .camera = "side", .width = 160, .height = 120};
  dm::SceneIgtlEngine g;
  g.listen = "127.0.0.1:0";
  g.tool = "ToolToScene";
  g.handle = "HandleToScene";
  g.force = "Force";
  g.bodies = true;
  if (render) g.image = "Camera";
  g.waitForClients = 1;
  g.waitTimeout = 20;
  scene.engines.igtl = g;
  scene.outputs.forces = true;
  return scene;
}

TEST(SceneIgtl, ParsesChecksAndWritesTheEngine) {
  const dm::SceneDesc scene = streamedBoxPush(true);
  const std::string text = dm::toJson(scene).dump();
  auto back = dm::parseScene(text, "streamed.json", scene.baseDir);
  ASSERT_TRUE(back) << back.error();
  EXPECT_EQ(back->engines.igtl, scene.engines.igtl);

  // Without a render engine there are no frames to publish; without
  // physics no bodies; a name longer than OpenIGTLink's 20 characters.
  json j = dm::toJson(scene);
  j["engines"].erase("render");
  j["engines"].erase("physics");
  j["outputs"]["frames"] = false;
  j["engines"]["igtl"]["publish"]["force"] = "AForceNameLongerThan20";
  j["engines"]["igtl"]["publsh"] = 1;
  std::vector<dm::Error> problems;
  auto bad = dm::parseScene(j.dump(), "streamed.json", scene.baseDir, &problems);
  ASSERT_FALSE(bad);
  const std::string all = dm::formatSceneErrors(problems);
  for (const char* needle : {"engines/igtl/publish/image", "engines/igtl/publish/bodies",
                             "engines/igtl/publish/force", "engines/igtl/publsh"})
    EXPECT_NE(all.find(needle), std::string::npos) << needle << " not in\n" << all;
}

TEST(SceneIgtl, WaitingForAClientThatNeverComesFailsNamingTheKey) {
  dm::SceneDesc scene = streamedBoxPush(false);
  scene.engines.igtl->waitTimeout = 0.2;
  dm::test::TempDir dir("igtl_wait");
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 0.5, .outDir = dir.path() / "out"});
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, dm::ErrorCode::Timeout);
  EXPECT_NE(r.error().message().find("engines/igtl/wait_for_clients"), std::string::npos) << r.error();
}

#if defined(DM_TEST_WITH_IGTL) && defined(DM_TEST_WITH_RENDERER)

// What the reference client got: per device, (scene time, value).
struct Received {
  std::map<std::string, std::vector<std::pair<double, igtl::Matrix4x4>>> transforms;  // mm
  std::vector<std::pair<double, dm::Vec3>> forces;                                    // N
  std::vector<std::pair<double, std::vector<std::uint8_t>>> images;                   // RGB bytes
  int width = 0, height = 0, depth = 0, components = 0, scalarType = 0;
  int unpackFailures = 0;
  std::string otherTypes;
};

double seconds(igtl::MessageHeader* h) {
  unsigned int sec = 0, frac = 0;
  h->GetTimeStamp(&sec, &frac);
  return sec + frac / 4294967296.0;
}

// Receives until the server closes the connection: every body unpacked
// by the reference library with its CRC check on.
void receiveAll(igtl::ClientSocket* socket, Received& got) {
  for (;;) {
    igtl::MessageHeader::Pointer h = igtl::MessageHeader::New();
    h->InitPack();
    if (socket->Receive(h->GetPackPointer(), h->GetPackSize()) != h->GetPackSize()) return;
    h->Unpack();
    const std::string type = h->GetDeviceType();
    const double t = seconds(h);
    auto body = [&](igtl::MessageBase* m) {
      m->SetMessageHeader(h);
      m->AllocatePack();
      if (socket->Receive(m->GetPackBodyPointer(), m->GetPackBodySize()) != m->GetPackBodySize())
        return false;
      if ((m->Unpack(1) & igtl::MessageHeader::UNPACK_BODY) == 0) {
        ++got.unpackFailures;
        return false;
      }
      return true;
    };
    if (type == "TRANSFORM") {
      igtl::TransformMessage::Pointer m = igtl::TransformMessage::New();
      if (!body(m)) continue;
      igtl::Matrix4x4 mat;
      m->GetMatrix(mat);
      auto& list = got.transforms[h->GetDeviceName()];
      list.emplace_back();
      list.back().first = t;
      std::memcpy(list.back().second, mat, sizeof mat);
    } else if (type == "SENSOR") {
      igtl::SensorMessage::Pointer m = igtl::SensorMessage::New();
      if (!body(m) || m->GetLength() != 3) continue;
      got.forces.emplace_back(t, dm::Vec3(m->GetValue(0), m->GetValue(1), m->GetValue(2)));
    } else if (type == "IMAGE") {
      igtl::ImageMessage::Pointer m = igtl::ImageMessage::New();
      if (!body(m)) continue;
      m->GetDimensions(got.width, got.height, got.depth);
      got.components = m->GetNumComponents();
      got.scalarType = m->GetScalarType();
      const auto* p = static_cast<const std::uint8_t*>(m->GetScalarPointer());
      got.images.emplace_back(t, std::vector<std::uint8_t>(p, p + m->GetImageSize()));
    } else {
      got.otherTypes += type + " ";
      std::vector<char> skip(static_cast<std::size_t>(h->GetBodySizeToRead()));
      if (!skip.empty() &&
          socket->Receive(skip.data(), static_cast<int>(skip.size())) != static_cast<int>(skip.size()))
        return;
    }
  }
}

TEST(SceneIgtl, TheReferenceLibraryReceivesTheToolForceBoxAndFrames) {
  const dm::SceneDesc scene = streamedBoxPush(true);
  dm::test::TempDir dir("igtl_stream");
  const dm::SceneRunOptions options{
      .mode = dm::RunMode::Lockstep, .duration = 2.0, .outDir = dir.path() / "out"};
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  ASSERT_TRUE((*rt)->prepare(options));
  const int port = (*rt)->igtlPort();
  ASSERT_GT(port, 0);

  Received got;
  std::thread client([&] {
    igtl::ClientSocket::Pointer socket = igtl::ClientSocket::New();
    if (socket->ConnectToServer("127.0.0.1", port) != 0) return;
    socket->SetReceiveTimeout(20000);
    receiveAll(socket, got);
    socket->CloseSocket();
  });
  auto r = (*rt)->run(options);
  client.join();
  ASSERT_TRUE(r) << r.error();
  const json& sum = r->summary;
  ASSERT_TRUE(sum.contains("igtl")) << sum.dump(2);
  EXPECT_EQ(sum["igtl"]["clients"], 1);
  EXPECT_EQ(sum["igtl"]["send_failures"], 0) << "the client missed messages";
  EXPECT_EQ(got.unpackFailures, 0);
  EXPECT_EQ(got.otherTypes, "");

  // Every tick of the 30 Hz engine over 0..2 s (61, both ends in
  // lockstep): one of each, in order.
  const std::size_t ticks = scene_run::named(sum["engines"], "igtl")["ticks"];
  EXPECT_EQ(ticks, 61u);
  const auto& tool = got.transforms["ToolToScene"];
  ASSERT_EQ(tool.size(), ticks);
  EXPECT_EQ(got.transforms["HandleToScene"].size(), ticks);
  EXPECT_EQ(got.forces.size(), ticks);
  EXPECT_EQ(sum["igtl"]["published"]["sensor"], ticks);
  // Stamped with the haptic tick they come from: the newest at or before
  // the engine's tick (the 1 kHz tick within the last millisecond).
  for (std::size_t i = 0; i < tool.size(); ++i) {
    EXPECT_LE(tool[i].first, double(i) / 30.0 + 1e-8);
    EXPECT_GT(tool[i].first, double(i) / 30.0 - 1e-3 - 1e-8);
  }

  // The force and the tool are the haptic tick of the same scene time,
  // bit for bit (SENSOR is float64) and to float32 in mm (TRANSFORM).
  const std::vector<scene_run::TraceRow> rows = scene_run::forceTrace(dir.path() / "out" / "forces.csv");
  ASSERT_GE(rows.size(), 1990u);
  double maxForce = 0;
  for (std::size_t i = 0; i < got.forces.size(); ++i) {
    const double t = got.forces[i].first;  // not a structured binding: clang 14 cannot capture one
    const auto& f = got.forces[i].second;
    const auto row = std::min_element(rows.begin(), rows.end(), [t](const auto& a, const auto& b) {
      return std::abs(a.t - t) < std::abs(b.t - t);
    });
    ASSERT_NEAR(row->t, t, 1e-6);
    EXPECT_EQ(f, row->force) << "at t = " << t;
    const igtl::Matrix4x4& m = tool[i].second;
    EXPECT_NEAR(m[0][3] * 1e-3, row->proxy.x(), 1e-6);
    EXPECT_NEAR(m[1][3] * 1e-3, row->proxy.y(), 1e-6);
    EXPECT_NEAR(m[2][3] * 1e-3, row->proxy.z(), 1e-6);
    maxForce = std::max(maxForce, f.norm());
  }
  EXPECT_GT(maxForce, 0.3) << "the tool never pushed the box";

  // The box: at rest on the table at first, pushed along +x by the end,
  // its last TRANSFORM (t = 1.967 s) close to where physics left it.
  const auto& box = got.transforms["box"];
  ASSERT_FALSE(box.empty());
  EXPECT_NEAR(box.front().second[2][3], 20.0, 0.1);  // mm: resting on the table
  const dm::Vec3 final = scene_run::vec(scene_run::named(sum["physics"]["bodies"], "box")["position_m"]);
  EXPECT_GT(box.back().second[0][3] * 1e-3, 0.002);
  EXPECT_NEAR(box.back().second[0][3] * 1e-3, final.x(), 0.0015);

  // Frames: 160 x 120 RGB, 8 bits, one per render tick, not blank.
  ASSERT_GE(got.images.size(), 55u);
  EXPECT_EQ(sum["igtl"]["published"]["image"], got.images.size());
  EXPECT_EQ(got.width, 160);
  EXPECT_EQ(got.height, 120);
  EXPECT_EQ(got.depth, 1);
  EXPECT_EQ(got.components, 3);
  EXPECT_EQ(got.scalarType, igtl::ImageMessage::TYPE_UINT8);
  const std::vector<std::uint8_t>& last = got.images.back().second;
  ASSERT_EQ(last.size(), 160u * 120u * 3u);
  const auto [lo, hi] = std::minmax_element(last.begin(), last.end());
  EXPECT_GT(int(*hi) - int(*lo), 60) << "a blank frame";
}

#endif

}  // namespace scene_igtl_test
