// libFuzzer target: OpenIGTLink decoding of every supported type. The CRC
// check is off so the fuzzer reaches the content parsers; each input's
// content is then parsed as every type (the type field is overridden), with
// small size limits. Accepted messages must re-encode and decode again.
#include <dm/network/igtl.hpp>

#include <cstdint>
#include <cstdlib>

namespace {

template <class F>
void asType(dm::igtl::MessageView m, const char* type, F&& decode) {
  m.header.type = type;
  (void)decode(m);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace igtl = dm::igtl;
  std::span<const std::byte> in(reinterpret_cast<const std::byte*>(data), size);
  (void)igtl::decodeMessage(in);  // with the CRC check
  auto m = igtl::decodeMessage(in, {.verifyCrc = false, .maxBodyBytes = 1 << 20});
  if (!m) return 0;
  constexpr std::size_t kMax = 16 << 20;
  asType(*m, "TRANSFORM", [](const auto& v) { return igtl::decodeTransform(v); });
  asType(*m, "POSITION", [](const auto& v) { return igtl::decodePosition(v); });
  asType(*m, "IMAGE", [](const auto& v) { return igtl::decodeVolume(v, kMax); });
  asType(*m, "IMAGE", [](const auto& v) { return igtl::decodeImage(v, kMax); });
  asType(*m, "STATUS", [](const auto& v) { return igtl::decodeStatus(v); });
  asType(*m, "STRING", [](const auto& v) { return igtl::decodeString(v); });
  asType(*m, "COMMAND", [](const auto& v) { return igtl::decodeCommand(v); });
  asType(*m, "POINT", [](const auto& v) { return igtl::decodePoints(v); });
  asType(*m, "POLYDATA", [](const auto& v) { return igtl::decodePolyData(v); });
  asType(*m, "SENSOR", [](const auto& v) { return igtl::decodeSensor(v); });
  asType(*m, "STT_TDATA", [](const auto& v) { return igtl::decodeQuery(v); });
  asType(*m, "RTS_TDATA", [](const auto& v) { return igtl::decodeQuery(v); });
  (void)igtl::decodeQuery(*m);
  // Round trip of what is accepted under its own type.
  const igtl::Envelope env{
      .version = m->header.version,
      .deviceName = m->header.deviceName,
      .timestamp = m->header.timestamp,
      .messageId = m->header.version >= 2 ? m->messageId : 0,
      .metadata = m->header.version >= 2 ? m->metadata : std::vector<igtl::MetadataEntry>{}};
  if (m->header.type == "STRING") {
    if (auto s = igtl::decodeString(*m); s) {
      auto again = igtl::encodeString(env, *s);
      if (!again) std::abort();
      auto back = igtl::decodeMessage(*again);
      if (!back || igtl::decodeString(*back).value() != *s || back->metadata != m->metadata) std::abort();
    }
  } else if (m->header.type == "SENSOR") {
    if (auto v = igtl::decodeSensor(*m); v) {
      auto again = igtl::encodeSensor(env, *v);
      if (!again) std::abort();
      auto back = igtl::decodeMessage(*again);
      if (!back || igtl::decodeSensor(*back).value() != *v) std::abort();
    }
  } else if (m->header.type == "COMMAND") {
    if (auto c = igtl::decodeCommand(*m); c) {
      auto again = igtl::encodeCommand(env, *c);
      if (!again) std::abort();
      auto back = igtl::decodeMessage(*again);
      if (!back || igtl::decodeCommand(*back).value() != *c) std::abort();
    }
  }
  return 0;
}
