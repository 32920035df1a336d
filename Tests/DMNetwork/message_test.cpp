// The DMPlatform message model: CRC-32C known answers, round trips, every
// single- and double-bit corruption rejected, limits checked before the
// payload arrives, stream framing at every split, and the sequence tracker.
#include <dm/network/crc.hpp>
#include <dm/network/message.hpp>

#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "network_test_support.hpp"

namespace {

using Bytes = std::vector<std::byte>;

using dm::test::ascii;

Bytes randomBytes(std::mt19937& rng, std::size_t n) {
  std::uniform_int_distribution<int> any(0, 255);
  Bytes b(n);
  for (auto& x : b) x = static_cast<std::byte>(any(rng));
  return b;
}

TEST(Crc32c, MatchesTheCatalogueCheckValueAndContinues) {
  // CRC-32C "check" from the CRC catalogue (RFC 3720 appendix B.4 polynomial).
  EXPECT_EQ(dm::crc32c(ascii("123456789")), 0xE3069283u);
  EXPECT_EQ(dm::crc32c({}), 0u);
  // RFC 3720 B.4: 32 bytes of zeros → 0x8A9136AA.
  EXPECT_EQ(dm::crc32c(Bytes(32, std::byte{0})), 0x8A9136AAu);
  const Bytes all = ascii("123456789");
  EXPECT_EQ(dm::crc32c(std::span(all).subspan(4), dm::crc32c(std::span(all).first(4))), 0xE3069283u);
}

TEST(Message, RoundTripsHeaderFieldsAndPayload) {
  std::mt19937 rng(3);
  for (std::size_t n : {0u, 1u, 27u, 1000u, 70000u}) {
    const Bytes payload = randomBytes(rng, n);
    const dm::MessageHeader h{
        .type = 0xBEEF, .flags = 0xA5, .sequence = 0xFFFFFFFEu, .timestampNs = -1234567890123LL};
    auto wire = dm::encodeMessage(h, payload);
    ASSERT_TRUE(wire.ok());
    ASSERT_EQ(wire->size(), dm::kMessageHeaderBytes + n);
    auto m = dm::decodeMessage(*wire);
    ASSERT_TRUE(m.ok()) << m.error().message();
    EXPECT_EQ(m->header.type, h.type);
    EXPECT_EQ(m->header.flags, h.flags);
    EXPECT_EQ(m->header.sequence, h.sequence);
    EXPECT_EQ(m->header.timestampNs, h.timestampNs);
    EXPECT_TRUE(std::equal(m->payload.begin(), m->payload.end(), payload.begin(), payload.end()));
  }
}

TEST(Message, HeaderIsLittleEndianAtTheDocumentedOffsets) {
  const Bytes payload = ascii("abc");
  auto wire =
      dm::encodeMessage({.type = 0x0102, .flags = 3, .sequence = 0x04050607, .timestampNs = 0x08}, payload);
  ASSERT_TRUE(wire.ok());
  const auto u = [&](std::size_t i) { return std::to_integer<int>((*wire)[i]); };
  EXPECT_EQ(u(0), 'D');
  EXPECT_EQ(u(3), 'M');
  EXPECT_EQ(u(4), 1);
  EXPECT_EQ(u(5), 3);
  EXPECT_EQ(u(6), 0x02);
  EXPECT_EQ(u(7), 0x01);
  EXPECT_EQ(u(8), 0x07);
  EXPECT_EQ(u(12), 3);
  EXPECT_EQ(u(16), 0x08);
  // The checksum is the CRC-32C of bytes [0, 24) and the payload.
  const std::uint32_t crc = dm::crc32c(payload, dm::crc32c(std::span(*wire).first(24)));
  EXPECT_EQ(u(24) | u(25) << 8 | u(26) << 16 | static_cast<std::uint32_t>(u(27)) << 24, crc);
}

// What must hold: decodeMessage() rejects every message with 1 or 2 flipped
// bits (header or payload). Magic/version/length flips fail those checks; any
// other flip is caught by CRC-32C, whose Hamming distance is ≥ 3 here.
TEST(Message, EverySingleAndDoubleBitFlipIsRejected) {
  std::mt19937 rng(11);
  const Bytes payload = randomBytes(rng, 20);
  auto wire = dm::encodeMessage({.type = 9, .sequence = 77, .timestampNs = 123456789}, payload);
  ASSERT_TRUE(wire.ok());
  const std::size_t bits = wire->size() * 8;
  Bytes w = *wire;
  auto flip = [&](std::size_t b) { w[b / 8] ^= static_cast<std::byte>(1u << (b % 8)); };
  std::size_t accepted = 0;
  for (std::size_t a = 0; a < bits; ++a) {
    flip(a);
    if (dm::decodeMessage(w).ok()) ++accepted;
    for (std::size_t b = a + 1; b < bits; ++b) {
      flip(b);
      if (dm::decodeMessage(w).ok()) ++accepted;
      flip(b);
    }
    flip(a);
  }
  EXPECT_EQ(accepted, 0u);
  EXPECT_TRUE(dm::decodeMessage(w).ok());  // restored
}

TEST(Message, ErrorsNameTheFieldAndOffset) {
  const Bytes payload = ascii("hello");
  auto wire = dm::encodeMessage({.type = 1}, payload);
  ASSERT_TRUE(wire.ok());
  Bytes w = *wire;
  w[0] = std::byte{'X'};
  auto e = dm::decodeMessage(w);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message().find("magic"), std::string::npos);
  EXPECT_NE(e.error().message().find("byte 0"), std::string::npos);

  w = *wire;
  w[4] = std::byte{2};
  e = dm::decodeMessage(w);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().code, dm::ErrorCode::Version);

  w = *wire;
  w[30] ^= std::byte{1};
  e = dm::decodeMessage(w);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message().find("checksum"), std::string::npos);
  EXPECT_NE(e.error().message().find("byte 24"), std::string::npos);

  e = dm::decodeMessage(std::span(*wire).first(wire->size() - 1));
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message().find("byte 12"), std::string::npos);
  e = dm::decodeMessage(std::span(*wire).first(10));
  ASSERT_FALSE(e.ok());
  Bytes longer = *wire;
  longer.push_back(std::byte{0});
  EXPECT_FALSE(dm::decodeMessage(longer).ok());
}

TEST(Message, PayloadLimitIsCheckedOnBothSides) {
  const dm::MessageLimits small{.maxPayloadBytes = 8};
  EXPECT_FALSE(dm::encodeMessage({}, Bytes(9), small).ok());
  auto wire = dm::encodeMessage({}, Bytes(9));
  ASSERT_TRUE(wire.ok());
  auto e = dm::decodeMessage(*wire, small);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().code, dm::ErrorCode::Unsupported);
  EXPECT_NE(e.error().message().find("length"), std::string::npos);
}

TEST(MessageStream, FramesConcatenatedMessagesAtEverySplit) {
  std::mt19937 rng(5);
  std::vector<Bytes> payloads;
  Bytes stream;
  for (std::uint32_t i = 0; i < 6; ++i) {
    payloads.push_back(randomBytes(rng, i * 13));
    ASSERT_TRUE(dm::appendMessage({.type = 1, .sequence = i}, payloads.back(), stream).ok());
  }
  for (std::size_t split = 0; split <= stream.size(); ++split) {
    dm::MessageStreamDecoder dec;
    std::vector<Bytes> got;
    for (auto part : {std::span(stream).first(split), std::span(stream).subspan(split)}) {
      ASSERT_TRUE(dec.feed(part).ok());
      while (true) {
        auto m = dec.next();
        ASSERT_TRUE(m.ok()) << m.error().message();
        if (!*m) break;
        EXPECT_EQ((*m)->header.sequence, got.size());
        got.emplace_back((*m)->payload.begin(), (*m)->payload.end());
      }
    }
    ASSERT_EQ(got, payloads) << split;
    EXPECT_EQ(dec.streamOffset(), stream.size());
  }
}

TEST(MessageStream, RejectsAnOversizeHeaderWithoutWaitingForThePayload) {
  auto wire = dm::encodeMessage({.type = 2}, Bytes(1000));
  ASSERT_TRUE(wire.ok());
  dm::MessageStreamDecoder dec({.maxPayloadBytes = 100});
  ASSERT_TRUE(dec.feed(std::span(*wire).first(dm::kMessageHeaderBytes)).ok());
  auto m = dec.next();
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.error().code, dm::ErrorCode::Unsupported);
  // The failure is sticky until reset().
  ASSERT_TRUE(dec.feed(std::span(*wire).subspan(dm::kMessageHeaderBytes)).ok());
  EXPECT_FALSE(dec.next().ok());
  dec.reset();
  auto ok = dm::encodeMessage({.type = 3}, Bytes(10));
  ASSERT_TRUE(dec.feed(*ok).ok());
  auto m2 = dec.next();
  ASSERT_TRUE(m2.ok() && m2->has_value());
  EXPECT_EQ((*m2)->header.type, 3);
}

TEST(MessageStream, CorruptionInTheStreamIsReportedWithItsStreamOffset) {
  Bytes stream;
  ASSERT_TRUE(dm::appendMessage({.type = 1}, Bytes(10), stream).ok());
  ASSERT_TRUE(dm::appendMessage({.type = 2}, Bytes(10), stream).ok());
  stream[38 + 30] ^= std::byte{0x10};  // payload of the second message
  dm::MessageStreamDecoder dec;
  ASSERT_TRUE(dec.feed(stream).ok());
  auto first = dec.next();
  ASSERT_TRUE(first.ok() && first->has_value());
  auto second = dec.next();
  ASSERT_FALSE(second.ok());
  EXPECT_NE(second.error().message().find("byte 62"), std::string::npos) << second.error().message();
}

TEST(MessageStream, RefusesToBufferWithoutBound) {
  dm::MessageStreamDecoder dec({.maxPayloadBytes = 16});
  const Bytes chunk(1024);
  bool refused = false;
  for (int i = 0; i < 200 && !refused; ++i) refused = !dec.feed(chunk).ok();
  EXPECT_TRUE(refused);
  EXPECT_LE(dec.bufferedBytes(), 2 * (28 + 16) + (64u << 10));
}

TEST(SequenceTracker, ClassifiesInOrderDuplicateGapAndLate) {
  dm::SequenceTracker t;
  EXPECT_EQ(t.observe(10).kind, dm::Arrival::First);
  EXPECT_EQ(t.observe(11).kind, dm::Arrival::InOrder);
  EXPECT_EQ(t.observe(11).kind, dm::Arrival::Duplicate);
  auto g = t.observe(15);
  EXPECT_EQ(g.kind, dm::Arrival::Gap);
  EXPECT_EQ(g.lost, 3u);
  EXPECT_EQ(t.stats().missing, 3u);
  EXPECT_EQ(t.observe(13).kind, dm::Arrival::Late);
  EXPECT_EQ(t.observe(13).kind, dm::Arrival::Duplicate);
  EXPECT_EQ(t.stats().missing, 2u);
  EXPECT_EQ(t.observe(16).kind, dm::Arrival::InOrder);
  EXPECT_EQ(t.observe(10).kind, dm::Arrival::Duplicate);
  EXPECT_EQ(t.highest(), 16u);
  EXPECT_EQ(t.stats().received, 8u);
  EXPECT_EQ(t.stats().duplicates, 3u);
}

TEST(SequenceTracker, WrapsAroundAtTwoToThe32) {
  dm::SequenceTracker t;
  t.observe(0xFFFFFFFEu);
  EXPECT_EQ(t.observe(0xFFFFFFFFu).kind, dm::Arrival::InOrder);
  EXPECT_EQ(t.observe(0u).kind, dm::Arrival::InOrder);
  auto g = t.observe(2u);
  EXPECT_EQ(g.kind, dm::Arrival::Gap);
  EXPECT_EQ(g.lost, 1u);
  EXPECT_EQ(t.observe(1u).kind, dm::Arrival::Late);
  EXPECT_EQ(t.observe(0xFFFFFFFFu).kind, dm::Arrival::Duplicate);
}

TEST(SequenceTracker, WindowForgetsOldNumbersAfterLongJumps) {
  dm::SequenceTracker t;
  t.observe(0);
  t.observe(1);
  // A jump inside the window clears the slots it passes, so a late 5 is new.
  EXPECT_EQ(t.observe(1000).kind, dm::Arrival::Gap);
  EXPECT_EQ(t.observe(5).kind, dm::Arrival::Late);
  EXPECT_EQ(t.observe(1).kind, dm::Arrival::Duplicate);
  // Beyond the window nothing can be said.
  EXPECT_EQ(t.observe(5000).kind, dm::Arrival::Gap);
  EXPECT_EQ(t.observe(1).kind, dm::Arrival::Stale);
  // Slots reused after the jump do not remember the old numbers.
  EXPECT_EQ(t.observe(5000 - 1023).kind, dm::Arrival::Late);
  // Randomised: a permutation of a window-sized block is all Late/InOrder/Gap, once each.
  dm::SequenceTracker r;
  std::vector<std::uint32_t> seq(500);
  for (std::uint32_t i = 0; i < seq.size(); ++i) seq[i] = 100 + i;
  std::mt19937 rng(2);
  std::shuffle(seq.begin() + 1, seq.end(), rng);
  for (auto s : seq) EXPECT_NE(r.observe(s).kind, dm::Arrival::Duplicate);
  for (auto s : seq) EXPECT_EQ(r.observe(s).kind, dm::Arrival::Duplicate);
  EXPECT_EQ(r.stats().missing, 0u);
}

}  // namespace
