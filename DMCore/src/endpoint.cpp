// "address:port" parsing shared by scene files and the network transports.
#include <dm/core/endpoint.hpp>

#include <charconv>

namespace dm {

Result<HostPort> parseHostPort(std::string_view text, std::string_view field, bool allowZeroPort) {
  const auto bad = [&](const char* why) {
    return fail(ErrorCode::InvalidArgument,
                formatString("%.*s: '%.*s' %s", static_cast<int>(field.size()), field.data(),
                             static_cast<int>(text.size()), text.data(), why),
                std::string(field), "write \"address:port\", e.g. \"192.168.1.20:47000\" or \"[::1]:47000\"");
  };
  const std::size_t colon = text.rfind(':');
  if (colon == std::string_view::npos || colon == 0) return bad("has no \"address:port\" form");
  std::string_view address = text.substr(0, colon);
  if (address.size() >= 2 && address.front() == '[' && address.back() == ']')
    address = address.substr(1, address.size() - 2);
  const std::string_view portText = text.substr(colon + 1);
  unsigned port = 0;
  const auto [end, ec] = std::from_chars(portText.data(), portText.data() + portText.size(), port);
  if (ec != std::errc() || end != portText.data() + portText.size() || port > 65535 ||
      (port == 0 && !allowZeroPort))
    return bad(allowZeroPort ? "has no port 0..65535" : "has no port 1..65535");
  return HostPort{std::string(address), static_cast<std::uint16_t>(port)};
}

}  // namespace dm
