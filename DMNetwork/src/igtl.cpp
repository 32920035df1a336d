// OpenIGTLink codec: header (v1-v3, extended header, metadata), TRANSFORM,
// POSITION, STATUS, STRING, COMMAND, POINT, SENSOR and the GET_/STT_/STP_/RTS_
// queries. IMAGE and POLYDATA live in igtl_image.cpp and igtl_polydata.cpp.
#include <dm/network/crc.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>

#include "igtl_wire.hpp"

namespace dm::igtl {

using namespace wire;

namespace {

constexpr std::size_t kStatusHeaderBytes = 30;
constexpr std::size_t kSensorHeaderBytes = 10;  // length, status, unit
constexpr std::size_t kStringHeaderBytes = 4;
constexpr std::size_t kCommandHeaderBytes = 4 + 128 + 2 + 4;
constexpr std::size_t kPointBytes = 136;
constexpr std::size_t kSttTdataBytes = 36;

std::string headerWhere(std::size_t offset) { return formatString("OpenIGTLink header, byte %zu", offset); }

}  // namespace

namespace wire {

std::string where(const MessageView& m, std::size_t contentOffset) {
  return formatString("OpenIGTLink %s message \"%s\", byte %zu", m.header.type.c_str(),
                      m.header.deviceName.c_str(), m.contentOffset + contentOffset);
}

Error bad(const MessageView& m, std::size_t contentOffset, ErrorCode code, std::string what,
          std::string hint) {
  return fail(code, std::move(what), where(m, contentOffset), std::move(hint));
}

Status expectType(const MessageView& m, std::string_view type) {
  if (m.header.type == type) return ok();
  return bad(m, 0, ErrorCode::InvalidArgument,
             formatString("message type is \"%s\", expected \"%.*s\"", m.header.type.c_str(),
                          static_cast<int>(type.size()), type.data()),
             "dispatch on MessageView::header.type before decoding the content");
}

std::string fixedString(const std::byte* p, std::size_t n) {
  const auto* c = reinterpret_cast<const char*>(p);
  return std::string(c, strnlen(c, n));
}

Status putFixedString(std::vector<std::byte>& out, std::string_view s, std::size_t n, const char* field) {
  if (s.size() > n)
    return fail(ErrorCode::InvalidArgument,
                formatString("%s \"%.*s\" has %zu characters, the field holds %zu", field,
                             static_cast<int>(s.size()), s.data(), s.size(), n),
                "OpenIGTLink encoder", "shorten it");
  const std::size_t start = out.size();
  out.resize(start + n, std::byte{0});
  std::memcpy(out.data() + start, s.data(), s.size());
  return ok();
}

}  // namespace wire

std::uint64_t timestampFromNanos(std::int64_t ns) noexcept {
  if (ns <= 0) return 0;
  const auto sec = static_cast<std::uint64_t>(ns / 1'000'000'000);
  const auto rem = static_cast<std::uint64_t>(ns % 1'000'000'000);
  std::uint64_t frac = ((rem << 32) + 500'000'000) / 1'000'000'000;
  std::uint64_t s = sec;
  if (frac > 0xFFFFFFFFull) {
    frac = 0;
    ++s;
  }
  return ((s & 0xFFFFFFFFull) << 32) | frac;
}

std::int64_t timestampToNanos(std::uint64_t stamp) noexcept {
  const std::uint64_t sec = stamp >> 32;
  const std::uint64_t frac = stamp & 0xFFFFFFFFull;
  return static_cast<std::int64_t>(sec * 1'000'000'000 + ((frac * 1'000'000'000 + (1ull << 31)) >> 32));
}

Result<Header> decodeHeader(std::span<const std::byte> bytes, const DecodeOptions& options) {
  if (bytes.size() < kHeaderBytes)
    return fail(ErrorCode::Parse,
                formatString("%zu bytes is shorter than the 58-byte OpenIGTLink header", bytes.size()),
                headerWhere(bytes.size()), "wait for the whole header before decoding");
  Header h;
  const std::byte* p = bytes.data();
  h.version = getBe16(p);
  h.type = fixedString(p + 2, kTypeNameBytes);
  h.deviceName = fixedString(p + 14, kDeviceNameBytes);
  h.timestamp = getBe64(p + 34);
  h.bodySize = getBe64(p + 42);
  h.crc = getBe64(p + 50);
  if (h.version < 1 || h.version > 3)
    return fail(ErrorCode::Version,
                formatString("header version is %u, this codec reads 1, 2 and 3", h.version), headerWhere(0),
                "the peer is not OpenIGTLink or the stream is out of sync");
  if (h.type.empty())
    return fail(ErrorCode::Parse, "message type name is empty", headerWhere(2),
                "the peer is not OpenIGTLink or the stream is out of sync");
  if (h.bodySize > options.maxBodyBytes)
    return fail(ErrorCode::Unsupported,
                formatString("%s message body size is %llu bytes, the limit is %zu", h.type.c_str(),
                             static_cast<unsigned long long>(h.bodySize), options.maxBodyBytes),
                headerWhere(42), "raise DecodeOptions::maxBodyBytes if the peer legitimately sends more");
  return h;
}

Result<MessageView> decodeMessage(std::span<const std::byte> bytes, const DecodeOptions& options) {
  auto header = decodeHeader(bytes, options);
  if (!header) return std::move(header).error();
  MessageView m;
  m.header = std::move(*header);
  const Header& h = m.header;
  const std::size_t body = static_cast<std::size_t>(h.bodySize);
  if (bytes.size() - kHeaderBytes != body)
    return fail(ErrorCode::Parse,
                formatString("%s message: body size field says %zu bytes, %zu follow the header",
                             h.type.c_str(), body, bytes.size() - kHeaderBytes),
                headerWhere(42), "pass exactly one whole message (header + body size bytes)");
  const auto bodyBytes = bytes.subspan(kHeaderBytes);
  if (options.verifyCrc) {
    const std::uint64_t crc = crc64Ecma(bodyBytes);
    if (crc != h.crc)
      return fail(
          ErrorCode::Parse,
          formatString("%s message: CRC field is 0x%016llX, the CRC-64 of the %zu-byte body is 0x%016llX",
                       h.type.c_str(), static_cast<unsigned long long>(h.crc), body,
                       static_cast<unsigned long long>(crc)),
          headerWhere(50), "the message was corrupted; drop it (DecodeOptions::verifyCrc skips the check)");
  }
  m.content = bodyBytes;
  m.contentOffset = kHeaderBytes;
  if (h.version < 2) return m;

  auto extWhere = [&](std::size_t off) { return headerWhere(kHeaderBytes + off); };
  if (body < kExtendedHeaderBytes)
    return fail(
        ErrorCode::Parse,
        formatString("version %u %s message: body of %zu bytes cannot hold the 12-byte extended header",
                     h.version, h.type.c_str(), body),
        extWhere(0), "a version 1 peer must send version 1 headers");
  const std::byte* e = bodyBytes.data();
  const std::size_t extSize = getBe16(e);
  const std::size_t metaHeaderSize = getBe16(e + 2);
  const std::size_t metaSize = getBe32(e + 4);
  m.messageId = getBe32(e + 8);
  if (extSize < kExtendedHeaderBytes || extSize > body)
    return fail(ErrorCode::Parse,
                formatString("%s message: extended header size is %zu, must be 12..%zu", h.type.c_str(),
                             extSize, body),
                extWhere(0));
  if (extSize + metaHeaderSize + metaSize > body)
    return fail(
        ErrorCode::Parse,
        formatString("%s message: extended header (%zu) + metadata header (%zu) + metadata (%zu) bytes "
                     "exceed the %zu-byte body",
                     h.type.c_str(), extSize, metaHeaderSize, metaSize, body),
        extWhere(2));
  const std::size_t contentSize = body - extSize - metaHeaderSize - metaSize;
  m.content = bodyBytes.subspan(extSize, contentSize);
  m.contentOffset = kHeaderBytes + extSize;
  if (metaHeaderSize == 0) {
    if (metaSize != 0)
      return fail(
          ErrorCode::Parse,
          formatString("%s message: %zu metadata bytes without a metadata header", h.type.c_str(), metaSize),
          extWhere(4));
    return m;
  }
  const std::size_t mhOff = extSize + contentSize;
  const std::byte* mh = bodyBytes.data() + mhOff;
  if (metaHeaderSize < 2)
    return fail(
        ErrorCode::Parse,
        formatString("%s message: metadata header size %zu is below 2", h.type.c_str(), metaHeaderSize),
        extWhere(2));
  const std::size_t count = getBe16(mh);
  if (metaHeaderSize != 2 + 8 * count)
    return fail(ErrorCode::Parse,
                formatString("%s message: %zu metadata entries need a %zu-byte metadata header, the extended "
                             "header says %zu",
                             h.type.c_str(), count, 2 + 8 * count, metaHeaderSize),
                extWhere(mhOff));
  std::size_t total = 0;
  for (std::size_t i = 0; i < count; ++i)
    total += getBe16(mh + 2 + 8 * i) + std::size_t{getBe32(mh + 2 + 8 * i + 4)};
  if (total != metaSize)
    return fail(ErrorCode::Parse,
                formatString("%s message: metadata keys and values add up to %zu bytes, the extended header "
                             "says %zu",
                             h.type.c_str(), total, metaSize),
                extWhere(mhOff));
  m.metadata.reserve(count);
  const std::byte* d = mh + metaHeaderSize;
  for (std::size_t i = 0; i < count; ++i) {
    const std::byte* entry = mh + 2 + 8 * i;
    const std::size_t ks = getBe16(entry), vs = getBe32(entry + 4);
    MetadataEntry me;
    me.key.assign(reinterpret_cast<const char*>(d), ks);
    me.encoding = getBe16(entry + 2);
    me.value.assign(reinterpret_cast<const char*>(d + ks), vs);
    d += ks + vs;
    m.metadata.push_back(std::move(me));
  }
  return m;
}

Result<std::vector<std::byte>> encodeRaw(const Envelope& env, std::string_view type,
                                         std::span<const std::byte> content) {
  std::vector<std::byte> out;
  if (auto s = appendRaw(env, type, content, out); !s) return std::move(s).error();
  return out;
}

Status appendRaw(const Envelope& env, std::string_view type, std::span<const std::byte> content,
                 std::vector<std::byte>& out) {
  if (env.version < 1 || env.version > 3)
    return fail(ErrorCode::InvalidArgument,
                formatString("header version %u; OpenIGTLink has 1, 2 and 3", env.version),
                "OpenIGTLink encoder", "use 1 for v1/v2 peers, 2 or 3 for metadata");
  if (type.empty())
    return fail(ErrorCode::InvalidArgument, "empty message type", "OpenIGTLink encoder", "name the type");
  const std::size_t start = out.size();
  std::size_t metaBytes = 0;
  if (env.version >= 2) {
    if (env.metadata.size() > 0xFFFF)
      return fail(ErrorCode::InvalidArgument,
                  formatString("%zu metadata entries, at most 65535", env.metadata.size()),
                  "OpenIGTLink encoder");
    for (const auto& e : env.metadata) {
      if (e.key.size() > 0xFFFF || e.value.size() > 0xFFFFFFFFull)
        return fail(ErrorCode::InvalidArgument,
                    formatString("metadata key of %zu bytes (max 65535)", e.key.size()),
                    "OpenIGTLink encoder", "shorten the key or the value");
      metaBytes += e.key.size() + e.value.size();
    }
    if (metaBytes > 0xFFFFFFFFull)
      return fail(ErrorCode::InvalidArgument, "metadata exceeds 4 GiB", "OpenIGTLink encoder");
  } else if (!env.metadata.empty() || env.messageId != 0) {
    return fail(ErrorCode::InvalidArgument, "metadata and message id need header version 2 or 3",
                "OpenIGTLink encoder", "set Envelope::version = 2");
  }
  const std::size_t metaHeader = env.version >= 2 ? 2 + 8 * env.metadata.size() : 0;
  const std::size_t body =
      (env.version >= 2 ? kExtendedHeaderBytes : 0) + content.size() + metaHeader + metaBytes;
  out.reserve(start + kHeaderBytes + body);
  putBe16(out, env.version);
  if (auto s = putFixedString(out, type, kTypeNameBytes, "message type"); !s) {
    out.resize(start);
    return s;
  }
  if (auto s = putFixedString(out, env.deviceName, kDeviceNameBytes, "device name"); !s) {
    out.resize(start);
    return s;
  }
  putBe64(out, env.timestamp);
  putBe64(out, body);
  putBe64(out, 0);  // CRC, filled below
  if (env.version >= 2) {
    putBe16(out, kExtendedHeaderBytes);
    putBe16(out, static_cast<std::uint16_t>(metaHeader));
    putBe32(out, static_cast<std::uint32_t>(metaBytes));
    putBe32(out, env.messageId);
  }
  out.insert(out.end(), content.begin(), content.end());
  if (env.version >= 2) {
    putBe16(out, static_cast<std::uint16_t>(env.metadata.size()));
    for (const auto& e : env.metadata) {
      putBe16(out, static_cast<std::uint16_t>(e.key.size()));
      putBe16(out, e.encoding);
      putBe32(out, static_cast<std::uint32_t>(e.value.size()));
    }
    for (const auto& e : env.metadata) {
      putBytes(out, e.key);
      putBytes(out, e.value);
    }
  }
  const std::uint64_t crc = crc64Ecma(std::span<const std::byte>(out).subspan(start + kHeaderBytes));
  for (int i = 0; i < 8; ++i)
    out[start + 50 + static_cast<std::size_t>(i)] = static_cast<std::byte>((crc >> (56 - 8 * i)) & 0xFF);
  return ok();
}

// ---- TRANSFORM ------------------------------------------------------------

Result<Affine3> decodeTransformAffine(const MessageView& m) {
  if (auto s = expectType(m, "TRANSFORM"); !s) return std::move(s).error();
  if (m.content.size() != 48)
    return bad(m, 0, ErrorCode::Parse,
               formatString("TRANSFORM content is %zu bytes, must be 48 (12 float32)", m.content.size()));
  Affine3 a = Affine3::Identity();
  const std::byte* p = m.content.data();
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r) a.linear()(r, c) = getF32(p + 4 * static_cast<std::size_t>(3 * c + r));
  for (int r = 0; r < 3; ++r)
    a.translation()(r) = getF32(p + 36 + 4 * static_cast<std::size_t>(r)) * kMetresPerMm;
  for (int i = 0; i < 12; ++i)
    if (!std::isfinite(getF32(p + 4 * static_cast<std::size_t>(i))))
      return bad(m, 4 * static_cast<std::size_t>(i), ErrorCode::Parse,
                 formatString("matrix element %d is not finite", i), "the sender's tracker lost the tool?");
  return a;
}

Result<Isometry3> decodeTransform(const MessageView& m) {
  auto a = decodeTransformAffine(m);
  if (!a) return std::move(a).error();
  const Mat3 r = a->linear();
  const double err = (r.transpose() * r - Mat3::Identity()).cwiseAbs().maxCoeff();
  if (err > 1e-4 || r.determinant() < 0)
    return bad(
        m, 0, ErrorCode::Parse,
        formatString("the 3x3 part is not a rotation (|RᵀR − I| = %.3g, det = %.4f)", err, r.determinant()),
        "use decodeTransformAffine() for scaled or sheared transforms");
  Isometry3 iso = Isometry3::Identity();
  iso.linear() = r;
  iso.translation() = a->translation();
  return iso;
}

Status appendTransform(const Envelope& env, const Affine3& transform, std::vector<std::byte>& out) {
  std::array<std::byte, 48> c;
  auto put = [&c](std::size_t at, double v) {
    const auto bits = std::bit_cast<std::uint32_t>(static_cast<float>(v));
    for (std::size_t i = 0; i < 4; ++i) c[at + i] = static_cast<std::byte>((bits >> (24 - 8 * i)) & 0xFFu);
  };
  for (int col = 0; col < 3; ++col)
    for (int r = 0; r < 3; ++r) put(static_cast<std::size_t>(12 * col + 4 * r), transform.linear()(r, col));
  for (int r = 0; r < 3; ++r)
    put(static_cast<std::size_t>(36 + 4 * r), transform.translation()(r) * kMmPerMetre);
  return appendRaw(env, "TRANSFORM", c, out);
}

Result<std::vector<std::byte>> encodeTransform(const Envelope& env, const Affine3& transform) {
  std::vector<std::byte> out;
  if (auto s = appendTransform(env, transform, out); !s) return std::move(s).error();
  return out;
}

Result<std::vector<std::byte>> encodeTransform(const Envelope& env, const Isometry3& transform) {
  return encodeTransform(env, Affine3(transform.matrix()));
}

// ---- POSITION -------------------------------------------------------------

Result<Pose> decodePosition(const MessageView& m) {
  if (auto s = expectType(m, "POSITION"); !s) return std::move(s).error();
  const std::size_t n = m.content.size();
  if (n != 12 && n != 24 && n != 28)
    return bad(m, 0, ErrorCode::Parse,
               formatString("POSITION content is %zu bytes, must be 12, 24 or 28", n));
  const std::byte* p = m.content.data();
  Vec3 pos(getF32(p), getF32(p + 4), getF32(p + 8));
  if (!pos.allFinite()) return bad(m, 0, ErrorCode::Parse, "position is not finite");
  Quat q = Quat::Identity();
  if (n >= 24) {
    const double x = getF32(p + 12), y = getF32(p + 16), z = getF32(p + 20);
    double w;
    if (n == 28) {
      w = getF32(p + 24);
    } else {
      w = std::sqrt(std::max(0.0, 1.0 - (x * x + y * y + z * z)));
    }
    q = Quat(w, x, y, z);
    const double norm = q.norm();
    if (!std::isfinite(norm) || norm < 1e-6)
      return bad(m, 12, ErrorCode::Parse,
                 formatString("quaternion has norm %g; it must be a unit quaternion", norm));
  }
  return Pose(pos * kMetresPerMm, q);
}

Result<std::vector<std::byte>> encodePosition(const Envelope& env, const Pose& pose) {
  std::vector<std::byte> c;
  c.reserve(28);
  for (int i = 0; i < 3; ++i) putF32(c, pose.p(i) * kMmPerMetre);
  putF32(c, pose.q.x());
  putF32(c, pose.q.y());
  putF32(c, pose.q.z());
  putF32(c, pose.q.w());
  return encodeRaw(env, "POSITION", c);
}

// ---- STATUS ---------------------------------------------------------------

Result<StatusInfo> decodeStatus(const MessageView& m) {
  if (auto s = expectType(m, "STATUS"); !s) return std::move(s).error();
  if (m.content.size() < kStatusHeaderBytes)
    return bad(m, 0, ErrorCode::Parse,
               formatString("STATUS content is %zu bytes, the fixed part needs 30", m.content.size()));
  const std::byte* p = m.content.data();
  StatusInfo s;
  s.code = getBe16(p);
  s.subcode = static_cast<std::int64_t>(getBe64(p + 2));
  s.errorName = fixedString(p + 10, 20);
  s.message = fixedString(p + kStatusHeaderBytes, m.content.size() - kStatusHeaderBytes);
  return s;
}

Result<std::vector<std::byte>> encodeStatus(const Envelope& env, const StatusInfo& s) {
  if (s.message.find('\0') != std::string::npos)
    return fail(ErrorCode::InvalidArgument, "STATUS message contains a NUL", "OpenIGTLink encoder",
                "the wire format ends the message at the first NUL");
  std::vector<std::byte> c;
  c.reserve(kStatusHeaderBytes + s.message.size() + 1);
  putBe16(c, s.code);
  putBe64(c, static_cast<std::uint64_t>(s.subcode));
  if (auto st = putFixedString(c, s.errorName, 20, "STATUS error name"); !st) return std::move(st).error();
  putBytes(c, s.message);
  c.push_back(std::byte{0});
  return encodeRaw(env, "STATUS", c);
}

// ---- STRING ---------------------------------------------------------------

Result<StringInfo> decodeString(const MessageView& m) {
  if (auto s = expectType(m, "STRING"); !s) return std::move(s).error();
  if (m.content.size() < kStringHeaderBytes)
    return bad(m, 0, ErrorCode::Parse,
               formatString("STRING content is %zu bytes, the header needs 4", m.content.size()));
  const std::byte* p = m.content.data();
  StringInfo s;
  s.encoding = getBe16(p);
  const std::size_t len = getBe16(p + 2);
  if (len > m.content.size() - kStringHeaderBytes)
    return bad(m, 2, ErrorCode::Parse,
               formatString("STRING length field says %zu bytes, %zu follow", len,
                            m.content.size() - kStringHeaderBytes));
  s.text.assign(reinterpret_cast<const char*>(p + kStringHeaderBytes), len);
  return s;
}

Result<std::vector<std::byte>> encodeString(const Envelope& env, const StringInfo& s) {
  if (s.text.size() > 0xFFFF)
    return fail(ErrorCode::InvalidArgument, formatString("STRING of %zu bytes, at most 65535", s.text.size()),
                "OpenIGTLink encoder", "split the text");
  std::vector<std::byte> c;
  c.reserve(kStringHeaderBytes + s.text.size());
  putBe16(c, s.encoding);
  putBe16(c, static_cast<std::uint16_t>(s.text.size()));
  putBytes(c, s.text);
  return encodeRaw(env, "STRING", c);
}

// ---- COMMAND --------------------------------------------------------------

Result<CommandInfo> decodeCommand(const MessageView& m) {
  if (m.header.type != "COMMAND" && m.header.type != "RTS_COMMAND")
    return bad(
        m, 0, ErrorCode::InvalidArgument,
        formatString("message type is \"%s\", expected COMMAND or RTS_COMMAND", m.header.type.c_str()));
  if (m.content.size() < kCommandHeaderBytes)
    return bad(m, 0, ErrorCode::Parse,
               formatString("%s content is %zu bytes, the fixed part needs 138", m.header.type.c_str(),
                            m.content.size()));
  const std::byte* p = m.content.data();
  CommandInfo c;
  c.id = getBe32(p);
  c.name = fixedString(p + 4, 128);
  c.encoding = getBe16(p + 132);
  const std::size_t len = getBe32(p + 134);
  if (len > m.content.size() - kCommandHeaderBytes)
    return bad(m, 134, ErrorCode::Parse,
               formatString("command length field says %zu bytes, %zu follow", len,
                            m.content.size() - kCommandHeaderBytes));
  c.content.assign(reinterpret_cast<const char*>(p + kCommandHeaderBytes), len);
  return c;
}

Result<std::vector<std::byte>> encodeCommand(const Envelope& env, const CommandInfo& c,
                                             std::string_view type) {
  if (type != "COMMAND" && type != "RTS_COMMAND")
    return fail(ErrorCode::InvalidArgument,
                formatString("type \"%.*s\"; a command is COMMAND or RTS_COMMAND",
                             static_cast<int>(type.size()), type.data()),
                "OpenIGTLink encoder");
  if (c.content.size() > 0xFFFFFFFFull)
    return fail(ErrorCode::InvalidArgument, "command content exceeds 4 GiB", "OpenIGTLink encoder");
  std::vector<std::byte> b;
  b.reserve(kCommandHeaderBytes + c.content.size());
  putBe32(b, c.id);
  if (auto s = putFixedString(b, c.name, 128, "command name"); !s) return std::move(s).error();
  putBe16(b, c.encoding);
  putBe32(b, static_cast<std::uint32_t>(c.content.size()));
  putBytes(b, c.content);
  return encodeRaw(env, type, b);
}

// ---- POINT ----------------------------------------------------------------

Result<std::vector<Point>> decodePoints(const MessageView& m) {
  if (auto s = expectType(m, "POINT"); !s) return std::move(s).error();
  if (m.content.size() % kPointBytes != 0)
    return bad(
        m, m.content.size() - m.content.size() % kPointBytes, ErrorCode::Parse,
        formatString("POINT content is %zu bytes, not a multiple of the 136-byte element", m.content.size()));
  const std::size_t n = m.content.size() / kPointBytes;
  std::vector<Point> pts;
  pts.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::byte* p = m.content.data() + i * kPointBytes;
    Point pt;
    pt.name = fixedString(p, 64);
    pt.group = fixedString(p + 64, 32);
    for (int k = 0; k < 4; ++k)
      pt.rgba[static_cast<std::size_t>(k)] = std::to_integer<std::uint8_t>(p[96 + k]);
    pt.position = Vec3(getF32(p + 100), getF32(p + 104), getF32(p + 108)) * kMetresPerMm;
    pt.radius = getF32(p + 112) * kMetresPerMm;
    pt.owner = fixedString(p + 116, 20);
    if (!pt.position.allFinite() || !std::isfinite(pt.radius))
      return bad(m, i * kPointBytes + 100, ErrorCode::Parse,
                 formatString("point %zu has a non-finite position or radius", i));
    pts.push_back(std::move(pt));
  }
  return pts;
}

Result<std::vector<std::byte>> encodePoints(const Envelope& env, std::span<const Point> points) {
  std::vector<std::byte> c;
  c.reserve(points.size() * kPointBytes);
  for (const Point& pt : points) {
    if (auto s = putFixedString(c, pt.name, 64, "point name"); !s) return std::move(s).error();
    if (auto s = putFixedString(c, pt.group, 32, "point group"); !s) return std::move(s).error();
    for (std::uint8_t v : pt.rgba) c.push_back(std::byte{v});
    for (int i = 0; i < 3; ++i) putF32(c, pt.position(i) * kMmPerMetre);
    putF32(c, pt.radius * kMmPerMetre);
    if (auto s = putFixedString(c, pt.owner, 20, "point owner"); !s) return std::move(s).error();
  }
  return encodeRaw(env, "POINT", c);
}

// ---- SENSOR ---------------------------------------------------------------

Result<std::uint64_t> packUnit(const Unit& unit) {
  if (unit.prefix > 0xF)
    return fail(ErrorCode::InvalidArgument, formatString("unit prefix code %u, at most 15", unit.prefix),
                "OpenIGTLink encoder");
  std::uint64_t packed = std::uint64_t{unit.prefix} << 60;
  for (std::size_t i = 0; i < unit.factors.size(); ++i) {
    const UnitFactor& f = unit.factors[i];
    if (f.unit > 0x3F || f.exponent < -7 || f.exponent > 7)
      return fail(ErrorCode::InvalidArgument,
                  formatString("unit factor %zu: code %u, exponent %d (code ≤ 63, exponent −7..7)", i, f.unit,
                               f.exponent),
                  "OpenIGTLink encoder");
    const int shift = 10 * (5 - static_cast<int>(i));
    packed |= std::uint64_t{f.unit} << (shift + 4);
    packed |= std::uint64_t(static_cast<std::uint8_t>(f.exponent) & 0x0F) << shift;
  }
  return packed;
}

Unit unpackUnit(std::uint64_t packed) noexcept {
  Unit u;
  u.prefix = static_cast<std::uint8_t>(packed >> 60);
  for (std::size_t i = 0; i < u.factors.size(); ++i) {
    const int shift = 10 * (5 - static_cast<int>(i));
    u.factors[i].unit = static_cast<std::uint8_t>((packed >> (shift + 4)) & 0x3F);
    const int e = static_cast<int>((packed >> shift) & 0x0F);
    u.factors[i].exponent = static_cast<std::int8_t>(e >= 8 ? e - 16 : e);  // 4-bit two's complement
  }
  return u;
}

Result<SensorInfo> decodeSensor(const MessageView& m) {
  if (auto s = expectType(m, "SENSOR"); !s) return std::move(s).error();
  if (m.content.size() < kSensorHeaderBytes)
    return bad(m, 0, ErrorCode::Parse,
               formatString("SENSOR content is %zu bytes, the header needs 10", m.content.size()));
  const std::byte* p = m.content.data();
  const std::size_t n = std::to_integer<std::size_t>(p[0]);
  if (m.content.size() != kSensorHeaderBytes + 8 * n)
    return bad(m, 0, ErrorCode::Parse,
               formatString("SENSOR length field says %zu values (%zu bytes), the content has %zu", n,
                            kSensorHeaderBytes + 8 * n, m.content.size()));
  SensorInfo s;
  s.status = std::to_integer<std::uint8_t>(p[1]);
  s.unit = getBe64(p + 2);
  s.data.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    s.data[i] = std::bit_cast<double>(getBe64(p + kSensorHeaderBytes + 8 * i));
    if (!std::isfinite(s.data[i]))
      return bad(m, kSensorHeaderBytes + 8 * i, ErrorCode::Parse,
                 formatString("SENSOR value %zu is not finite", i));
  }
  return s;
}

Result<std::vector<std::byte>> encodeSensor(const Envelope& env, const SensorInfo& s) {
  if (s.data.size() > 255)
    return fail(ErrorCode::InvalidArgument, formatString("SENSOR of %zu values, at most 255", s.data.size()),
                "OpenIGTLink encoder", "send several SENSOR messages");
  std::vector<std::byte> c;
  c.reserve(kSensorHeaderBytes + 8 * s.data.size());
  c.push_back(std::byte{static_cast<std::uint8_t>(s.data.size())});
  c.push_back(std::byte{s.status});
  putBe64(c, s.unit);
  for (std::size_t i = 0; i < s.data.size(); ++i) {
    if (!std::isfinite(s.data[i]))
      return fail(ErrorCode::InvalidArgument, formatString("SENSOR value %zu is not finite", i),
                  "OpenIGTLink encoder");
    putBe64(c, std::bit_cast<std::uint64_t>(s.data[i]));
  }
  return encodeRaw(env, "SENSOR", c);
}

// ---- queries --------------------------------------------------------------

bool isQueryType(std::string_view type) noexcept {
  return type.size() > 4 && (type.starts_with("GET_") || type.starts_with("STT_") ||
                             type.starts_with("STP_") || type.starts_with("RTS_"));
}

Result<Query> decodeQuery(const MessageView& m) {
  const std::string& t = m.header.type;
  if (!isQueryType(t))
    return bad(m, 0, ErrorCode::InvalidArgument,
               formatString("message type \"%s\" is not a GET_/STT_/STP_/RTS_ query", t.c_str()));
  Query q;
  q.dataType = t.substr(4);
  const std::size_t n = m.content.size();
  if (t.starts_with("GET_") || t.starts_with("STP_")) {
    q.kind = t.starts_with("GET_") ? QueryKind::Get : QueryKind::Stop;
    if (n != 0)
      return bad(m, 0, ErrorCode::Parse,
                 formatString("%s must have an empty body, it has %zu bytes", t.c_str(), n),
                 "the peer does not follow the OpenIGTLink query convention");
    return q;
  }
  if (t.starts_with("STT_")) {
    q.kind = QueryKind::Start;
    if (n == 0) return q;
    if ((q.dataType == "TDATA" || q.dataType == "QTDATA") && n == kSttTdataBytes) {
      const std::int32_t res = static_cast<std::int32_t>(getBe32(m.content.data()));
      if (res < 0) return bad(m, 0, ErrorCode::Parse, formatString("%s resolution is %d ms", t.c_str(), res));
      q.resolutionMs = static_cast<std::uint32_t>(res);
      q.coordinateName = fixedString(m.content.data() + 4, 32);
      return q;
    }
    return bad(m, 0, ErrorCode::Unsupported,
               formatString("%s with a %zu-byte body: only STT_TDATA/STT_QTDATA carry one (36 bytes)",
                            t.c_str(), n));
  }
  q.kind = QueryKind::Ready;
  if (q.dataType == "COMMAND")
    return bad(m, 0, ErrorCode::InvalidArgument, "RTS_COMMAND carries a command",
               "decode it with decodeCommand()");
  if (n == 0) return q;
  if (n == 1) {
    q.status = std::to_integer<std::uint8_t>(m.content[0]);
    return q;
  }
  return bad(m, 0, ErrorCode::Parse,
             formatString("%s body is %zu bytes, must be 0 or 1 (status)", t.c_str(), n));
}

Result<std::vector<std::byte>> encodeQuery(const Envelope& env, const Query& q) {
  static constexpr const char* kPrefix[] = {"GET_", "STT_", "STP_", "RTS_"};
  const std::string type = kPrefix[static_cast<int>(q.kind)] + q.dataType;
  std::vector<std::byte> c;
  const bool tdata = q.dataType == "TDATA" || q.dataType == "QTDATA";
  if (q.kind == QueryKind::Start && tdata) {
    if (q.resolutionMs > 0x7FFFFFFFu)
      return fail(ErrorCode::InvalidArgument, "resolution exceeds 2^31 - 1 ms", "OpenIGTLink encoder");
    putBe32(c, q.resolutionMs);
    if (auto s = putFixedString(c, q.coordinateName, 32, "coordinate name"); !s) return std::move(s).error();
  } else if (q.kind == QueryKind::Ready) {
    if (q.dataType == "COMMAND")
      return fail(ErrorCode::InvalidArgument, "RTS_COMMAND carries a command", "OpenIGTLink encoder",
                  "use encodeCommand(env, cmd, \"RTS_COMMAND\")");
    c.push_back(std::byte{q.status});
  }
  return encodeRaw(env, type, c);
}

}  // namespace dm::igtl
