// SLIP (RFC 1055): the RFC's escaping, round trips of random packets with
// every chunk split point, protocol violations with their stream offsets,
// the frame length limit.
#include <dm/network/slip.hpp>

#include <gtest/gtest.h>

#include <random>

namespace {

using Bytes = std::vector<std::byte>;

Bytes bytes(std::initializer_list<int> v) {
  Bytes b;
  for (int x : v) b.push_back(static_cast<std::byte>(x));
  return b;
}

struct Collector {
  std::vector<Bytes> frames;
  std::vector<dm::SlipFault> faults;
  void feed(dm::SlipDecoder& d, std::span<const std::byte> chunk) {
    d.feed(
        chunk, [&](std::span<const std::byte> f) { frames.emplace_back(f.begin(), f.end()); },
        [&](const dm::SlipFault& f) { faults.push_back(f); });
  }
};

Bytes randomPacket(std::mt19937& rng, std::size_t n) {
  // Biased towards the special bytes so escapes are exercised densely.
  std::uniform_int_distribution<int> pick(0, 9), any(0, 255);
  Bytes b(n);
  for (auto& x : b) {
    const int k = pick(rng);
    x = static_cast<std::byte>(k == 0 ? 0xC0 : k == 1 ? 0xDB : k == 2 ? 0xDC : k == 3 ? 0xDD : any(rng));
  }
  return b;
}

TEST(Slip, EncodesTheRfcEscapes) {
  // RFC 1055: END → ESC ESC_END, ESC → ESC ESC_ESC, others verbatim, framed by END.
  EXPECT_EQ(dm::encodeSlip(bytes({0x01, 0xC0, 0xDB, 0x02, 0xDC, 0xDD})),
            bytes({0xC0, 0x01, 0xDB, 0xDC, 0xDB, 0xDD, 0x02, 0xDC, 0xDD, 0xC0}));
  EXPECT_EQ(dm::encodeSlip({}), bytes({0xC0, 0xC0}));
}

TEST(Slip, EncodedBodyHasNoEndAndEveryEscIsFollowedByACode) {
  std::mt19937 rng(1);
  const Bytes wire = dm::encodeSlip(randomPacket(rng, 4000));
  ASSERT_GE(wire.size(), 2u);
  for (std::size_t i = 1; i + 1 < wire.size(); ++i) {
    EXPECT_NE(wire[i], dm::kSlipEnd) << i;
    if (wire[i] == dm::kSlipEsc) {
      EXPECT_TRUE(wire[i + 1] == dm::kSlipEscEnd || wire[i + 1] == dm::kSlipEscEsc);
    }
  }
}

TEST(Slip, RoundTripsRandomPacketsAtEverySplitPoint) {
  std::mt19937 rng(7);
  std::vector<Bytes> packets;
  Bytes wire;
  for (std::size_t n : {1u, 2u, 3u, 17u, 64u, 200u}) {
    packets.push_back(randomPacket(rng, n));
    dm::appendSlip(packets.back(), wire);
  }
  for (std::size_t split = 0; split <= wire.size(); ++split) {
    dm::SlipDecoder dec(256);
    Collector c;
    c.feed(dec, std::span(wire).first(split));
    c.feed(dec, std::span(wire).subspan(split));
    ASSERT_EQ(c.frames, packets) << "split at " << split;
    EXPECT_TRUE(c.faults.empty());
  }
  // Byte by byte as well (every ESC separated from its code).
  dm::SlipDecoder dec(256);
  Collector c;
  for (std::size_t i = 0; i < wire.size(); ++i) c.feed(dec, std::span(wire).subspan(i, 1));
  EXPECT_EQ(c.frames, packets);
  EXPECT_EQ(dec.stats().frames, packets.size());
  EXPECT_EQ(dec.stats().bytesIn, wire.size());
}

TEST(Slip, PollStopsAfterEachFrame) {
  Bytes wire = dm::encodeSlip(bytes({1, 2}));
  dm::appendSlip(bytes({3}), wire);
  dm::SlipDecoder dec;
  std::span<const std::byte> rest(wire);
  std::size_t n = dec.poll(rest);
  ASSERT_TRUE(dec.hasFrame());
  EXPECT_EQ(n, 4u);  // END 1 2 END
  EXPECT_EQ(Bytes(dec.frame().begin(), dec.frame().end()), bytes({1, 2}));
  rest = rest.subspan(n);
  n = dec.poll(rest);
  ASSERT_TRUE(dec.hasFrame());
  EXPECT_EQ(Bytes(dec.frame().begin(), dec.frame().end()), bytes({3}));
  EXPECT_EQ(n, rest.size());
  EXPECT_EQ(dec.poll({}), 0u);
  EXPECT_FALSE(dec.hasFrame());
}

TEST(Slip, EmptyFramesAndLeadingNoiseFlushesAreSkipped) {
  dm::SlipDecoder dec;
  Collector c;
  c.feed(dec, bytes({0xC0, 0xC0, 0xC0, 0x05, 0xC0, 0xC0}));
  EXPECT_EQ(c.frames, std::vector<Bytes>{bytes({0x05})});
}

TEST(Slip, BadEscapeDropsTheFrameReportsItsOffsetAndResyncsAtEnd) {
  // offsets:            0     1     2     3     4     5     6     7
  const Bytes wire = bytes({0xC0, 0x01, 0xDB, 0x41, 0x02, 0xC0, 0x05, 0xC0});
  for (std::size_t split = 0; split <= wire.size(); ++split) {
    dm::SlipDecoder dec;
    Collector c;
    c.feed(dec, std::span(wire).first(split));
    c.feed(dec, std::span(wire).subspan(split));
    ASSERT_EQ(c.faults.size(), 1u) << split;
    EXPECT_EQ(c.faults[0].kind, dm::SlipFaultKind::BadEscape);
    EXPECT_EQ(c.faults[0].streamOffset, 3u);
    EXPECT_EQ(c.faults[0].byte, 0x41);
    EXPECT_EQ(c.frames, std::vector<Bytes>{bytes({0x05})}) << split;
    EXPECT_EQ(dec.stats().badEscapes, 1u);
    EXPECT_NE(c.faults[0].message().find("stream byte 3"), std::string::npos);
  }
}

TEST(Slip, EscFollowedByEndDropsThatFrameAndTheEndStartsTheNext) {
  dm::SlipDecoder dec;
  Collector c;
  c.feed(dec, bytes({0xC0, 0x01, 0xDB, 0xC0, 0x07, 0xC0}));
  ASSERT_EQ(c.faults.size(), 1u);
  EXPECT_EQ(c.faults[0].streamOffset, 3u);
  EXPECT_EQ(c.frames, std::vector<Bytes>{bytes({0x07})});
}

TEST(Slip, OversizeFramesAreDroppedAndCountedWithoutGrowing) {
  dm::SlipDecoder dec(4);
  Collector c;
  Bytes wire = dm::encodeSlip(bytes({1, 2, 3, 4, 5, 6}));
  dm::appendSlip(bytes({1, 2, 3, 4}), wire);                    // exactly the limit: accepted
  dm::appendSlip(bytes({0xC0, 0xC0, 0xC0, 0xC0, 0xC0}), wire);  // 5 decoded bytes, escaped
  dm::appendSlip(bytes({9}), wire);
  c.feed(dec, wire);
  EXPECT_EQ(c.frames, (std::vector<Bytes>{bytes({1, 2, 3, 4}), bytes({9})}));
  ASSERT_EQ(c.faults.size(), 2u);
  EXPECT_EQ(c.faults[0].kind, dm::SlipFaultKind::Oversize);
  EXPECT_EQ(c.faults[0].streamOffset, 5u);  // END 1 2 3 4 [5]
  EXPECT_EQ(dec.stats().oversizeFrames, 2u);
  // First frame: 4 buffered + the 5th and 6th raw bytes; third: 4 buffered + ESC and its code.
  EXPECT_EQ(dec.stats().bytesDropped, (4u + 2u) + (4u + 2u));
}

TEST(Slip, EndlessGarbageWithoutEndIsCountedNotBuffered) {
  dm::SlipDecoder dec(16);
  Bytes junk(1 << 20, std::byte{0x41});
  Collector c;
  c.feed(dec, junk);
  EXPECT_TRUE(c.frames.empty());
  EXPECT_EQ(c.faults.size(), 1u);
  EXPECT_EQ(dec.stats().bytesDropped, junk.size());
  c.feed(dec, bytes({0xC0, 0x33, 0xC0}));
  EXPECT_EQ(c.frames, std::vector<Bytes>{bytes({0x33})});
}

}  // namespace
