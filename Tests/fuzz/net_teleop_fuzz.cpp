// libFuzzer target: the tele-operation stream's datagram decoder
// (dm::decodeTeleopPacket), which reads whatever arrives on the stream's UDP
// port. Input byte 0 picks the mode:
//  * even: the rest is one datagram as received (any type, Wave included).
//    Checks: no crash; an accepted State has a unit quaternion and finite
//    values, and re-encodes to a datagram that decodes to the same values;
//    an accepted Wave has a finite wave and an energy >= 0.
//  * odd: the rest seeds a valid State, Force or Info; it is encoded, one bit
//    is flipped (position from the input) and the result must be refused.
#include <dm/network/teleop.hpp>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

namespace {

double finiteAt(const std::uint8_t* p, std::size_t n, std::size_t i) {
  double v = 0;
  if (n >= 8 * (i + 1)) std::memcpy(&v, p + 8 * i, 8);
  return std::isfinite(v) ? std::fmod(v, 1e6) : 0.0;
}

void checkState(const dm::TeleopPacket& p) {
  if (std::abs(p.state.orientation.norm() - 1.0) > 1e-9) std::abort();
  if (!p.state.position.allFinite() || !p.state.linearVelocity.allFinite()) std::abort();
  std::array<std::byte, dm::kTeleopMaxDatagram> again{};
  const std::size_t n = dm::writeTeleopState(p.header, p.echo, p.state, again);
  auto back = dm::decodeTeleopPacket(std::span(again.data(), n));
  if (!back || back->state.position != p.state.position || back->state.buttons != p.state.buttons ||
      back->echo.holdNs != p.echo.holdNs || back->header.sequence != p.header.sequence)
    std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::uint8_t mode = data[0];
  const std::uint8_t* rest = data + 1;
  const std::size_t n = size - 1;
  if ((mode & 1u) == 0) {
    auto p = dm::decodeTeleopPacket(std::span(reinterpret_cast<const std::byte*>(rest), n));
    if (p && p->header.type == dm::kTeleopStateType) checkState(*p);
    if (p && p->header.type == dm::kTeleopForceType &&
        (!p->force.force.allFinite() || !p->force.torque.allFinite()))
      std::abort();
    if (p && p->header.type == dm::kTeleopWaveType && (!p->wave.wave.allFinite() || !(p->wave.energy >= 0)))
      std::abort();
    return 0;
  }
  std::vector<std::byte> wire(dm::kTeleopMaxDatagram);
  const dm::MessageHeader header{.sequence = n > 0 ? rest[0] : 0u, .timestampNs = static_cast<std::int64_t>(n)};
  switch ((mode >> 1) % 3) {
    case 0: {
      dm::HapticState s;
      s.position = dm::Vec3(finiteAt(rest, n, 0), finiteAt(rest, n, 1), finiteAt(rest, n, 2));
      s.orientation = dm::Quat(Eigen::AngleAxisd(finiteAt(rest, n, 3), dm::Vec3::UnitZ()));
      wire.resize(dm::writeTeleopState(header, {}, s, wire));
      break;
    }
    case 1: {
      dm::HapticOutput f;
      f.force = dm::Vec3(finiteAt(rest, n, 0), finiteAt(rest, n, 1), finiteAt(rest, n, 2));
      wire.resize(dm::writeTeleopForce(header, {}, f, wire));
      break;
    }
    default: {
      dm::HapticInfo info;
      info.model.assign(reinterpret_cast<const char*>(rest), std::min<std::size_t>(n, 80));
      info.model = info.model.c_str();  // up to the first NUL, as the wire carries it
      info.servoRateHz = 1000;
      wire = dm::encodeTeleopInfo(header, info);
      break;
    }
  }
  auto ok = dm::decodeTeleopPacket(wire);
  if (!ok) std::abort();  // what we encode must decode
  const std::size_t bit = (n >= 3 ? (static_cast<std::size_t>(rest[1]) << 8 | rest[2]) : 0) % (wire.size() * 8);
  wire[bit / 8] ^= std::byte{static_cast<unsigned char>(1u << (bit % 8))};
  if (dm::decodeTeleopPacket(wire)) std::abort();  // CRC-32C catches every single-bit error
  return 0;
}
