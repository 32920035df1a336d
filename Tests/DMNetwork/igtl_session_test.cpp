// The OpenIGTLink session layer against itself: the stream framer on split
// and malformed streams, IgtlClient → IgtlServer for every typed handler
// (COMMAND included: the reference 1.11 library has no COMMAND), query
// answering and subscriptions, and what malformed input does to a
// connection. Interoperability with the reference library is in
// igtl_session_interop_test.cpp.
#include <dm/network/crc.hpp>
#include <dm/network/igtl_session.hpp>
#include <dm/network/io_thread.hpp>
#include <dm/network/tcp.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "../common/eventually.hpp"

namespace {

using namespace std::chrono_literals;
namespace dmi = dm::igtl;
using Bytes = std::vector<std::byte>;
using dm::test::eventually;

Bytes concat(std::initializer_list<Bytes> parts) {
  Bytes out;
  for (const auto& p : parts) out.insert(out.end(), p.begin(), p.end());
  return out;
}

dm::Affine3 someTransform(double angle, const dm::Vec3& t) {
  dm::Affine3 a = dm::Affine3::Identity();
  a.linear() = dm::Quat(Eigen::AngleAxisd(angle, dm::Vec3(1, 2, -1).normalized())).toRotationMatrix();
  a.translation() = t;
  return a;
}

// Big-endian u64 at `at`.
void putBe64(Bytes& b, std::size_t at, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) b[at + static_cast<std::size_t>(i)] = std::byte(v >> (56 - 8 * i));
}

// ---------------------------------------------------------------- framer ---

TEST(IgtlStreamFramer, DeliversEveryMessageWhateverTheChunking) {
  const dm::Affine3 t = someTransform(0.4, {0.01, -0.02, 0.3});
  const Bytes stream = concat(
      {dmi::encodeTransform({.deviceName = "Tool"}, t).value(),
       dmi::encodeString({.deviceName = "Text"}, {.text = "hello"}).value(),
       dmi::encodeStatus(
           {.version = 2, .deviceName = "Robot", .messageId = 7, .metadata = {{.key = "k", .value = "v"}}},
           {.code = 1, .message = "ok"})
           .value(),
       dmi::encodeQuery({.deviceName = "CT"}, {.dataType = "IMAGE"}).value()});
  for (std::size_t chunk :
       {std::size_t{1}, std::size_t{7}, std::size_t{58}, std::size_t{59}, stream.size()}) {
    dmi::StreamFramer framer;
    std::vector<std::string> types;
    std::optional<dm::Affine3> got;
    std::uint32_t statusId = 0;
    for (std::size_t at = 0; at < stream.size(); at += chunk) {
      const auto part = std::span(stream).subspan(at, std::min(chunk, stream.size() - at));
      ASSERT_TRUE(framer
                      .feed(part,
                            [&](const dm::Result<dmi::MessageView>& m) {
                              ASSERT_TRUE(m.ok()) << m.error().message();
                              types.push_back(m->header.type);
                              if (m->header.type == "TRANSFORM") got = dmi::decodeTransformAffine(*m).value();
                              if (m->header.type == "STATUS") statusId = m->messageId;
                            })
                      .ok());
    }
    EXPECT_EQ(types, (std::vector<std::string>{"TRANSFORM", "STRING", "STATUS", "GET_IMAGE"})) << chunk;
    ASSERT_TRUE(got.has_value());
    EXPECT_TRUE(got->matrix().isApprox(t.matrix(), 1e-6)) << chunk;
    EXPECT_EQ(statusId, 7u);
    EXPECT_EQ(framer.bufferedBytes(), 0u);
    EXPECT_EQ(framer.messages(), 4u);
  }
}

TEST(IgtlStreamFramer, RefusesAnOversizeBodyWithOnlyTheHeaderBuffered) {
  Bytes header = dmi::encodeString({.deviceName = "Text"}, {.text = "x"}).value();
  header.resize(dmi::kHeaderBytes);
  putBe64(header, 42, 1u << 20);  // body size 1 MiB, limit 1 KiB
  dmi::StreamFramer framer({.maxBodyBytes = 1024});
  int delivered = 0;
  auto count = [&](const dm::Result<dmi::MessageView>&) { ++delivered; };
  // 57 bytes: nothing to decide yet.
  ASSERT_TRUE(framer.feed(std::span(header).first(57), count).ok());
  EXPECT_EQ(framer.bufferedBytes(), 57u);
  // The 58th byte completes the header: refused at once, and the body bytes
  // that follow in the same chunk are never kept.
  Bytes rest(header.begin() + 57, header.end());
  rest.resize(rest.size() + 500, std::byte{0xAB});
  const dm::Status s = framer.feed(rest, count);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, dm::ErrorCode::Unsupported);
  EXPECT_NE(s.error().message().find("1048576"), std::string::npos) << s.error().message();
  EXPECT_TRUE(framer.failed());
  EXPECT_EQ(framer.bufferedBytes(), 0u);
  EXPECT_EQ(delivered, 0);
  // Failed for good until reset().
  EXPECT_FALSE(framer.feed(dmi::encodeString({}, {.text = "y"}).value(), count).ok());
  framer.reset();
  EXPECT_TRUE(framer.feed(dmi::encodeString({}, {.text = "y"}).value(), count).ok());
  EXPECT_EQ(delivered, 1);
}

TEST(IgtlStreamFramer, RefusesABadCrcAndAGarbageHeader) {
  Bytes bad = dmi::encodeString({.deviceName = "Text"}, {.text = "checksum me"}).value();
  bad.back() ^= std::byte{0x01};
  dmi::StreamFramer framer;
  int delivered = 0;
  const dm::Status s = framer.feed(bad, [&](const auto&) { ++delivered; });
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message().find("CRC"), std::string::npos) << s.error().message();
  EXPECT_EQ(delivered, 0);

  dmi::StreamFramer other;
  Bytes garbage(100, std::byte{0x47});  // version 0x4747
  EXPECT_FALSE(other.feed(garbage, [&](const auto&) { ++delivered; }).ok());
  EXPECT_EQ(delivered, 0);

  // Peers known to leave the CRC at zero can be read with the check off.
  Bytes zeroCrc = dmi::encodeString({}, {.text = "no crc"}).value();
  putBe64(zeroCrc, 50, 0);
  dmi::StreamFramer lenient({.verifyCrc = false});
  EXPECT_TRUE(lenient.feed(zeroCrc, [&](const auto& m) { delivered += m.ok() ? 1 : 0; }).ok());
  EXPECT_EQ(delivered, 1);
}

TEST(IgtlStreamFramer, PassesOnABadExtendedHeaderAndStaysInSync) {
  // Version 2 body of 12 bytes whose extended header claims 200 bytes; the
  // CRC is right, so framing is intact.
  Bytes ext(12, std::byte{0});
  ext[1] = std::byte{200};
  Bytes bad = dmi::encodeRaw({.deviceName = "X"}, "STRING", ext).value();
  bad[1] = std::byte{2};  // header version 2 (the CRC covers only the body)
  const Bytes good = dmi::encodeString({}, {.text = "after"}).value();
  dmi::StreamFramer framer;
  std::vector<bool> results;
  ASSERT_TRUE(framer.feed(concat({bad, good}), [&](const auto& m) { results.push_back(m.ok()); }).ok());
  EXPECT_EQ(results, (std::vector<bool>{false, true}));
}

// ---------------------------------------------------------------- session ---

/// Everything the handlers received, guarded for the test thread.
struct Inbox {
  std::mutex mutex;
  std::vector<std::pair<std::string, dm::Affine3>> transforms;  // device, value
  std::vector<dm::Pose> poses;
  std::vector<dm::Volume> volumes;
  std::vector<dm::Image> images;
  std::vector<dmi::StatusInfo> statuses;
  std::vector<dmi::StringInfo> strings;
  std::vector<std::vector<dmi::Point>> points;
  std::vector<dm::Mesh> meshes;
  std::vector<std::pair<std::string, dmi::CommandInfo>> commands;  // type, value
  std::vector<dmi::Query> queries;
  std::vector<dmi::Header> raw;
  std::vector<std::uint64_t> timestamps;

  dm::IgtlHandlers handlers(std::function<void(dm::ConnectionId, const dmi::CommandInfo&)> onCommand = {}) {
    dm::IgtlHandlers h;
    h.onTransform = [this](dm::ConnectionId, const dmi::MessageView& m, const dm::Affine3& v) {
      std::lock_guard lock(mutex);
      transforms.emplace_back(m.header.deviceName, v);
      timestamps.push_back(m.header.timestamp);
    };
    h.onPosition = [this](dm::ConnectionId, const dmi::MessageView&, const dm::Pose& v) { keep(poses, v); };
    h.onVolume = [this](dm::ConnectionId, const dmi::MessageView&, const dm::Volume& v) { keep(volumes, v); };
    h.onImage = [this](dm::ConnectionId, const dmi::MessageView&, const dm::Image& v) {
      keep(images, v.clone());
    };
    h.onStatus = [this](dm::ConnectionId, const dmi::MessageView&, const dmi::StatusInfo& v) {
      keep(statuses, v);
    };
    h.onString = [this](dm::ConnectionId, const dmi::MessageView&, const dmi::StringInfo& v) {
      keep(strings, v);
    };
    h.onPoints = [this](dm::ConnectionId, const dmi::MessageView&, const std::vector<dmi::Point>& v) {
      keep(points, v);
    };
    h.onPolyData = [this](dm::ConnectionId, const dmi::MessageView&, const dm::Mesh& v) { keep(meshes, v); };
    h.onCommand = [this, onCommand](dm::ConnectionId id, const dmi::MessageView& m,
                                    const dmi::CommandInfo& v) {
      {
        std::lock_guard lock(mutex);
        commands.emplace_back(m.header.type, v);
      }
      if (onCommand) onCommand(id, v);
    };
    h.onQuery = [this](dm::ConnectionId, const dmi::MessageView&, const dmi::Query& v) { keep(queries, v); };
    h.onRaw = [this](dm::ConnectionId, const dmi::MessageView& m) { keep(raw, m.header); };
    return h;
  }

  template <class T>
  void keep(std::vector<T>& list, const T& v) {
    std::lock_guard lock(mutex);
    list.push_back(v);
  }
  template <class F>
  auto with(F&& f) {
    std::lock_guard lock(mutex);
    return f();
  }
  std::size_t rawCount(const std::string& type) {
    std::lock_guard lock(mutex);
    return static_cast<std::size_t>(
        std::count_if(raw.begin(), raw.end(), [&](const dmi::Header& h) { return h.type == type; }));
  }
};

struct Pair {
  dm::IoThread net;
  Inbox serverBox, clientBox;
  std::unique_ptr<dm::IgtlServer> server;
  std::unique_ptr<dm::IgtlClient> client;

  explicit Pair(
      dm::IgtlServerOptions serverOptions = {},
      std::function<void(dm::IgtlServer&, dm::ConnectionId, const dmi::CommandInfo&)> onCommand = {}) {
    EXPECT_TRUE(net.start().ok());
    auto s = dm::IgtlServer::listen(
        net, std::move(serverOptions),
        serverBox.handlers([this, onCommand](dm::ConnectionId id, const dmi::CommandInfo& c) {
          if (onCommand) onCommand(*server, id, c);
        }));
    EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.error().message());
    server = std::move(*s);
    auto c =
        dm::IgtlClient::connect(net, {.tcp = {.peer = {"127.0.0.1", server->port()}}}, clientBox.handlers());
    EXPECT_TRUE(c.ok());
    client = std::move(*c);
    EXPECT_TRUE(client->waitConnected(5s).ok());
    EXPECT_TRUE(eventually([&] { return server->connections().size() == 1; }));
  }
  ~Pair() {
    client.reset();
    server.reset();
  }
  dm::ConnectionId connection() const { return server->connections().at(0); }
};

dm::Mesh tetrahedron() {
  dm::Mesh m;
  m.positions = {{0, 0, 0}, {0.01, 0, 0}, {0, 0.01, 0}, {0, 0, 0.01}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return m;
}

TEST(IgtlSession, ServerHandlersReceiveEveryTypeFromOurClient) {
  Pair p;
  const dm::Affine3 t = someTransform(0.7, {0.1, 0.2, -0.05});
  const dm::Pose pose(dm::Vec3(0.01, -0.02, 0.03), dm::Quat(Eigen::AngleAxisd(0.3, dm::Vec3::UnitZ())));
  auto vol = dm::Volume::create({5, 4, 3}, dm::VoxelType::I16, t);
  ASSERT_TRUE(vol.ok());
  for (std::size_t i = 0; i < vol->voxelCount(); ++i) vol->setValueAt(i, static_cast<double>(i) * 7 - 100);
  auto img = dm::Image::create(6, 4, 3, dm::PixelType::U8);
  ASSERT_TRUE(img.ok());
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 6; ++x)
      for (int c = 0; c < 3; ++c)
        img->at<std::uint8_t>(x, y, c) = static_cast<std::uint8_t>(x * 40 + y * 10 + c);
  const std::vector<dmi::Point> pts{
      {.name = "A", .group = "Fiducial", .position = {0.001, 0.002, 0.003}, .radius = 0.002, .owner = "CT"},
      {.name = "B", .group = "Target", .rgba = {1, 2, 3, 4}, .position = {-0.1, 0, 0.25}}};
  const dmi::CommandInfo cmd{.id = 42, .name = "Start", .content = "<Command Name=\"Start\"/>"};
  const std::uint64_t stamp = (1700000000ull << 32) | 0x80000000u;

  for (const Bytes& b :
       {dmi::encodeTransform({.deviceName = "Tool", .timestamp = stamp}, t).value(),
        dmi::encodePosition({.deviceName = "Needle"}, pose).value(),
        dmi::encodeVolume({.deviceName = "CT"}, *vol).value(),
        dmi::encodeImage({.deviceName = "US"}, *img).value(),
        dmi::encodeStatus({.deviceName = "Robot"},
                          {.code = 4, .subcode = -3, .errorName = "NoTool", .message = "gone"})
            .value(),
        dmi::encodeString({.version = 2, .deviceName = "Text"}, {.encoding = 106, .text = "grüß"}).value(),
        dmi::encodePoints({.deviceName = "Plan"}, pts).value(),
        dmi::encodePolyData({.deviceName = "Tet"}, tetrahedron()).value(),
        dmi::encodeCommand({.version = 3, .deviceName = "Ctl"}, cmd).value(),
        dmi::encodeRaw({.deviceName = "Sensor"}, "SENSOR", Bytes(10, std::byte{1})).value()})
    ASSERT_TRUE(p.client->send(b).ok());

  Inbox& in = p.serverBox;
  ASSERT_TRUE(eventually([&] { return in.rawCount("SENSOR") == 1; }));
  in.with([&] {
    ASSERT_EQ(in.transforms.size(), 1u);
    EXPECT_EQ(in.transforms[0].first, "Tool");
    EXPECT_TRUE(in.transforms[0].second.matrix().isApprox(t.matrix(), 1e-6));
    EXPECT_EQ(in.timestamps[0], stamp);
    ASSERT_EQ(in.poses.size(), 1u);
    EXPECT_TRUE(in.poses[0].p.isApprox(pose.p, 1e-6));
    EXPECT_LT(in.poses[0].q.angularDistance(pose.q), 1e-6);
    // The 3-D volume reaches onVolume; the 2-D RGB image reaches onImage
    // (3 components: not a Volume).
    ASSERT_EQ(in.volumes.size(), 1u);
    EXPECT_EQ(in.volumes[0].dims(), vol->dims());
    EXPECT_EQ(in.volumes[0].type(), dm::VoxelType::I16);
    EXPECT_EQ(in.volumes[0].value(4, 3, 2), vol->value(4, 3, 2));
    EXPECT_TRUE(in.volumes[0].indexToWorld().matrix().isApprox(t.matrix(), 1e-5));
    ASSERT_EQ(in.images.size(), 1u);
    EXPECT_EQ(in.images[0].width(), 6);
    EXPECT_EQ(in.images[0].channels(), 3);
    EXPECT_EQ(in.images[0].at<std::uint8_t>(5, 3, 2), 5 * 40 + 3 * 10 + 2);
    ASSERT_EQ(in.statuses.size(), 1u);
    EXPECT_EQ(in.statuses[0],
              (dmi::StatusInfo{.code = 4, .subcode = -3, .errorName = "NoTool", .message = "gone"}));
    ASSERT_EQ(in.strings.size(), 1u);
    EXPECT_EQ(in.strings[0].text, "grüß");
    ASSERT_EQ(in.points.size(), 1u);
    ASSERT_EQ(in.points[0].size(), 2u);
    EXPECT_EQ(in.points[0][1].group, "Target");
    EXPECT_TRUE(in.points[0][1].position.isApprox(pts[1].position, 1e-6));
    EXPECT_NEAR(in.points[0][0].radius, 0.002, 1e-9);
    ASSERT_EQ(in.meshes.size(), 1u);
    EXPECT_NEAR(in.meshes[0].surfaceArea(), tetrahedron().surfaceArea(), 1e-12);
    ASSERT_EQ(in.commands.size(), 1u);
    EXPECT_EQ(in.commands[0].first, "COMMAND");
    EXPECT_EQ(in.commands[0].second, cmd);
  });
  const auto stats = p.server->stats(p.connection());
  ASSERT_TRUE(stats.ok());
  EXPECT_EQ(stats->messagesIn, 10u);
  EXPECT_EQ(stats->typedDecodeFailures, 0u);
  EXPECT_EQ(stats->malformed, 0u);
}

// COMMAND is protocol v3; the reference 1.11 library has no COMMAND class,
// so the COMMAND / RTS_COMMAND exchange is checked between our two ends.
TEST(IgtlSession, CommandIsAnsweredWithRtsCommandOverTheSession) {
  Pair p({}, [](dm::IgtlServer& server, dm::ConnectionId id, const dmi::CommandInfo& c) {
    const dmi::CommandInfo reply{
        .id = c.id, .name = c.name, .content = "<Command><Result>true</Result></Command>"};
    ASSERT_TRUE(
        server.send(id, dmi::encodeCommand({.version = 3, .deviceName = "Ctl"}, reply, "RTS_COMMAND").value())
            .ok());
  });
  ASSERT_TRUE(p.client
                  ->send(dmi::encodeCommand({.version = 3, .deviceName = "Ctl"},
                                            {.id = 9, .name = "GetStatus", .content = "<Command/>"})
                             .value())
                  .ok());
  ASSERT_TRUE(eventually([&] { return p.clientBox.with([&] { return p.clientBox.commands.size() == 1; }); }));
  p.clientBox.with([&] {
    EXPECT_EQ(p.clientBox.commands[0].first, "RTS_COMMAND");
    EXPECT_EQ(p.clientBox.commands[0].second.id, 9u);
    EXPECT_EQ(p.clientBox.commands[0].second.name, "GetStatus");
    EXPECT_EQ(p.clientBox.commands[0].second.content, "<Command><Result>true</Result></Command>");
  });
}

TEST(IgtlSession, GetAnswersTheLatestPublishedMessageOrAnEmptyBody) {
  Pair p;
  Inbox& in = p.clientBox;
  // Nothing published yet: a TRANSFORM with the query's name and no body.
  ASSERT_TRUE(p.client->send(dmi::encodeQuery({.deviceName = "A"}, {.dataType = "TRANS"}).value()).ok());
  ASSERT_TRUE(eventually([&] { return in.rawCount("TRANSFORM") == 1; }));
  in.with([&] {
    EXPECT_EQ(in.raw[0].deviceName, "A");
    EXPECT_EQ(in.raw[0].bodySize, 0u);
  });

  const dm::Affine3 a1 = someTransform(0.1, {0.001, 0, 0}), a2 = someTransform(0.2, {0.002, 0, 0}),
                    b = someTransform(0.3, {0.003, 0, 0});
  ASSERT_TRUE(p.server->publish(dmi::encodeTransform({.deviceName = "A"}, a1).value()).ok());
  ASSERT_TRUE(p.server->publish(dmi::encodeTransform({.deviceName = "B"}, b).value()).ok());
  ASSERT_TRUE(p.server->publish(dmi::encodeTransform({.deviceName = "A"}, a2).value()).ok());
  for (const char* device : {"B", "A", ""})
    ASSERT_TRUE(p.client->send(dmi::encodeQuery({.deviceName = device}, {.dataType = "TRANS"}).value()).ok());
  ASSERT_TRUE(eventually([&] { return in.with([&] { return in.transforms.size() == 3; }); }));
  in.with([&] {
    EXPECT_EQ(in.transforms[0].first, "B");
    EXPECT_TRUE(in.transforms[0].second.matrix().isApprox(b.matrix(), 1e-6));
    EXPECT_EQ(in.transforms[1].first, "A");  // the latest of A, not the first
    EXPECT_TRUE(in.transforms[1].second.matrix().isApprox(a2.matrix(), 1e-6));
    EXPECT_EQ(in.transforms[2].first, "A");  // any device: the latest published
  });
  EXPECT_EQ(p.server->stats().queriesAnswered, 4u);
}

TEST(IgtlSession, SubscriptionDeliversLaterPublishesUntilStopped) {
  Pair p;
  Inbox& in = p.clientBox;
  auto tdata = [](int i) {
    return dmi::encodeRaw({.deviceName = "Tracker"}, "TDATA", Bytes(70, std::byte(i))).value();
  };
  ASSERT_EQ(p.server->publish(tdata(0)).value().sent, 0u);  // nobody subscribed yet

  ASSERT_TRUE(p.client
                  ->send(dmi::encodeQuery({.deviceName = "Tracker"},
                                          {.kind = dmi::QueryKind::Start, .dataType = "TDATA"})
                             .value())
                  .ok());
  ASSERT_TRUE(eventually([&] { return in.with([&] { return in.queries.size() == 1; }); }));
  in.with([&] {
    EXPECT_EQ(in.queries[0], (dmi::Query{.kind = dmi::QueryKind::Ready, .dataType = "TDATA", .status = 0}));
  });
  for (int i = 1; i <= 3; ++i) {
    auto f = p.server->publish(tdata(i));
    ASSERT_TRUE(f.ok());
    EXPECT_EQ(f->sent, 1u);
    EXPECT_TRUE(f->failures.empty());
  }
  // Another device's data is not part of this subscription.
  EXPECT_EQ(p.server->publish(dmi::encodeRaw({.deviceName = "Other"}, "TDATA", Bytes(70)).value())->sent, 0u);
  ASSERT_TRUE(eventually([&] { return in.rawCount("TDATA") == 3; }));

  ASSERT_TRUE(p.client
                  ->send(dmi::encodeQuery({.deviceName = "Tracker"},
                                          {.kind = dmi::QueryKind::Stop, .dataType = "TDATA"})
                             .value())
                  .ok());
  ASSERT_TRUE(eventually([&] { return in.with([&] { return in.queries.size() == 2; }); }));
  in.with([&] { EXPECT_EQ(in.queries[1].status, 0); });
  EXPECT_EQ(p.server->publish(tdata(4))->sent, 0u);
  // A GET_ answered after it is a barrier: nothing else came before it.
  ASSERT_TRUE(p.client->send(dmi::encodeQuery({}, {.dataType = "STATUS"}).value()).ok());
  ASSERT_TRUE(eventually([&] { return in.rawCount("STATUS") == 1; }));
  EXPECT_EQ(in.rawCount("TDATA"), 3u);
}

// STT_TDATA at a 60 s resolution from p's client, answered (its first query).
testing::AssertionResult subscribeOncePerMinute(Pair& p) {
  Inbox& in = p.clientBox;
  if (!p.client
           ->send(dmi::encodeQuery({}, {.kind = dmi::QueryKind::Start,
                                        .dataType = "TDATA",
                                        .resolutionMs = 60'000,
                                        .coordinateName = "Patient"})
                      .value())
           .ok())
    return testing::AssertionFailure() << "STT_TDATA not sent";
  if (!eventually([&] { return in.with([&] { return in.queries.size() == 1; }); }))
    return testing::AssertionFailure() << "no RTS_TDATA";
  return testing::AssertionSuccess();
}

TEST(IgtlSession, SttResolutionSkipsPublishesThatComeTooSoon) {
  Pair p;
  Inbox& in = p.clientBox;
  ASSERT_TRUE(subscribeOncePerMinute(p));
  const Bytes m = dmi::encodeRaw({.deviceName = "Tracker"}, "TDATA", Bytes(70)).value();
  EXPECT_EQ(p.server->publish(m)->sent, 1u);
  // Within one minute of the first: skipped for this subscriber.
  for (int i = 0; i < 3; ++i) {
    auto f = p.server->publish(m);
    EXPECT_EQ(f->sent, 0u);
    EXPECT_EQ(f->throttled, 1u);
  }
  EXPECT_EQ(p.server->stats().throttled, 3u);
  ASSERT_TRUE(eventually([&] { return in.rawCount("TDATA") == 1; }));
}

// Publishing to everyone (a streaming server, as a scene's OpenIGTLink
// engine is): a client that never subscribed gets every message, one that
// subscribed with a resolution still gets them as its STT_ asked.
TEST(IgtlSession, PublishToEveryoneReachesClientsThatNeverSubscribed) {
  Pair p;
  Inbox& in = p.clientBox;
  const Bytes t = dmi::encodeTransform({.deviceName = "Tool"}, dm::Isometry3::Identity()).value();
  for (int i = 0; i < 3; ++i) {
    auto f = p.server->publish(t, dm::IgtlPublishTo::Everyone);
    ASSERT_TRUE(f.ok());
    EXPECT_EQ(f->sent, 1u);
  }
  EXPECT_EQ(p.server->publish(t)->sent, 0u);  // to subscribers only: none
  ASSERT_TRUE(eventually([&] { return in.with([&] { return in.transforms.size() == 3; }); }));
  ASSERT_TRUE(eventually([&] { return p.server->queuedBytes() == 0; }));

  ASSERT_TRUE(subscribeOncePerMinute(p));
  const Bytes m = dmi::encodeRaw({.deviceName = "Tracker"}, "TDATA", Bytes(70)).value();
  EXPECT_EQ(p.server->publish(m, dm::IgtlPublishTo::Everyone)->sent, 1u);
  EXPECT_EQ(p.server->publish(m, dm::IgtlPublishTo::Everyone)->throttled, 1u);
  ASSERT_TRUE(eventually([&] { return in.rawCount("TDATA") == 1; }));
}

TEST(IgtlSession, OversizeBodySizeClosesTheConnectionBeforeTheBody) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  Inbox box;
  auto server = dm::IgtlServer::listen(net, {.decode = {.maxBodyBytes = 4096}}, box.handlers());
  ASSERT_TRUE(server.ok());
  std::atomic<bool> lost{false};
  auto raw = dm::TcpClient::connect(net, {.peer = {"127.0.0.1", (*server)->port()}},
                                    {.onState = [&](dm::ConnectionState s, const std::string&) {
                                      if (s == dm::ConnectionState::Disconnected) lost = true;
                                    }});
  ASSERT_TRUE(raw.ok());
  ASSERT_TRUE((*raw)->waitConnected(5s).ok());
  Bytes header = dmi::encodeRaw({.deviceName = "Big"}, "IMAGE", {}).value();
  putBe64(header, 42, std::uint64_t{1} << 30);  // 1 GiB announced, none sent
  ASSERT_TRUE((*raw)->send(header).ok());
  // The server closes without waiting for a body byte.
  ASSERT_TRUE(eventually([&] { return lost.load(); }));
  const dm::IgtlStats s = (*server)->stats();
  EXPECT_EQ(s.malformed, 1u);
  EXPECT_EQ(s.messagesIn, 0u);
  EXPECT_TRUE((*server)->connections().empty());
  EXPECT_TRUE(box.raw.empty());
}

TEST(IgtlSession, BadCrcClosesTheConnectionAndIsCounted) {
  Pair p;
  const Bytes good = dmi::encodeString({}, {.text = "first"}).value();
  Bytes bad = dmi::encodeString({}, {.text = "second"}).value();
  bad[dmi::kHeaderBytes + 5] ^= std::byte{0x20};
  ASSERT_TRUE(p.client->send(good).ok());
  // send() checks the framing only; the CRC is the encoder's business.
  ASSERT_TRUE(p.client->send(bad).ok());
  ASSERT_TRUE(eventually([&] { return p.server->connections().empty(); }));
  EXPECT_EQ(p.server->stats().malformed, 1u);
  EXPECT_EQ(p.server->stats().messagesIn, 1u);
  p.serverBox.with([&] {
    ASSERT_EQ(p.serverBox.strings.size(), 1u);
    EXPECT_EQ(p.serverBox.strings[0].text, "first");
  });
  ASSERT_TRUE(eventually([&] { return p.client->state() == dm::ConnectionState::Disconnected; }));
}

TEST(IgtlSession, BadTypedBodyIsCountedAndTheConnectionStays) {
  Pair p;
  const dm::Affine3 t = someTransform(0.5, {0.01, 0.01, 0.01});
  ASSERT_TRUE(p.client->send(dmi::encodeRaw({.deviceName = "Tool"}, "TRANSFORM", Bytes(40)).value()).ok());
  Bytes nan(48, std::byte{0xFF});  // 12 NaNs
  ASSERT_TRUE(p.client->send(dmi::encodeRaw({.deviceName = "Tool"}, "TRANSFORM", nan).value()).ok());
  ASSERT_TRUE(p.client->send(dmi::encodeRaw({}, "GET_IMAGE", Bytes(3)).value()).ok());  // GET_ with a body
  ASSERT_TRUE(p.client->send(dmi::encodeTransform({.deviceName = "Tool"}, t).value()).ok());
  ASSERT_TRUE(
      eventually([&] { return p.serverBox.with([&] { return p.serverBox.transforms.size() == 1; }); }));
  p.serverBox.with(
      [&] { EXPECT_TRUE(p.serverBox.transforms[0].second.matrix().isApprox(t.matrix(), 1e-6)); });
  const auto s = p.server->stats(p.connection());
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->typedDecodeFailures, 3u);
  EXPECT_EQ(s->messagesIn, 4u);
  EXPECT_EQ(s->malformed, 0u);
  EXPECT_EQ(p.server->connections().size(), 1u);
}

TEST(IgtlSession, ClientClosesOnAMalformedStreamFromTheServer) {
  dm::IoThread net;
  ASSERT_TRUE(net.start().ok());
  auto raw = dm::TcpServer::listen(net, {}, {});
  ASSERT_TRUE(raw.ok());
  Inbox box;
  auto client =
      dm::IgtlClient::connect(net, {.tcp = {.peer = {"127.0.0.1", (*raw)->port()}}}, box.handlers());
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE((*client)->waitConnected(5s).ok());
  ASSERT_TRUE(eventually([&] { return (*raw)->connections().size() == 1; }));
  const auto id = (*raw)->connections()[0];
  ASSERT_TRUE((*raw)->send(id, dmi::encodeString({}, {.text = "fine"}).value()).ok());
  ASSERT_TRUE((*raw)->send(id, Bytes(64, std::byte{0})).ok());  // version 0: garbage
  ASSERT_TRUE(eventually([&] { return (*client)->state() == dm::ConnectionState::Closed; }));
  EXPECT_EQ((*client)->stats().malformed, 1u);
  EXPECT_EQ((*client)->stats().messagesIn, 1u);
  box.with([&] { EXPECT_EQ(box.strings.size(), 1u); });
}

TEST(IgtlSession, SendRefusesWhatIsNotOneMessageAndReportsBackPressure) {
  Pair p({.tcp = {.sendQueueBytes = 100}});
  const Bytes msg = dmi::encodeString({}, {.text = std::string(200, 'x')}).value();
  EXPECT_EQ(p.client->send(std::span(msg).first(70)).error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_EQ(p.client->send(concat({msg, msg})).error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_EQ(p.server->send(p.connection(), Bytes(10)).error().code, dm::ErrorCode::InvalidArgument);
  EXPECT_EQ(p.server->send(9999, msg).error().code, dm::ErrorCode::NotFound);
  // 262 bytes into a 100-byte queue: Busy, returned to the caller.
  const dm::Status busy = p.server->send(p.connection(), msg);
  ASSERT_FALSE(busy.ok());
  EXPECT_EQ(busy.error().code, dm::ErrorCode::Busy);
  auto fan = p.server->publish(msg);
  ASSERT_TRUE(fan.ok());
  auto all = p.server->broadcast(msg);
  ASSERT_TRUE(all.ok());
  ASSERT_EQ(all->failures.size(), 1u);
  EXPECT_EQ(all->failures[0].second.code, dm::ErrorCode::Busy);
  EXPECT_EQ(p.server->stats().sendFailures, 2u);
}

}  // namespace
