// scene_joints.cpp — the physics engine's "joints" (v2): ball, hinge, slider
// and fixed joints between the scene's rigid bodies or to the world, their
// checks against the objects and their JSON (docs/scene-format.md, "Joints";
// the runtime builds them in DMEngine/src/physics_engine.cpp).
#include <array>
#include <numbers>
#include <set>

#include "scene_parse.hpp"

namespace dm::scene_parse {

namespace {

using Type = SceneJoint::Type;

constexpr std::array<std::pair<std::string_view, Type>, 4> kTypes{
    {{"ball", Type::Ball}, {"hinge", Type::Hinge}, {"slider", Type::Slider}, {"fixed", Type::Fixed}}};

std::string_view typeName(Type t) {
  for (const auto& [name, type] : kTypes)
    if (type == t) return name;
  return "ball";
}

// `key` names a rigid body of the physics world: a dynamic object, or a
// static one that collides (the others are not in the world). Returns
// whether it is dynamic.
bool readBody(ConfigReader& r, std::string_view key, const SceneDesc& scene, std::string& name) {
  const std::size_t before = r.errors().size();
  name = r.string(key);
  if (r.errors().size() != before) return false;
  const SceneObject* o = scene.object(name);
  const std::string proxy = scene.engines.haptics ? scene.engines.haptics->proxyObject : std::string();
  if (o == nullptr) {
    r.addError("no object " + inQuotes(name), key, "name an object under \"objects\"");
  } else if (!proxy.empty() && name == proxy) {
    r.addError("object " + inQuotes(name) + " is the haptic proxy, which the tool moves", key,
               "join the bodies the tool touches, not the tool's picture");
  } else if (o->membrane) {
    r.addError("object " + inQuotes(name) + " is a membrane (mass–spring), not a rigid body", key,
               "hold a membrane with its \"pinned\" vertices");
  } else if (o->soft) {
    r.addError("object " + inQuotes(name) + " is soft tissue (FEM), not a rigid body", key,
               "hold tissue with \"fixed\" regions in its \"soft\" block");
  } else if (!o->dynamic && !o->collide) {
    r.addError(
        "object " + inQuotes(name) + " is static and does not collide, so it is not in the physics world",
        key, "leave \"b\" out to hold to the world, or let the object collide");
  } else {
    return o->dynamic;
  }
  return false;
}

// "limits": [lower, upper] around the start (0): radians within (−π, π) for
// a hinge, metres for a slider.
void readLimits(ConfigReader& r, SceneJoint& j) {
  if (!r.has("limits")) return;
  if (j.type != Type::Hinge && j.type != Type::Slider) {
    r.addError("a " + std::string(typeName(j.type)) + " joint has no limits", "limits",
               "limits bound a hinge's angle or a slider's travel");
    return;
  }
  const std::size_t before = r.errors().size();
  const std::vector<double> v = r.numbers("limits", 2);
  if (r.errors().size() != before) return;
  const double bound = j.type == Type::Hinge ? std::numbers::pi : 1e3;
  const char* unit = j.type == Type::Hinge ? "rad" : "m";
  if (!(v[0] <= 0.0 && 0.0 <= v[1] && v[0] < v[1]))
    r.addError(formatString("limits [%g, %g] %s do not hold the start", v[0], v[1], unit), "limits",
               "the joint starts at 0 in the objects' poses: lower ≤ 0 ≤ upper, lower < upper");
  else if (!(v[0] > -bound && v[1] < bound))
    r.addError(
        formatString("limits [%g, %g] %s reach past ±%g", v[0], v[1], unit, bound), "limits",
        j.type == Type::Hinge ? "a hinge's limits lie within (−π, π)" : "a slider's travel within ±1 km");
  else {
    j.limited = true;
    j.lower = v[0];
    j.upper = v[1];
  }
}

}  // namespace

void readJoints(ConfigReader& physics, ScenePhysicsEngine& p, const SceneDesc& scene) {
  ConfigReader list = physics.child("joints");
  if (!expectArray(list)) return;
  std::set<std::string, std::less<>> names;
  for (std::size_t i = 0; i < list.size(); ++i) {
    ConfigReader r = list.at(i);
    if (!expectObject(r)) continue;
    r.knownKeys({"name", "type", "a", "b", "anchor", "axis", "limits"});
    SceneJoint j;
    j.name = readUniqueName(r, names, "joint");
    const std::size_t typeErrors = r.errors().size();
    const std::string type = r.oneOf("type", {"ball", "hinge", "slider", "fixed"});
    const bool typed = r.errors().size() == typeErrors;
    for (const auto& [name, t] : kTypes)
      if (name == type) j.type = t;
    const bool aMoves = readBody(r, "a", scene, j.a);
    bool bMoves = false;
    if (r.has("b")) {
      bMoves = readBody(r, "b", scene, j.b);
      if (j.b == j.a)
        r.addError("a joint holds two different bodies; \"a\" and \"b\" are both " + inQuotes(j.a), "b",
                   "leave \"b\" out to hold \"a\" to the world");
    }
    // Both bodies read without a problem (a missing or wrong one was named
    // above), and neither moves.
    if (r.errors().size() == typeErrors && !aMoves && !bMoves)
      r.addError("neither body moves: " + inQuotes(j.a) +
                     (j.b.empty() ? " and the world" : " and " + inQuotes(j.b)) + " are static",
                 "a", "join a dynamic object");
    j.anchor = readVec3(r, "anchor");
    if (typed) {
      const bool axial = j.type == Type::Hinge || j.type == Type::Slider;
      if (axial && !r.has("axis"))
        r.addError("a " + type + " joint needs an \"axis\"", "axis",
                   "the world direction it turns about or slides along, e.g. [0, 0, 1]");
      else if (axial)
        j.axis = readDirection(r, "axis", j.axis);
      else if (r.has("axis"))
        r.addError("a " + type + " joint has no axis", "axis",
                   "remove \"axis\", or make it a hinge or a slider");
      readLimits(r, j);
    }
    p.joints.push_back(std::move(j));
  }
}

Json jointsJson(const std::vector<SceneJoint>& joints) {
  Json out = Json::array();
  for (const SceneJoint& j : joints) {
    Json e = {{"name", j.name}, {"type", typeName(j.type)}, {"a", j.a}, {"anchor", toJson(j.anchor)}};
    if (!j.b.empty()) e["b"] = j.b;
    if (j.type == Type::Hinge || j.type == Type::Slider) e["axis"] = toJson(j.axis);
    if (j.limited) e["limits"] = Json::array({j.lower, j.upper});
    out.push_back(std::move(e));
  }
  return out;
}

}  // namespace dm::scene_parse
