// The Haply board's protocol pieces that need no line: the pantograph's
// kinematics (hAPI's Pantograph: the handle, J = ∂(x, y)/∂θ) and the
// decoding of a board's answer to an update. Header-only, for the
// haply-2diy driver (built in and as a plugin) and its fuzz target; see
// haply_2diy.cpp for the protocol.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>

namespace dm::driver::haply {

struct HaplyLinkage {
  double l = 0.05, L = 0.07, d = 0.02;
};

// The handle for arm angles t1, t2 (radians); false when they are no pose.
inline bool haplyHandle(const HaplyLinkage& k, double t1, double t2, double& x, double& y) {
  const double ax = k.l * std::cos(t1), ay = k.l * std::sin(t1);
  const double bx = k.d + k.l * std::cos(t2), by = k.l * std::sin(t2);
  const double dx = bx - ax, dy = by - ay, ab = std::hypot(dx, dy);
  if (!(ab > 1e-9) || ab > 2.0 * k.L) return false;
  const double h = std::sqrt(k.L * k.L - 0.25 * ab * ab);
  const double mx = 0.5 * (ax + bx), my = 0.5 * (ay + by);
  // The two intersections are m ± h·n with n ⟂ AB; the handle is the upper.
  double nx = -dy / ab, ny = dx / ab;
  if (ny < 0 || (ny == 0 && nx < 0)) nx = -nx, ny = -ny;
  x = mx + h * nx;
  y = my + h * ny;
  return y > 0.0 && ax < bx;
}

struct HaplyPose {
  bool valid = false;
  double x = 0, y = 0;
  double jt[2][2] = {};  // Jᵀ: jt[i] = ∂(x, y)/∂θi
};

inline HaplyPose haplyPoseOf(const HaplyLinkage& k, double deg1, double deg2) {
  constexpr double kDeg = 3.14159265358979323846 / 180.0, h = 1e-6;
  HaplyPose p;
  const double t1 = deg1 * kDeg, t2 = deg2 * kDeg;
  if (!haplyHandle(k, t1, t2, p.x, p.y)) return p;
  double xp, yp, xm, ym;
  for (int i = 0; i < 2; ++i) {
    const double e1 = i == 0 ? h : 0.0, e2 = i == 1 ? h : 0.0;
    if (!haplyHandle(k, t1 + e1, t2 + e2, xp, yp) || !haplyHandle(k, t1 - e1, t2 - e2, xm, ym)) return p;
    p.jt[i][0] = (xp - xm) / (2 * h);
    p.jt[i][1] = (yp - ym) / (2 * h);
  }
  p.valid = true;
  return p;
}

inline void putFloatLE(std::uint8_t* out, float v) {
  std::uint32_t bits;
  std::memcpy(&bits, &v, 4);
  for (int i = 0; i < 4; ++i) out[i] = static_cast<std::uint8_t>(bits >> (8 * i));
}
inline float getFloatLE(const std::uint8_t* in) {
  std::uint32_t bits = 0;
  for (int i = 0; i < 4; ++i) bits |= static_cast<std::uint32_t>(in[i]) << (8 * i);
  float v;
  std::memcpy(&v, &bits, 4);
  return v;
}

/// A board's answer to an update: the analog value (when a pin is read) and
/// the angles of arm 1 and arm 2 in degrees.
struct Answer {
  float analog = 0.0f;
  double degrees[2] = {0.0, 0.0};
};

/// Decodes `n` bytes as the answer of the board `id` (its id, a float for
/// the analog pin when `analogPin`, then the angles in port order; arm 1's
/// first unless `arm1Second`); false when they are not one (another
/// length or id, a non-finite angle).
inline bool decodeAnswer(const std::uint8_t* bytes, std::size_t n, std::uint8_t id, bool analogPin,
                         bool arm1Second, Answer& out) {
  const std::size_t size = 1 + 4 * ((analogPin ? 1 : 0) + 2);
  if (n != size || bytes[0] != id) return false;
  std::size_t at = 1;
  if (analogPin) {
    out.analog = getFloatLE(bytes + at);
    at += 4;
  }
  const int first = arm1Second ? 1 : 0;
  out.degrees[first] = getFloatLE(bytes + at);
  out.degrees[1 - first] = getFloatLE(bytes + at + 4);
  return std::isfinite(out.degrees[0]) && std::isfinite(out.degrees[1]);
}

}  // namespace dm::driver::haply
