// The resistance of tissue to a cutting blade (fracture toughness times the
// engaged edge length); see dm/physics/blade.hpp.
#include <dm/physics/blade.hpp>

#include <cmath>
#include <string>

namespace dm {

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
