// HMAC-SHA-256 message authentication on libcrypto (private dependency).
#include <dm/network/auth.hpp>

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>

#include <algorithm>
#include <climits>
#include <cstring>

namespace dm {

namespace {

int hexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

}  // namespace

const char* toString(AuthVerdict v) noexcept {
  switch (v) {
    case AuthVerdict::Accepted:
      return "accepted";
    case AuthVerdict::NoTag:
      return "no tag";
    case AuthVerdict::BadTag:
      return "bad tag";
    case AuthVerdict::Replayed:
      return "replayed";
    case AuthVerdict::Stale:
      return "stale";
  }
  return "?";
}

Result<AuthTag> hmacSha256(std::span<const std::byte> key, std::span<const std::byte> data) {
  if (key.size() > static_cast<std::size_t>(INT_MAX))
    return fail(ErrorCode::InvalidArgument, formatString("key of %zu bytes is too long", key.size()),
                "hmacSha256", "use a key of at most 2 GiB");
  AuthTag tag{};
  unsigned int len = 0;
  static const unsigned char kEmpty = 0;
  const auto* k = key.empty() ? &kEmpty : reinterpret_cast<const unsigned char*>(key.data());
  const auto* d = data.empty() ? &kEmpty : reinterpret_cast<const unsigned char*>(data.data());
  if (HMAC(EVP_sha256(), k, static_cast<int>(key.size()), d, data.size(),
           reinterpret_cast<unsigned char*>(tag.data()), &len) == nullptr ||
      len != kAuthTagBytes)
    return fail(ErrorCode::Internal, "libcrypto HMAC-SHA-256 failed", "hmacSha256",
                "check the OpenSSL install");
  return tag;
}

// HMAC-SHA-256 from two digest passes over the pre-padded key blocks
// (RFC 2104) with one fetched digest and one reusable digest context. Our
// code allocates nothing per tag; OpenSSL 3.0 itself re-creates the
// provider's SHA-256 state on each EVP_DigestInit_ex2 (two small mallocs per
// tag, measured with CRYPTO_set_mem_functions), no locks.
struct MessageAuthenticator::Impl {
  EVP_MD* md = nullptr;
  EVP_MD_CTX* ctx = nullptr;
  std::array<unsigned char, 64> ipad{}, opad{};
  ~Impl() {
    OPENSSL_cleanse(ipad.data(), ipad.size());
    OPENSSL_cleanse(opad.data(), opad.size());
    EVP_MD_CTX_free(ctx);
    EVP_MD_free(md);
  }
};

MessageAuthenticator::MessageAuthenticator(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
MessageAuthenticator::MessageAuthenticator(MessageAuthenticator&&) noexcept = default;
MessageAuthenticator& MessageAuthenticator::operator=(MessageAuthenticator&&) noexcept = default;
MessageAuthenticator::~MessageAuthenticator() = default;

Result<MessageAuthenticator> MessageAuthenticator::fromKey(std::span<const std::byte> key) {
  if (key.size() < kAuthMinKeyBytes)
    return fail(
        ErrorCode::InvalidArgument,
        formatString("key of %zu bytes is shorter than the %zu-byte minimum", key.size(), kAuthMinKeyBytes),
        "MessageAuthenticator key",
        "use a random key of at least 16 bytes (32 hex digits); 32 bytes is best");
  auto impl = std::make_unique<Impl>();
  impl->md = EVP_MD_fetch(nullptr, "SHA256", nullptr);
  if (impl->md != nullptr) impl->ctx = EVP_MD_CTX_new();
  std::array<unsigned char, 64> block{};
  bool okay = impl->ctx != nullptr;
  if (okay && key.size() > block.size()) {
    unsigned int n = 0;
    okay = EVP_Digest(key.data(), key.size(), block.data(), &n, impl->md, nullptr) == 1;
  } else if (okay) {
    std::memcpy(block.data(), key.data(), key.size());
  }
  for (std::size_t i = 0; i < block.size(); ++i) {
    impl->ipad[i] = static_cast<unsigned char>(block[i] ^ 0x36u);
    impl->opad[i] = static_cast<unsigned char>(block[i] ^ 0x5cu);
  }
  OPENSSL_cleanse(block.data(), block.size());
  if (!okay)
    return fail(ErrorCode::Internal, "libcrypto could not set up SHA-256", "MessageAuthenticator",
                "check the OpenSSL install (the default provider must be available)");
  return MessageAuthenticator(std::move(impl));
}

Result<std::vector<std::byte>> parseHexKey(std::string_view hex) {
  if (hex.size() % 2 != 0 || hex.size() < 2 * kAuthMinKeyBytes)
    return fail(ErrorCode::InvalidArgument,
                formatString("hex key has %zu digits; need an even number, at least %zu", hex.size(),
                             2 * kAuthMinKeyBytes),
                "MessageAuthenticator hex key",
                "write the key as 32 or more hex digits, e.g. `openssl rand -hex 32`");
  std::vector<std::byte> key(hex.size() / 2);
  for (std::size_t i = 0; i < hex.size(); ++i) {
    const int v = hexValue(hex[i]);
    if (v < 0) {
      OPENSSL_cleanse(key.data(), key.size());
      return fail(ErrorCode::InvalidArgument, "hex key has a character that is not a hex digit",
                  formatString("hex key offset %zu", i), "use only 0-9, a-f, A-F");
    }
    key[i / 2] = static_cast<std::byte>(static_cast<unsigned>(key[i / 2]) |
                                        (static_cast<unsigned>(v) << (i % 2 == 0 ? 4 : 0)));
  }
  return key;
}

Result<MessageAuthenticator> MessageAuthenticator::fromHex(std::string_view hex) {
  auto key = parseHexKey(hex);
  if (!key) return key.error();
  auto r = fromKey(*key);
  OPENSSL_cleanse(key->data(), key->size());
  return r;
}

bool MessageAuthenticator::computeTag(const MessageHeader& header, std::uint32_t lengthField,
                                      std::span<const std::byte> payload, AuthTag& out) noexcept {
  const auto prefix = messageHeaderPrefix(header, lengthField);
  EVP_MD_CTX* c = impl_->ctx;
  std::array<unsigned char, kAuthTagBytes> inner{};
  unsigned int n = 0;
  bool good = EVP_DigestInit_ex2(c, impl_->md, nullptr) == 1 &&
              EVP_DigestUpdate(c, impl_->ipad.data(), impl_->ipad.size()) == 1 &&
              EVP_DigestUpdate(c, prefix.data(), prefix.size()) == 1 &&
              (payload.empty() || EVP_DigestUpdate(c, payload.data(), payload.size()) == 1) &&
              EVP_DigestFinal_ex(c, inner.data(), &n) == 1 && n == kAuthTagBytes;
  good = good && EVP_DigestInit_ex2(c, impl_->md, nullptr) == 1 &&
         EVP_DigestUpdate(c, impl_->opad.data(), impl_->opad.size()) == 1 &&
         EVP_DigestUpdate(c, inner.data(), inner.size()) == 1 &&
         EVP_DigestFinal_ex(c, reinterpret_cast<unsigned char*>(out.data()), &n) == 1 && n == kAuthTagBytes;
  return good;
}

Status MessageAuthenticator::sign(const MessageHeader& header, std::span<const std::byte> payload,
                                  std::vector<std::byte>& out, const MessageLimits& limits) {
  const std::size_t limit = std::min<std::size_t>(limits.maxPayloadBytes, 0xFFFFFFFFu);
  if (payload.size() > limit || limit - payload.size() < kAuthTagBytes)
    return fail(ErrorCode::InvalidArgument,
                formatString("payload of %zu bytes plus the %zu-byte tag exceeds the limit of %zu",
                             payload.size(), kAuthTagBytes, limit),
                "MessageAuthenticator::sign", "split the command or raise MessageLimits::maxPayloadBytes");
  MessageHeader h = header;
  h.flags = static_cast<std::uint8_t>(h.flags | kMessageFlagAuthenticated);
  std::vector<std::byte> body(payload.size() + kAuthTagBytes);
  if (!payload.empty()) std::memcpy(body.data(), payload.data(), payload.size());
  AuthTag tag{};
  if (!computeTag(h, static_cast<std::uint32_t>(body.size()), payload, tag))
    return fail(ErrorCode::Internal, "libcrypto HMAC-SHA-256 failed", "MessageAuthenticator::sign",
                "check the OpenSSL install");
  std::memcpy(body.data() + payload.size(), tag.data(), tag.size());
  return appendMessage(h, body, out, limits);
}

bool MessageAuthenticator::tagValid(const MessageView& message) noexcept {
  if ((message.header.flags & kMessageFlagAuthenticated) == 0 || message.payload.size() < kAuthTagBytes ||
      message.payload.size() > 0xFFFFFFFFu)
    return false;
  const auto body = message.payload.first(message.payload.size() - kAuthTagBytes);
  const auto received = message.payload.last(kAuthTagBytes);
  AuthTag expected{};
  if (!computeTag(message.header, static_cast<std::uint32_t>(message.payload.size()), body, expected))
    return false;
  return CRYPTO_memcmp(expected.data(), received.data(), kAuthTagBytes) == 0;
}

AuthVerdict MessageAuthenticator::verify(const MessageView& message, SequenceTracker& tracker,
                                         std::span<const std::byte>& payload) noexcept {
  if ((message.header.flags & kMessageFlagAuthenticated) == 0 || message.payload.size() < kAuthTagBytes)
    return AuthVerdict::NoTag;
  if (!tagValid(message)) return AuthVerdict::BadTag;
  switch (tracker.observe(message.header.sequence).kind) {
    case Arrival::Duplicate:
      return AuthVerdict::Replayed;
    case Arrival::Stale:
      return AuthVerdict::Stale;
    default:
      break;
  }
  payload = message.payload.first(message.payload.size() - kAuthTagBytes);
  return AuthVerdict::Accepted;
}

}  // namespace dm
