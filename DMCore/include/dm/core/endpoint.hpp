// dm/core/endpoint.hpp — "address:port" text, as device parameters, scene
// files and command lines write network endpoints. Parsing only (no
// sockets), so that scene files in DMIO and the transports in DMNetwork
// read the same form with the same errors.
//
// @code
//   auto hp = dm::parseHostPort("[::1]:47000", "listen");  // {"::1", 47000}
//   if (!hp) return hp.error();
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <cstdint>
#include <string>
#include <string_view>

namespace dm {

/// A host (name or numeric address, IPv6 without brackets) and a port.
struct HostPort {
  std::string host;
  std::uint16_t port = 0;
};

/// Splits "address:port" (IPv6 as "[::1]:port"). InvalidArgument with
/// `where` = `field` when there is no "address:port" form or the port is
/// not 1..65535 (0 allowed with `allowZeroPort`). O(length).
Result<HostPort> parseHostPort(std::string_view text, std::string_view field, bool allowZeroPort = false);

}  // namespace dm
