// Shared pieces of the haptic renderers (dm/haptics/renderer.hpp).
#include <dm/haptics/renderer.hpp>

#include <cmath>
#include <string>

namespace dm {

Status HapticMaterial::validate(std::string_view where) const {
  const std::string at(where);
  const auto bad = [&](const char* field, double value, const char* rule) -> Status {
    return fail(ErrorCode::InvalidArgument,
                formatString("material %s is %g; it must be %s", field, value, rule), at + "/" + field,
                "fix the material in the scene");
  };
  if (!std::isfinite(stiffness) || stiffness <= 0.0) return bad("stiffness", stiffness, "finite and > 0 N/m");
  if (!std::isfinite(damping) || damping < 0.0) return bad("damping", damping, "finite and >= 0 N*s/m");
  if (!std::isfinite(staticFriction) || staticFriction < 0.0)
    return bad("staticFriction", staticFriction, "finite and >= 0");
  if (!std::isfinite(dynamicFriction) || dynamicFriction < 0.0)
    return bad("dynamicFriction", dynamicFriction, "finite and >= 0");
  if (dynamicFriction > staticFriction)
    return bad("dynamicFriction", dynamicFriction,
               "at most staticFriction (dynamic friction never exceeds static)");
  return ok();
}

}  // namespace dm
