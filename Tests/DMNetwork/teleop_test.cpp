// Tests of the tele-operation stream (dm/network/teleop.hpp): the payload
// codec against hand-laid bytes and corruption, and each end's handling of
// loss, reordering, duplicates, clock offset, round-trip timing and RFC 3550
// jitter, driven by a raw POSIX socket that plays the other end with
// sequence numbers and timestamps the test chooses.
#include <dm/core/clock.hpp>
#include <dm/network/teleop.hpp>

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <thread>
#include <vector>

#include "../common/eventually.hpp"
#include "network_test_support.hpp"

namespace {

using namespace std::chrono_literals;
using dm::test::eventually;
using dm::test::monotonicNs;

dm::HapticState sampleState(double k) {
  dm::HapticState s;
  s.timeNs = 123456789;
  s.position = dm::Vec3(0.01 * k, -0.02, 0.03);
  s.orientation = dm::Quat(Eigen::AngleAxisd(0.3 * k, dm::Vec3(0, 0, 1)));
  s.linearVelocity = dm::Vec3(0.1, 0.2 * k, -0.3);
  s.angularVelocity = dm::Vec3(1, 2, 3);
  s.buttons = 0b101;
  return s;
}

using dm::test::sampleInfo;

/// A plain UDP socket on 127.0.0.1 that plays one end by hand.
class RawUdpPeer {
 public:
  RawUdpPeer() {
    fd_ = ::socket(AF_INET, SOCK_DGRAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a);
    socklen_t n = sizeof a;
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &n);
    port_ = ntohs(a.sin_port);
  }
  ~RawUdpPeer() { ::close(fd_); }
  std::uint16_t port() const { return port_; }
  void sendTo(std::uint16_t port, std::span<const std::byte> bytes) const {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(port);
    ::sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<sockaddr*>(&a), sizeof a);
  }
  /// One datagram within `timeout`, or nothing.
  std::optional<std::vector<std::byte>> receive(std::chrono::milliseconds timeout) const {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(timeout.count())) != 1) return std::nullopt;
    std::vector<std::byte> buffer(2048);
    const ssize_t n = ::recv(fd_, buffer.data(), buffer.size(), 0);
    if (n < 0) return std::nullopt;
    buffer.resize(static_cast<std::size_t>(n));
    return buffer;
  }

 private:
  int fd_ = -1;
  std::uint16_t port_ = 0;
};

std::vector<std::byte> stateDatagram(std::uint32_t sequence, std::int64_t sendNs, const dm::HapticState& s,
                                     dm::TeleopEcho echo = {}) {
  std::vector<std::byte> out(dm::kTeleopMaxDatagram);
  out.resize(dm::writeTeleopState({.sequence = sequence, .timestampNs = sendNs}, echo, s, out));
  return out;
}

class TeleopEnds : public ::testing::Test {};

// ---- codec ---------------------------------------------------------------------

TEST(TeleopCodec, StateRoundTripsBitExactlyAndHasTheDocumentedLayout) {
  const dm::HapticState s = sampleState(1.0);
  const auto bytes = stateDatagram(42, 1000, s, {.peerSendNs = 777, .holdNs = 5});
  ASSERT_EQ(bytes.size(), dm::kMessageHeaderBytes + dm::kTeleopStateBytes);
  // Payload layout: echo (16), device time (8), position at payload byte 24.
  double x = 0;
  std::memcpy(&x, bytes.data() + 28 + 24, 8);
  EXPECT_EQ(x, s.position.x());
  auto p = dm::decodeTeleopPacket(bytes);
  ASSERT_TRUE(p) << p.error().message();
  EXPECT_EQ(p->header.type, dm::kTeleopStateType);
  EXPECT_EQ(p->header.sequence, 42u);
  EXPECT_EQ(p->header.timestampNs, 1000);
  EXPECT_EQ(p->echo.peerSendNs, 777);
  EXPECT_EQ(p->echo.holdNs, 5);
  EXPECT_EQ(p->state.timeNs, s.timeNs);
  EXPECT_EQ(p->state.position, s.position);
  EXPECT_NEAR(p->state.orientation.angularDistance(s.orientation), 0.0, 1e-12);
  EXPECT_EQ(p->state.linearVelocity, s.linearVelocity);
  EXPECT_EQ(p->state.angularVelocity, s.angularVelocity);
  EXPECT_EQ(p->state.buttons, s.buttons);
}

TEST(TeleopCodec, ForceHelloAndInfoRoundTrip) {
  std::array<std::byte, dm::kTeleopMaxDatagram> buffer{};
  dm::HapticOutput f;
  f.force = dm::Vec3(1.5, -2, 3);
  f.torque = dm::Vec3(0.1, 0, -0.2);
  const std::size_t n = dm::writeTeleopForce({.sequence = 9}, {.peerSendNs = 1, .holdNs = 2}, f, buffer);
  ASSERT_EQ(n, 28 + dm::kTeleopForceBytes);
  auto force = dm::decodeTeleopPacket(std::span(buffer.data(), n));
  ASSERT_TRUE(force);
  EXPECT_EQ(force->force.force, f.force);
  EXPECT_EQ(force->force.torque, f.torque);

  const std::size_t h = dm::writeTeleopHello({}, buffer);
  auto hello = dm::decodeTeleopPacket(std::span(buffer.data(), h));
  ASSERT_TRUE(hello);
  EXPECT_EQ(hello->version, dm::kTeleopVersion);

  const dm::HapticInfo info = sampleInfo();
  auto decoded = dm::decodeTeleopPacket(dm::encodeTeleopInfo({}, info));
  ASSERT_TRUE(decoded) << decoded.error().message();
  EXPECT_EQ(decoded->info.driver, info.driver);
  EXPECT_EQ(decoded->info.model, info.model);
  EXPECT_EQ(decoded->info.serial, info.serial);
  EXPECT_EQ(decoded->info.capabilities, info.capabilities);
  EXPECT_EQ(decoded->info.buttonCount, 2u);
  EXPECT_EQ(decoded->info.workspace.min(), info.workspace.min());
  EXPECT_EQ(decoded->info.workspace.max(), info.workspace.max());
  EXPECT_EQ(decoded->info.maxForce, 8.0);
  EXPECT_EQ(decoded->info.servoRateHz, 1000.0);
}

TEST(TeleopCodec, WritersRefuseBuffersThatAreTooSmall) {
  std::array<std::byte, 40> small{};
  EXPECT_EQ(dm::writeTeleopState({}, {}, sampleState(1), small), 0u);
  EXPECT_EQ(dm::writeTeleopForce({}, {}, {}, small), 0u);
  EXPECT_EQ(dm::writeTeleopHello({}, std::span(small).first(31)), 0u);
}

TEST(TeleopCodec, EverySingleBitFlipIsRefused) {
  const auto bytes = stateDatagram(1, 2, sampleState(1));
  for (std::size_t bit = 0; bit < bytes.size() * 8; ++bit) {
    auto copy = bytes;
    copy[bit / 8] ^= std::byte{static_cast<unsigned char>(1u << (bit % 8))};
    EXPECT_FALSE(dm::decodeTeleopPacket(copy)) << "bit " << bit;
  }
}

TEST(TeleopCodec, MalformedPayloadsAreRefusedNamingTheByte) {
  // Non-finite position x: payload byte 24, datagram byte 52.
  dm::HapticState s = sampleState(1);
  s.position.x() = std::numeric_limits<double>::quiet_NaN();
  auto nan = dm::decodeTeleopPacket(stateDatagram(1, 1, s));
  ASSERT_FALSE(nan);
  EXPECT_EQ(nan.error().code, dm::ErrorCode::Parse);
  EXPECT_NE(nan.error().message().find("datagram byte 52"), std::string::npos) << nan.error().message();

  // A quaternion of norm 2.
  s = sampleState(1);
  s.orientation.coeffs() *= 2.0;
  auto quat = dm::decodeTeleopPacket(stateDatagram(1, 1, s));
  ASSERT_FALSE(quat);
  EXPECT_NE(quat.error().message().find("norm 2"), std::string::npos) << quat.error().message();

  // A payload one byte short, resealed so only the size is wrong.
  std::vector<std::byte> shortMsg(28 + dm::kTeleopForceBytes - 1);
  dm::sealMessage({.type = dm::kTeleopForceType}, shortMsg, dm::kTeleopForceBytes - 1);
  auto size = dm::decodeTeleopPacket(shortMsg);
  ASSERT_FALSE(size);
  EXPECT_NE(size.error().message().find("expected 64"), std::string::npos) << size.error().message();

  // Another type of the message model.
  std::vector<std::byte> other(28 + 4);
  dm::sealMessage({.type = 0x0001}, other, 4);
  EXPECT_FALSE(dm::decodeTeleopPacket(other));

  // A Hello of another version.
  std::vector<std::byte> hello(28 + 4);
  hello[28] = std::byte{2};
  dm::sealMessage({.type = dm::kTeleopHelloType}, hello, 4);
  auto version = dm::decodeTeleopPacket(hello);
  ASSERT_FALSE(version);
  EXPECT_EQ(version.error().code, dm::ErrorCode::Version);

  // An Info whose model string fills its 64 bytes without a NUL.
  auto info = dm::encodeTeleopInfo({}, sampleInfo());
  std::memset(info.data() + 28 + 128, 'x', 64);
  dm::sealMessage({.type = dm::kTeleopInfoType}, info, dm::kTeleopInfoBytes);
  auto unterminated = dm::decodeTeleopPacket(info);
  ASSERT_FALSE(unterminated);
  EXPECT_NE(unterminated.error().message().find("NUL"), std::string::npos);
}

// ---- host end ------------------------------------------------------------------

TEST_F(TeleopEnds, HostClassifiesLossReorderingAndDuplicatesAndKeepsTheNewestState) {
  RawUdpPeer device;
  auto host = dm::TeleopHost::open({.peer = {"127.0.0.1", device.port()}, .clocksSynchronized = true});
  ASSERT_TRUE(host) << host.error().message();
  // 0 1 2 5 (gap of 2) 4 (late) 4 (duplicate) 3 (late): the newest is 5.
  const std::uint32_t order[] = {0, 1, 2, 5, 4, 4, 3};
  for (std::uint32_t seq : order)
    device.sendTo((*host)->port(), stateDatagram(seq, monotonicNs(), sampleState(seq)));
  ASSERT_TRUE(eventually([&] { return (*host)->stats().received + (*host)->stats().duplicates == 7; }));
  const dm::TeleopStats s = (*host)->stats();
  EXPECT_EQ(s.received, 6u);
  EXPECT_EQ(s.duplicates, 1u);
  EXPECT_EQ(s.late, 2u);
  EXPECT_EQ(s.lost, 0u);  // 3 and 4 arrived late
  dm::HapticState latest;
  ASSERT_TRUE((*host)->latestState(latest));
  EXPECT_EQ(latest.position, sampleState(5).position);
  EXPECT_TRUE((*host)->linkUp());

  // 10 after 5: 6..9 lost.
  device.sendTo((*host)->port(), stateDatagram(10, monotonicNs(), sampleState(10)));
  ASSERT_TRUE(eventually([&] { return (*host)->stats().received == 7; }));
  EXPECT_EQ((*host)->stats().lost, 4u);
  EXPECT_NEAR((*host)->stats().lossRatio, 4.0 / 11.0, 1e-12);
}

TEST_F(TeleopEnds, HostDropsMalformedAndForeignDatagramsWithoutLosingTheLink) {
  RawUdpPeer device, stranger;
  auto host = dm::TeleopHost::open({.peer = {"127.0.0.1", device.port()}});
  ASSERT_TRUE(host);
  device.sendTo((*host)->port(), stateDatagram(0, monotonicNs(), sampleState(1)));
  auto garbage = stateDatagram(1, monotonicNs(), sampleState(2));
  garbage[40] ^= std::byte{0x10};
  device.sendTo((*host)->port(), garbage);
  stranger.sendTo((*host)->port(), stateDatagram(1, monotonicNs(), sampleState(3)));
  ASSERT_TRUE(eventually([&] { return (*host)->stats().malformed == 1 && (*host)->stats().foreign == 1; }));
  dm::HapticState latest;
  ASSERT_TRUE((*host)->latestState(latest));
  EXPECT_EQ(latest.position, sampleState(1).position);
  EXPECT_EQ((*host)->stats().received, 1u);
}

TEST_F(TeleopEnds, RoundTripSubtractsTheHoldTimeTheDeviceReports) {
  RawUdpPeer device;
  auto host = dm::TeleopHost::open({.peer = {"127.0.0.1", device.port()}});
  ASSERT_TRUE(host);
  // Round 1: the device holds the force 30 ms and says so: round trip ≈ wire time only.
  // Round 2: it holds it 30 ms and claims 0: round trip ≥ 30 ms.
  double measured[2] = {0, 0};
  for (int round = 0; round < 2; ++round) {
    ASSERT_TRUE((*host)->sendForce({}));
    auto got = device.receive(2000ms);
    ASSERT_TRUE(got);
    const std::int64_t arrived = monotonicNs();
    auto force = dm::decodeTeleopPacket(*got);
    ASSERT_TRUE(force);
    std::this_thread::sleep_for(30ms);
    const std::int64_t now = monotonicNs();
    const dm::TeleopEcho echo{force->header.timestampNs, round == 0 ? now - arrived : 0};
    device.sendTo((*host)->port(), stateDatagram(static_cast<std::uint32_t>(round), now, sampleState(1), echo));
    ASSERT_TRUE(eventually([&] { return (*host)->stats().roundTrip.count == static_cast<std::uint64_t>(round + 1); }));
    measured[round] = (*host)->stats().roundTrip.last;
  }
  EXPECT_GE(measured[0], 0.0);
  EXPECT_LT(measured[0], 0.025);  // loopback wire time, far below the 30 ms hold
  EXPECT_GE(measured[1], 0.030);
}

TEST_F(TeleopEnds, ClockOffsetOfThePeerIsEstimatedAndOneWayLatencyCorrected) {
  RawUdpPeer device;
  auto host = dm::TeleopHost::open({.peer = {"127.0.0.1", device.port()}});
  ASSERT_TRUE(host);
  const std::int64_t offset = 2'000'000'000;  // the device's clock reads 2 s ahead
  for (std::uint32_t i = 0; i < 20; ++i) {
    ASSERT_TRUE((*host)->sendForce({}));
    auto got = device.receive(2000ms);
    ASSERT_TRUE(got);
    const std::int64_t arrived = monotonicNs() + offset;
    auto force = dm::decodeTeleopPacket(*got);
    ASSERT_TRUE(force);
    const std::int64_t now = monotonicNs() + offset;
    device.sendTo((*host)->port(),
                  stateDatagram(i, now, sampleState(1), {force->header.timestampNs, now - arrived}));
    ASSERT_TRUE(eventually([&] { return (*host)->stats().received == i + 1; }));
  }
  const dm::TeleopStats s = (*host)->stats();
  // NTP's estimate errs by at most half the round-trip asymmetry (< the round trip).
  EXPECT_NEAR(s.clockOffset, 2.0, s.roundTrip.min + 1e-4);
  EXPECT_EQ(s.oneWay.count, 20u);
  EXPECT_GE(s.oneWay.min, 0.0);
  EXPECT_LT(s.oneWay.p50, 0.025);  // not 2 s: the offset is removed
}

TEST_F(TeleopEnds, JitterFollowsRfc3550ForAKnownTransitDifference) {
  RawUdpPeer device;
  auto host = dm::TeleopHost::open({.peer = {"127.0.0.1", device.port()}, .clocksSynchronized = true});
  ASSERT_TRUE(host);
  // Send timestamps 1 ms apart, sent back to back: each D ≈ −1 ms, so after
  // n datagrams J = 1 ms · (1 − (15/16)^(n−1)) (RFC 3550 §6.4.1).
  const int n = 33;
  const std::int64_t t0 = monotonicNs();
  for (int i = 0; i < n; ++i)
    device.sendTo((*host)->port(), stateDatagram(static_cast<std::uint32_t>(i), t0 + i * 1'000'000, sampleState(1)));
  ASSERT_TRUE(eventually([&] { return (*host)->stats().received == static_cast<std::uint64_t>(n); }));
  const double expected = 1e-3 * (1.0 - std::pow(15.0 / 16.0, n - 1));
  // Arrival spacing on loopback is microseconds; allow 0.15 ms for a slow machine.
  EXPECT_NEAR((*host)->stats().jitter, expected, 0.15e-3);
}

TEST_F(TeleopEnds, AnEmulatedLinkDelaysAndLosesWhatArrives) {
  RawUdpPeer device;
  auto host = dm::TeleopHost::open({.peer = {"127.0.0.1", device.port()},
                                    .clocksSynchronized = true,
                                    .emulate = dm::LinkEmulatorOptions{.delay = std::chrono::milliseconds(30),
                                                                       .lossProbability = 0.2,
                                                                       .seed = 11}});
  ASSERT_TRUE(host) << host.error().message();
  const int n = 300;
  for (int i = 0; i < n; ++i)
    device.sendTo((*host)->port(), stateDatagram(static_cast<std::uint32_t>(i), monotonicNs(), sampleState(1)));
  // The last one may be lost too: wait until nothing more is in flight.
  std::this_thread::sleep_for(150ms);
  const dm::TeleopStats s = (*host)->stats();
  EXPECT_GE(s.oneWay.min, 0.030);  // every datagram waited at least the emulated delay
  EXPECT_GT(s.received, 0.65 * n);  // 20 % lost: 240 expected, 6 sigma is ±42
  EXPECT_LT(s.received, 0.95 * n);
  EXPECT_LE(s.received + s.lost, static_cast<std::uint64_t>(n));  // trailing losses are not yet known
  EXPECT_NEAR(s.lossRatio, 0.2, 0.12);
}

TEST_F(TeleopEnds, WaveSamplesCrossBothWaysInArrivalOrder) {
  auto device = dm::TeleopDevice::open({}, sampleInfo());
  ASSERT_TRUE(device);
  auto host = dm::TeleopHost::open({.peer = {"127.0.0.1", (*device)->port()}});
  ASSERT_TRUE(host);
  ASSERT_TRUE((*host)->waitForDevice(2000ms));  // the device learns its host
  dm::WaveSender tx(1e-3);
  std::vector<dm::WaveSample> sent;
  for (int i = 0; i < 5; ++i) sent.push_back(tx.send(dm::Vec3(0.1 * i, -0.2, 0.3)));
  for (const auto& w : sent) ASSERT_TRUE((*device)->sendWave(w));
  for (const auto& w : sent) ASSERT_TRUE((*host)->sendWave(w));
  std::vector<dm::WaveSample> atHost, atDevice;
  ASSERT_TRUE(eventually([&] {
    dm::WaveSample w;
    while ((*host)->popWave(w)) atHost.push_back(w);
    while ((*device)->popWave(w)) atDevice.push_back(w);
    return atHost.size() == sent.size() && atDevice.size() == sent.size();
  }));
  for (std::size_t i = 0; i < sent.size(); ++i) {
    EXPECT_EQ(atHost[i].wave, sent[i].wave);
    EXPECT_EQ(atHost[i].sequence, sent[i].sequence);
    EXPECT_EQ(atHost[i].energy, sent[i].energy);
    EXPECT_EQ(atDevice[i].sequence, sent[i].sequence);
  }
  EXPECT_EQ((*host)->stats().wavesIn, sent.size());
  EXPECT_EQ((*device)->stats().wavesDropped, 0u);
}

TEST_F(TeleopEnds, WaitForDeviceTimesOutNamingThePeer) {
  RawUdpPeer silent;
  auto host = dm::TeleopHost::open({.peer = {"127.0.0.1", silent.port()}});
  ASSERT_TRUE(host);
  auto info = (*host)->waitForDevice(120ms);
  ASSERT_FALSE(info);
  EXPECT_EQ(info.error().code, dm::ErrorCode::Timeout);
  EXPECT_NE(info.error().message().find("127.0.0.1:" + std::to_string(silent.port())), std::string::npos)
      << info.error().message();
  EXPECT_GE(silent.receive(100ms).has_value(), true);  // it did say Hello
}

TEST_F(TeleopEnds, BadOptionsAreRefused) {
  EXPECT_FALSE(dm::TeleopHost::open({.peer = {"127.0.0.1", 0}}));
  EXPECT_FALSE(dm::TeleopHost::open({.peer = {"not an address", 5}}));
  EXPECT_FALSE(dm::TeleopHost::open({.peer = {"127.0.0.1", 5}, .timeoutSeconds = 0}));
  EXPECT_FALSE(dm::TeleopDevice::open({.allow = {"nonsense"}}, sampleInfo()));
}

// ---- device end ------------------------------------------------------------------

TEST_F(TeleopEnds, DeviceAnswersHelloLearnsItsHostAndRefusesASecondHostWhileTheFirstIsAlive) {
  auto device = dm::TeleopDevice::open({.timeoutSeconds = 0.15}, sampleInfo());
  ASSERT_TRUE(device);
  EXPECT_FALSE((*device)->sendState(sampleState(1)));  // no host yet
  EXPECT_FALSE((*device)->linkUp());

  RawUdpPeer first, second;
  std::array<std::byte, 64> hello{};
  const std::size_t n = dm::writeTeleopHello({}, hello);
  first.sendTo((*device)->port(), std::span(hello.data(), n));
  auto info = first.receive(2000ms);
  ASSERT_TRUE(info);
  auto decoded = dm::decodeTeleopPacket(*info);
  ASSERT_TRUE(decoded);
  EXPECT_EQ(decoded->info.model, sampleInfo().model);
  EXPECT_TRUE((*device)->linkUp());
  ASSERT_TRUE((*device)->sendState(sampleState(2)));
  auto state = first.receive(2000ms);
  ASSERT_TRUE(state);
  EXPECT_EQ(dm::decodeTeleopPacket(*state)->state.position, sampleState(2).position);

  // A second host is refused while the first is alive...
  std::array<std::byte, 128> force{};
  dm::HapticOutput f;
  f.force = dm::Vec3(1, 2, 3);
  std::size_t m = dm::writeTeleopForce({.sequence = 0}, {}, f, force);
  second.sendTo((*device)->port(), std::span(force.data(), m));
  ASSERT_TRUE(eventually([&] { return (*device)->stats().foreign == 1; }));
  dm::HapticOutput got;
  EXPECT_FALSE((*device)->latestForce(got));

  // ...and adopted once the first fell silent for the timeout.
  std::this_thread::sleep_for(200ms);
  second.sendTo((*device)->port(), std::span(force.data(), m));
  ASSERT_TRUE(eventually([&] { return (*device)->latestForce(got); }));
  EXPECT_EQ(got.force, f.force);
  ASSERT_TRUE((*device)->sendState(sampleState(3)));
  EXPECT_TRUE(second.receive(2000ms).has_value());
}

TEST_F(TeleopEnds, DeviceAllowListRefusesOtherHosts) {
  auto device = dm::TeleopDevice::open({.allow = {"127.0.0.2"}}, sampleInfo());
  ASSERT_TRUE(device);
  RawUdpPeer host;  // 127.0.0.1: not allowed
  std::array<std::byte, 64> hello{};
  host.sendTo((*device)->port(), std::span(hello.data(), dm::writeTeleopHello({}, hello)));
  ASSERT_TRUE(eventually([&] { return (*device)->stats().foreign == 1; }));
  EXPECT_FALSE(host.receive(50ms).has_value());
  EXPECT_FALSE((*device)->linkUp());
}

}  // namespace
