// The resistance of tissue to a cutting blade (fracture toughness times the
// engaged edge length); see dm/physics/blade.hpp.
#include <dm/collide/triangle.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/physics/blade.hpp>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

namespace dm {

double engagedLength(const Vec3& a, const Vec3& b, const Mesh& surface) {
  const Vec3 d = b - a;
  const double length = d.norm();
  if (!(length > 0.0) || !a.allFinite() || !b.allFinite()) return 0.0;
  // Crossings along the edge: +1 entering (against the outward normal), −1 leaving.
  std::vector<std::pair<double, int>> crossings;
  for (const Triangle& t : surface.triangles) {
    const Vec3 &p0 = surface.positions[t[0]], &p1 = surface.positions[t[1]], &p2 = surface.positions[t[2]];
    RayTriangleHit hit;
    if (rayTriangle(a, d, p0, p1, p2, 0.0, 1.0, hit))
      crossings.push_back({hit.t, (p1 - p0).cross(p2 - p0).dot(d) < 0.0 ? 1 : -1});
  }
  // An edge through a vertex or an edge of the surface hits every triangle
  // there that the watertight test gives it: one crossing each way.
  std::sort(crossings.begin(), crossings.end());
  std::size_t kept = 0;
  for (std::size_t i = 0; i < crossings.size(); ++i) {
    bool repeat = false;
    for (std::size_t j = kept; j-- > 0 && crossings[i].first - crossings[j].first <= 1e-12;)
      repeat = repeat || crossings[j].second == crossings[i].second;
    if (!repeat) crossings[kept++] = crossings[i];
  }
  crossings.resize(kept);
  int depth = windingNumber(surface, a) > 0.5 ? 1 : 0;
  double inside = 0.0, from = 0.0;
  for (const auto& [t, step] : crossings) {
    if (depth > 0) inside += t - from;
    depth = std::max(0, depth + step);
    from = t;
  }
  if (depth > 0) inside += 1.0 - from;
  return inside * length;
}

Result<BladeResistance> BladeResistance::create(const BladeResistanceOptions& options) {
  const struct {
    const char* name;
    double value;
  } fields[] = {
      {"toughness", options.toughness}, {"stiffness", options.stiffness}, {"maxForce", options.maxForce}};
  for (const auto& f : fields)
    if (!(f.value > 0.0) || !std::isfinite(f.value))
      return fail(ErrorCode::InvalidArgument,
                  std::string(f.name) + " = " + std::to_string(f.value) + " is not positive",
                  std::string("BladeResistance::create: ") + f.name);
  BladeResistance b;
  b.options_ = options;
  return b;
}

void BladeResistance::reset(const Vec3& p) noexcept {
  proxy_ = device_ = front_ = p;
  cutting_ = false;
  area_ = work_ = 0.0;
}

Vec3 BladeResistance::tick(const Vec3& device, const Vec3& direction, double engaged) noexcept {
  cutting_ = false;
  const double norm = direction.norm();
  if (!device.allFinite() || !std::isfinite(engaged) || engaged < 0.0 || !(norm > 0.0) ||
      !std::isfinite(norm))
    return Vec3::Zero();
  const Vec3 u = direction / norm;
  const double k = options_.stiffness;
  const Vec3 before = k * (device_ - proxy_);  // on the blade, from the hand
  if (engaged == 0.0) {
    front_ = proxy_ = device;
  } else {
    const double ahead = (device - front_).dot(u);
    const double hold = options_.toughness * engaged / k;  // the spring's stretch at J·w
    if (ahead <= 0.0) {
      proxy_ = device;  // in the cut already made
    } else if (ahead <= hold) {
      proxy_ = device - ahead * u;
    } else {
      const double advance = ahead - hold;
      front_ += advance * u;
      area_ += engaged * advance;
      proxy_ = device - hold * u;
      cutting_ = true;
    }
  }
  const Vec3 after = k * (device - proxy_);
  work_ += 0.5 * (before + after).dot(device - device_);  // trapezoid: exact for the spring
  device_ = device;
  Vec3 onHand = -after;
  const double f = onHand.norm();
  if (f > options_.maxForce) onHand *= options_.maxForce / f;
  return onHand;
}

}  // namespace dm
