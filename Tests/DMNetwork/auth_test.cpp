// Message authentication: HMAC-SHA-256 against the RFC 4231 vectors, and
// the verify rules — tampering, wrong key, missing tag, replay, reordering.
#include <dm/network/auth.hpp>
#include <dm/network/message.hpp>

#include <gtest/gtest.h>

#include <cstring>
#include <string>

namespace {

using Bytes = std::vector<std::byte>;

Bytes fromHex(const std::string& h) {
  Bytes b(h.size() / 2);
  for (std::size_t i = 0; i < b.size(); ++i)
    b[i] = static_cast<std::byte>(std::stoi(h.substr(2 * i, 2), nullptr, 16));
  return b;
}
Bytes ascii(const std::string& s) {
  Bytes b(s.size());
  std::memcpy(b.data(), s.data(), s.size());
  return b;
}
std::string toHex(std::span<const std::byte> b) {
  static const char* d = "0123456789abcdef";
  std::string s;
  for (auto x : b) {
    s += d[static_cast<unsigned>(x) >> 4];
    s += d[static_cast<unsigned>(x) & 15];
  }
  return s;
}

// RFC 4231 section 4: HMAC-SHA-256 results of test cases 1-4, 6, 7 (case 5
// is a truncated output and does not apply).
TEST(AuthHmac, MatchesRfc4231) {
  struct Case {
    Bytes key, data;
    const char* mac;
  };
  const Case cases[] = {
      {Bytes(20, std::byte{0x0b}), ascii("Hi There"),
       "b0344c61d8db38535ca8afceaf0bf12b881dc200c9833da726e9376c2e32cff7"},
      {ascii("Jefe"), ascii("what do ya want for nothing?"),
       "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"},
      {Bytes(20, std::byte{0xaa}), Bytes(50, std::byte{0xdd}),
       "773ea91e36800e46854db8ebd09181a72959098b3ef8c122d9635514ced565fe"},
      {fromHex("0102030405060708090a0b0c0d0e0f10111213141516171819"), Bytes(50, std::byte{0xcd}),
       "82558a389a443c0ea4cc819899f2083a85f0faa3e578f8077a2e3ff46729665b"},
      {Bytes(131, std::byte{0xaa}), ascii("Test Using Larger Than Block-Size Key - Hash Key First"),
       "60e431591ee0b67f0d8a26aacbf5b77f8e0bc6213728c5140546040f0ee37f54"},
      {Bytes(131, std::byte{0xaa}),
       ascii("This is a test using a larger than block-size key and a larger than block-size data. The key "
             "needs to be hashed before being used by the HMAC algorithm."),
       "9b09ffa71b942fcb27635fbcd5b0e944bfdc63644f0713938a7f51535c3a35e2"},
  };
  for (const auto& c : cases) {
    auto tag = dm::hmacSha256(c.key, c.data);
    ASSERT_TRUE(tag.ok());
    EXPECT_EQ(toHex(*tag), c.mac);
  }
}

// The authenticator's tag is the plain HMAC over header bytes [0, 24) and
// the payload — the documented wire layout, checked with the independent
// one-shot function.
TEST(AuthMessage, TagIsHmacOverHeaderPrefixAndPayload) {
  const Bytes key = fromHex("000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f");
  auto auth = dm::MessageAuthenticator::fromKey(key);
  ASSERT_TRUE(auth.ok());
  const Bytes payload = ascii("drill.speed=12000");
  Bytes wire;
  ASSERT_TRUE(
      auth->sign({.type = 9, .flags = 1, .sequence = 77, .timestampNs = 123456789}, payload, wire).ok());
  ASSERT_EQ(wire.size(), dm::kMessageHeaderBytes + payload.size() + dm::kAuthTagBytes);
  EXPECT_EQ(static_cast<unsigned>(wire[5]), 0x81u);  // flag bit added, application bit kept
  Bytes covered(wire.begin(), wire.begin() + 24);
  covered.insert(covered.end(), payload.begin(), payload.end());
  auto expected = dm::hmacSha256(key, covered);
  ASSERT_TRUE(expected.ok());
  EXPECT_EQ(0, std::memcmp(expected->data(), wire.data() + wire.size() - 32, 32));

  auto msg = dm::decodeMessage(wire);
  ASSERT_TRUE(msg.ok());
  dm::SequenceTracker seq;
  std::span<const std::byte> body;
  EXPECT_EQ(auth->verify(*msg, seq, body), dm::AuthVerdict::Accepted);
  ASSERT_EQ(body.size(), payload.size());
  EXPECT_EQ(0, std::memcmp(body.data(), payload.data(), payload.size()));
}

TEST(AuthMessage, RejectsShortAndMalformedKeys) {
  EXPECT_FALSE(dm::MessageAuthenticator::fromKey(Bytes(15, std::byte{1})).ok());
  EXPECT_TRUE(dm::MessageAuthenticator::fromKey(Bytes(16, std::byte{1})).ok());
  EXPECT_FALSE(dm::MessageAuthenticator::fromHex("00112233445566778899aabbccddee").ok());     // 15 bytes
  EXPECT_FALSE(dm::MessageAuthenticator::fromHex("00112233445566778899aabbccddeeff0").ok());  // odd
  auto bad = dm::MessageAuthenticator::fromHex("00112233445566778899aabbccddeeXf");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().where.find("30"), std::string::npos);
  // Hex and raw bytes of the same key sign identically.
  auto a = dm::MessageAuthenticator::fromHex("00112233445566778899AABBCCDDEEFF");
  auto b = dm::MessageAuthenticator::fromKey(fromHex("00112233445566778899aabbccddeeff"));
  ASSERT_TRUE(a.ok() && b.ok());
  Bytes wa, wb;
  ASSERT_TRUE(a->sign({.type = 1}, ascii("x"), wa).ok());
  ASSERT_TRUE(b->sign({.type = 1}, ascii("x"), wb).ok());
  EXPECT_EQ(wa, wb);
}

class AuthVerify : public ::testing::Test {
 protected:
  void SetUp() override {
    auto a = dm::MessageAuthenticator::fromKey(Bytes(32, std::byte{0x5a}));
    ASSERT_TRUE(a.ok());
    auth_.emplace(std::move(a).value());
  }
  Bytes signedMessage(std::uint32_t seq, const std::string& text = "stop") {
    Bytes w;
    EXPECT_TRUE(auth_->sign({.type = 4, .sequence = seq, .timestampNs = 1000 + seq}, ascii(text), w).ok());
    return w;
  }
  // Re-frames tampered bytes with a fresh CRC-32C so that only the tag can catch it.
  static Bytes reframe(const Bytes& w) {
    dm::MessageHeader h;
    h.flags = static_cast<std::uint8_t>(w[5]);
    h.type = static_cast<std::uint16_t>(static_cast<unsigned>(w[6]) | static_cast<unsigned>(w[7]) << 8);
    std::memcpy(&h.sequence, w.data() + 8, 4);
    std::memcpy(&h.timestampNs, w.data() + 16, 8);
    Bytes out;
    EXPECT_TRUE(dm::appendMessage(h, std::span(w).subspan(28), out).ok());
    return out;
  }
  dm::AuthVerdict check(const Bytes& w) {
    auto m = dm::decodeMessage(w);
    EXPECT_TRUE(m.ok());
    if (!m) return dm::AuthVerdict::NoTag;
    std::span<const std::byte> body;
    return auth_->verify(*m, seq_, body);
  }
  std::optional<dm::MessageAuthenticator> auth_;
  dm::SequenceTracker seq_;
};

TEST_F(AuthVerify, EveryTamperedByteIsRefused) {
  const Bytes good = signedMessage(5, "set torque 0.2");
  // Every byte covered by the tag: header [0, 24) except magic/version/length
  // (the codec refuses those before us) and each payload and tag byte.
  for (std::size_t i = 5; i < good.size(); ++i) {
    if ((i >= 12 && i < 16) || (i >= 24 && i < 28)) continue;
    Bytes bad = good;
    bad[i] ^= std::byte{0x01};
    if (i == 5) bad[i] ^= std::byte{0x02};  // keep the flag bit: flip another flags bit
    EXPECT_EQ(check(reframe(bad)), dm::AuthVerdict::BadTag) << "byte " << i;
  }
  EXPECT_EQ(seq_.stats().received, 0u);  // forged messages never reach the tracker
  EXPECT_EQ(check(good), dm::AuthVerdict::Accepted);
}

TEST_F(AuthVerify, ClearedFlagOrMissingTagIsNoTag) {
  Bytes w = signedMessage(1);
  w[5] = std::byte{0};
  EXPECT_EQ(check(reframe(w)), dm::AuthVerdict::NoTag);
  Bytes plain;
  ASSERT_TRUE(dm::appendMessage({.type = 4, .flags = dm::kMessageFlagAuthenticated, .sequence = 2},
                                ascii("short"), plain)
                  .ok());
  EXPECT_EQ(check(plain), dm::AuthVerdict::NoTag);
}

TEST_F(AuthVerify, WrongKeyIsRefused) {
  auto other = dm::MessageAuthenticator::fromKey(Bytes(32, std::byte{0x5b}));
  ASSERT_TRUE(other.ok());
  Bytes w;
  ASSERT_TRUE(other->sign({.type = 4, .sequence = 1}, ascii("stop"), w).ok());
  EXPECT_EQ(check(w), dm::AuthVerdict::BadTag);
}

TEST_F(AuthVerify, ReplayRefusedReorderingWithinWindowAccepted) {
  const Bytes m10 = signedMessage(10), m11 = signedMessage(11), m13 = signedMessage(13),
              m12 = signedMessage(12);
  EXPECT_EQ(check(m10), dm::AuthVerdict::Accepted);
  EXPECT_EQ(check(m11), dm::AuthVerdict::Accepted);
  EXPECT_EQ(check(m11), dm::AuthVerdict::Replayed);
  EXPECT_EQ(check(m13), dm::AuthVerdict::Accepted);  // gap
  EXPECT_EQ(check(m12), dm::AuthVerdict::Accepted);  // late, never seen: accepted
  EXPECT_EQ(check(m12), dm::AuthVerdict::Replayed);
  EXPECT_EQ(check(m10), dm::AuthVerdict::Replayed);
  const Bytes far = signedMessage(13 + dm::SequenceTracker::kWindow + 5);
  EXPECT_EQ(check(far), dm::AuthVerdict::Accepted);
  EXPECT_EQ(check(signedMessage(14)), dm::AuthVerdict::Stale);  // too far behind to tell
}

TEST_F(AuthVerify, SignRespectsLimit) {
  Bytes w;
  const dm::MessageLimits limits{.maxPayloadBytes = 40};
  EXPECT_TRUE(auth_->sign({.type = 1}, Bytes(8), w, limits).ok());
  EXPECT_FALSE(auth_->sign({.type = 1}, Bytes(9), w, limits).ok());
}

}  // namespace
