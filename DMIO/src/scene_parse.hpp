// scene_parse.hpp (private) — the readers shared by the scene file's
// sections (scene_file.cpp), its surgical keys (scene_surgery.cpp), its
// soft tissue (scene_soft.cpp), its 6-DOF tools (scene_6dof.cpp), its bone
// placement (scene_bone.cpp) and its OpenIGTLink engine (scene_igtl.cpp):
// enums by name, vectors, colours, poses, positive numbers, and their JSON.
#pragma once

#include <dm/core/config.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/units.hpp>
#include <dm/io/scene_file.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace dm::scene_parse {

// A quaternion this far from unit length is a mistake, not rounding.
constexpr double kUnitTolerance = 1e-3;
// Closer to unit than this is kept bit for bit, so toJson() round trips.
constexpr double kRenormalize = 1e-9;

template <class E, std::size_t N>
std::string enumName(E e, const std::array<std::string_view, N>& names) {
  return std::string(names[static_cast<std::size_t>(e)]);
}

template <std::size_t N, std::size_t... I>
std::string oneOfArray(ConfigReader& r, std::string_view key, const std::array<std::string_view, N>& names,
                       std::optional<std::string> fallback, std::index_sequence<I...>) {
  return r.oneOf(key, {names[I]...}, std::move(fallback));
}

// An enum value named by one of `names`; nullopt (and an error) when it is
// missing without a fallback or not one of them.
template <class E, std::size_t N>
std::optional<E> readEnum(ConfigReader& r, std::string_view key, const std::array<std::string_view, N>& names,
                          std::optional<E> fallback = std::nullopt) {
  const std::size_t before = r.errors().size();
  std::optional<std::string> fb;
  if (fallback) fb = enumName(*fallback, names);
  const std::string s = oneOfArray(r, key, names, fb, std::make_index_sequence<N>{});
  if (r.errors().size() != before) return std::nullopt;
  const auto it = std::find(names.begin(), names.end(), s);
  return static_cast<E>(it - names.begin());
}

// The candidate closest to `word` by edit distance, if it is plausibly a
// typo (at most max(2, length / 3) edits, like dm::closestMatch).
inline std::string nearestName(std::string_view word, const std::vector<std::string>& names) {
  if (word.size() > 256) return {};
  const std::size_t limit = std::max<std::size_t>(2, word.size() / 3);
  std::string best;
  std::size_t bestD = limit + 1;
  for (const std::string& n : names) {
    // The length difference bounds the distance from below: skip early.
    const std::size_t diff = n.size() > word.size() ? n.size() - word.size() : word.size() - n.size();
    if (diff >= bestD) continue;
    const std::size_t d = editDistance(word, n);
    if (d < bestD) {
      bestD = d;
      best = n;
    }
  }
  return best;
}

inline std::string inQuotes(std::string_view s) { return "\"" + std::string(s) + "\""; }

inline bool isNull(const ConfigReader& r) { return r.node().is_null(); }

// True if `r` is an object; records an error if it is present but is not.
inline bool expectObject(ConfigReader& r) {
  if (r.isObject()) return true;
  if (!isNull(r)) r.addError(std::string("expected an object, got ") + r.node().type_name());
  return false;
}

inline bool expectArray(ConfigReader& r) {
  if (r.isArray()) return true;
  if (!isNull(r)) r.addError(std::string("expected an array, got ") + r.node().type_name());
  return false;
}

inline Vec3 readVec3(ConfigReader& r, std::string_view key, const Vec3& fallback) {
  const std::vector<double> v =
      r.numbers(key, 3, std::vector<double>{fallback.x(), fallback.y(), fallback.z()});
  return {v[0], v[1], v[2]};
}

inline Vec3 readVec3(ConfigReader& r, std::string_view key) {
  const std::vector<double> v = r.numbers(key, 3);
  return {v[0], v[1], v[2]};
}

// A unit vector: any non-zero length is normalised (lengths within 1e-9 of
// one are kept as written, so a written scene reads back bit for bit).
inline Vec3 readDirection(ConfigReader& r, std::string_view key, const Vec3& fallback) {
  const std::size_t before = r.errors().size();
  Vec3 d = readVec3(r, key, fallback);
  if (r.errors().size() != before) return fallback;
  const double n = d.norm();
  if (!(n > 1e-12)) {
    r.addError("direction has zero length", key, "give a non-zero vector, e.g. [0, 0, -1]");
    return fallback;
  }
  if (std::abs(n - 1.0) > kRenormalize) d /= n;
  return d;
}

// A number that must be > 0 (and ≤ max).
inline double readPositive(ConfigReader& r, std::string_view key, std::optional<double> fallback,
                           double max = std::numeric_limits<double>::infinity()) {
  const std::size_t before = r.errors().size();
  const double v = r.number(key, {.min = 0.0, .max = max}, fallback);
  if (r.errors().size() == before && !(v > 0.0)) {
    r.addError("value must be greater than 0", key);
    return fallback.value_or(1.0);
  }
  return v;
}

// Linear colour [r, g, b] (or [r, g, b, a] when alpha is allowed), each
// component in [0, max].
inline Vec4 readColor(ConfigReader& r, std::string_view key, const Vec4& fallback, bool alpha,
                      double max = 1.0) {
  if (!r.has(key)) return fallback;
  ConfigReader c = r.child(key);
  const Json& j = c.node();
  if (!j.is_array() || !(j.size() == 3 || (alpha && j.size() == 4))) {
    if (j.is_array())
      c.addError("expected " + std::string(alpha ? "[r, g, b] or [r, g, b, a]" : "[r, g, b]") + ", got " +
                     std::to_string(j.size()) + " numbers",
                 {}, "give linear colour components between 0 and 1");
    return fallback;
  }
  Vec4 out(0.0, 0.0, 0.0, 1.0);
  for (std::size_t i = 0; i < j.size(); ++i) {
    const Json& e = j[i];
    if (!e.is_number() || !std::isfinite(e.get<double>())) {
      c.addError("expected a number, got " + std::string(e.type_name()), std::to_string(i));
      continue;
    }
    const double v = e.get<double>();
    if (v < 0.0 || v > max) {
      c.addError(formatString("component %g is outside [0, %g]", v, max), std::to_string(i),
                 "colours are linear, 0..1 (not 0..255)");
      continue;
    }
    out[static_cast<Eigen::Index>(i)] = v;
  }
  return out;
}

// {"position": [x, y, z], "rotation": [w, x, y, z]} or {..., "euler_deg": [rx, ry, rz]}.
inline Pose readPose(ConfigReader p) {
  Pose out;
  if (!expectObject(p)) return out;
  p.knownKeys({"position", "rotation", "euler_deg"});
  out.p = readVec3(p, "position", Vec3::Zero());
  if (p.has("rotation") && p.has("euler_deg")) {
    p.addError("both \"rotation\" and \"euler_deg\" are given", "euler_deg", "give only one of them");
    return out;
  }
  const std::size_t before = p.errors().size();
  if (p.has("rotation")) {
    const std::vector<double> q = p.numbers("rotation", 4);
    if (p.errors().size() != before) return out;
    Quat r(q[0], q[1], q[2], q[3]);
    const double n = r.norm();
    if (!(std::abs(n - 1.0) <= kUnitTolerance)) {
      p.addError(formatString("rotation quaternion has length %g, not 1", n), "rotation",
                 "give a unit quaternion [w, x, y, z], or use \"euler_deg\": [rx, ry, rz]");
      return out;
    }
    if (std::abs(n - 1.0) > kRenormalize) r.normalize();
    out.q = r;
  } else if (p.has("euler_deg")) {
    const Vec3 e = readVec3(p, "euler_deg") * units::deg;
    if (p.errors().size() != before) return out;
    out.q =
        (AngleAxis(e.z(), Vec3::UnitZ()) * AngleAxis(e.y(), Vec3::UnitY()) * AngleAxis(e.x(), Vec3::UnitX()))
            .normalized();
  }
  return out;
}

inline Json toJson(const Vec3& v) { return Json::array({v.x(), v.y(), v.z()}); }

// {"min": [x, y, z], "max": [x, y, z]}, min ≤ max (min < max on every axis
// when `solid`: a box that must hold something); nullopt on an error
// (recorded).
inline std::optional<SceneBox> readBox(ConfigReader& r, bool solid = false) {
  if (!expectObject(r)) return std::nullopt;
  r.knownKeys({"min", "max"});
  const std::size_t before = r.errors().size();
  SceneBox box{readVec3(r, "min"), readVec3(r, "max")};
  if (r.errors().size() != before) return std::nullopt;
  if ((box.max - box.min).minCoeff() < 0.0 || (solid && !((box.max - box.min).minCoeff() > 0.0))) {
    r.addError(solid ? "max is not above min on every axis" : "max is below min", "max",
               "give the box's lowest corner as min, its highest as max");
    return std::nullopt;
  }
  return box;
}

// A unique, non-empty "name" among `names` (a script, a fluid, an inlet...);
// an error (recorded) names an empty or repeated one.
inline std::string readUniqueName(ConfigReader& r, std::set<std::string, std::less<>>& names,
                                  std::string_view what) {
  const std::size_t before = r.errors().size();
  std::string name = r.string("name");
  if (r.errors().size() != before) return name;
  if (name.empty())
    r.addError("name is empty", "name",
               "give the " + std::string(what) + " a unique name; the summary uses it");
  else if (!names.insert(name).second)
    r.addError("duplicate " + std::string(what) + " name " + inQuotes(name), "name",
               "names must be unique: rename one");
  return name;
}

inline Json boxJson(const SceneBox& b) { return {{"min", toJson(b.min)}, {"max", toJson(b.max)}}; }
inline Json toJson(const Vec4& v) { return Json::array({v.x(), v.y(), v.z(), v.w()}); }
inline Json toJson(const Pose& p) {
  return {{"position", toJson(p.p)}, {"rotation", Json::array({p.q.w(), p.q.x(), p.q.y(), p.q.z()})}};
}

// Surgical keys (scene_surgery.cpp). Object keys "millable" and "critical",
// the haptics engine's "burr" block, and the checks between them and the
// engines once the whole scene is read.
void readMillable(ConfigReader& object, SceneObject& o);
// A volume resource's "phantom" block (a generated CT) and its JSON.
void readPhantom(ConfigReader& resource, SceneResource& res);
Json phantomJson(const CalvariumPhantom& p);
void readCritical(ConfigReader& object, SceneObject& o);
void readInclusion(ConfigReader& object, SceneObject& o);
void readBurr(ConfigReader& haptics, SceneHapticsEngine& h);
void checkSurgery(const SceneDesc& scene, ConfigReader root);
void writeSurgery(const SceneObject& o, Json& object);
void writeBurr(const SceneBurr& b, Json& haptics);

// Soft tissue (scene_soft.cpp): an object's "soft" block, its checks once
// the whole scene is read, and its JSON.
void readSoft(ConfigReader& object, SceneObject& o);
void checkSoft(const SceneDesc& scene, ConfigReader root);
// What every deforming object (soft tissue, a membrane) needs of the rest of
// the scene: a physics engine to deform it, no rigid-body or bone keys, no
// render mesh of its own (it is drawn as its deformed surface), a mesh
// resource no other object draws. `kind` names it in messages ("soft
// object"), `block` is its key ("soft"), `rateHz` the engine rate to hint.
void checkDeforming(const SceneDesc& scene, ConfigReader& r, const SceneObject& o, std::string_view kind,
                    std::string_view block, int rateHz);
void writeSoft(const SceneObject& o, Json& object);
// Membranes (scene_membrane.cpp): an object's "membrane" block, its checks
// against the engines and the other objects once the scene is read, its JSON.
void readMembrane(ConfigReader& object, SceneObject& o);
void checkMembranes(const SceneDesc& scene, ConfigReader root);
void writeMembrane(const SceneObject& o, Json& object);
// The haptics engine's "needle" block (the needle renderer's needle).
void readNeedle(ConfigReader& haptics, SceneHapticsEngine& h);
void readPunch(ConfigReader& haptics, SceneHapticsEngine& h);
void writePunch(const ScenePunch& p, Json& haptics);
void writeNeedle(const SceneNeedle& n, Json& haptics);

// The 6-DOF rigid-tool renderers (scene_6dof.cpp): the haptics engine's
// "vps" and "sphere_tree" blocks, their checks against the renderer, the
// objects and their materials (scene6Dof), their JSON.
void readVps(ConfigReader& haptics, SceneHapticsEngine& h);
void readSphereTree(ConfigReader& haptics, SceneHapticsEngine& h);
void checkTools6Dof(const SceneDesc& scene, ConfigReader root);
void writeVps(const SceneVps& v, Json& haptics);
void writeSphereTree(const SceneSphereTree& t, Json& haptics);

// Bone placement (scene_bone.cpp): a volume resource's "segment", an
// object's "voxels", the haptics engine's "bone_placement" block, their
// checks once the whole scene is read, their JSON.
void readSegment(ConfigReader& resource, SceneResource& res);
Json segmentJson(const SceneSegment& g);
void readVoxels(ConfigReader& object, SceneObject& o);
void readBonePlacement(ConfigReader& haptics, SceneHapticsEngine& h);
void checkBonePlacement(const SceneDesc& scene, ConfigReader root);
void writeVoxels(const SceneObject& o, Json& object);
void writeBonePlacement(const SceneBonePlacement& b, Json& haptics);

// The OpenIGTLink engine (scene_igtl.cpp): "engines"/"igtl", its checks
// against the other engines and objects once the scene is read, its JSON.
void readIgtl(ConfigReader& engines, SceneEngines& e);
void checkIgtl(const SceneDesc& scene, ConfigReader root);
void writeIgtl(const SceneIgtlEngine& g, Json& engines);

// scene_segmentation.cpp: the segmentation engine (DMVision's haptic-guided
// segmentation of a volume resource at the haptic tool).
void readSegmentation(ConfigReader& engines, SceneEngines& e);
void checkSegmentation(const SceneDesc& scene, ConfigReader root);
void writeSegmentation(const SceneSegmentationEngine& g, Json& engines);

// Scripts (scene_script.cpp): the "scripts" list with their checks against
// the engines (read after them), and its JSON. `resolve` turns a source
// into a confined path (adding its error to the reader when it cannot).
using SourceResolver =
    std::function<std::filesystem::path(ConfigReader&, const std::string&, std::string_view)>;
void readScripts(ConfigReader& root, SceneDesc& scene, const SourceResolver& resolve);
Json scriptsJson(const std::vector<SceneScript>& scripts);
// The physics engine's "joints" (v2; scene_joints.cpp): read after the
// objects, whose names they take.
void readJoints(ConfigReader& physics, ScenePhysicsEngine& p, const SceneDesc& scene);
Json jointsJson(const std::vector<SceneJoint>& joints);
// The physics engine's "backend" and "ode" settings (v2; scene_physics_backend.cpp),
// read after "sleep", which the ODE backend refuses; written only when not the default.
void readPhysicsBackend(ConfigReader& physics, ScenePhysicsEngine& p);
void writePhysicsBackend(const ScenePhysicsEngine& p, Json& physics);
// "fluids" (v2; scene_fluid.cpp).
void readFluids(ConfigReader& root, SceneDesc& scene);
Json fluidsJson(const std::vector<SceneFluid>& fluids);

}  // namespace dm::scene_parse
