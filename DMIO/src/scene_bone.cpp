// scene_bone.cpp — the scene file's bone placement: volume segments (a bone
// fragment cut from a CT: "segment" on a volume resource), an object's
// voxels ("voxels"), the haptics engine's "bone_placement" block, the checks
// between them once the whole scene is read, and their JSON
// (docs/scene-format.md, "Bone placement").
#include "scene_parse.hpp"

namespace dm {

bool SceneBonePlacement::operator==(const SceneBonePlacement& o) const {
  return fragment == o.fragment && threshold == o.threshold && couplingStiffness == o.couplingStiffness &&
         couplingDamping == o.couplingDamping && couplingAngularStiffness == o.couplingAngularStiffness &&
         couplingAngularDamping == o.couplingAngularDamping && mass == o.mass && density == o.density &&
         maxContacts == o.maxContacts && iterations == o.iterations && contactLevel == o.contactLevel &&
         slop == o.slop && baumgarte == o.baumgarte && maxTorque == o.maxTorque && target.p == o.target.p &&
         target.q.coeffs() == o.target.q.coeffs();
}

namespace scene_parse {

namespace {

constexpr std::array<std::string_view, 3> kSelects{"above", "below", "label"};

// The names of the volume resources that `fits`, for a hint.
template <class Fits>
std::string volumeNames(const SceneDesc& scene, Fits fits) {
  std::string names;
  for (const SceneResource& x : scene.resources)
    if (x.type == SceneResource::Type::Volume && fits(x))
      names += (names.empty() ? "" : ", ") + inQuotes(x.name);
  return names;
}

// `name` must be a volume resource (and, with `notSegment`, one read or
// generated rather than made from another); records the error at `key`.
void checkVolume(const SceneDesc& scene, ConfigReader& r, std::string_view key, const std::string& name,
                 bool notSegment) {
  const SceneResource* res = scene.resource(name);
  const bool volume = res != nullptr && res->type == SceneResource::Type::Volume;
  if (volume && !(notSegment && res->segment)) return;
  const std::string names =
      volumeNames(scene, [&](const SceneResource& x) { return !notSegment || !x.segment; });
  const std::string why = res == nullptr ? " is not defined"
                          : !volume      ? " is not a volume"
                                         : " is itself a segment (segments are made from scans)";
  r.addError("resource " + inQuotes(name) + why, key,
             names.empty() ? "define a \"volume\" resource (the CT)" : "use one of: " + names);
}

}  // namespace

void readSegment(ConfigReader& resource, SceneResource& res) {
  ConfigReader r = resource.child("segment");
  if (!expectObject(r)) return;
  r.knownKeys({"volume", "above", "below", "label", "outside", "near", "box", "cuts", "largest_component"});
  SceneSegment g;
  g.volume = r.string("volume");
  int selects = 0;
  for (std::size_t i = 0; i < kSelects.size(); ++i) {
    if (!r.has(kSelects[i])) continue;
    if (++selects > 1) {
      r.addError("a segment selects its voxels one way", kSelects[i],
                 "give one of \"above\", \"below\", \"label\"");
      continue;
    }
    g.select = static_cast<SceneSegment::Select>(i);
    g.value = g.select == SceneSegment::Select::Label
                  ? static_cast<double>(r.integer(kSelects[i], {.min = -2147483648.0, .max = 2147483647.0}))
                  : r.number(kSelects[i]);
  }
  if (selects == 0)
    r.addError("a segment needs to know which voxels it keeps", {},
               "add \"above\": <value> (a CT's bone: HU above ~300), \"below\": <value> or \"label\": <n>");
  if (r.has("outside")) {
    g.outside = r.string("outside");
    if (g.outside.empty()) r.addError("an empty volume name", "outside", "name the mask's volume resource");
  }
  if (r.has("near")) {
    ConfigReader n = r.child("near");
    if (expectObject(n)) {
      n.knownKeys({"volume", "distance"});
      SceneSegmentNear near;
      near.volume = n.string("volume");
      if (n.has("volume") && near.volume.empty())
        n.addError("an empty volume name", "volume", "name the mask's volume resource");
      near.distance = n.number("distance", {.min = 1e-6, .max = 0.1});
      g.near = std::move(near);
    }
  }
  if (r.has("box")) {
    ConfigReader b = r.child("box");
    if (expectObject(b)) {
      b.knownKeys({"min", "max"});
      const std::size_t before = b.errors().size();
      SceneBox box{readVec3(b, "min"), readVec3(b, "max")};
      if (b.errors().size() == before && !(box.min.array() < box.max.array()).all())
        b.addError("the box's min is not below its max on every axis", "max", "swap them or widen the box");
      g.box = box;
    }
  }
  if (r.has("cuts")) {
    ConfigReader list = r.child("cuts");
    if (expectArray(list)) {
      if (list.size() > 16) list.addError(formatString("%zu cuts, at most 16", list.size()));
      for (std::size_t i = 0; i < list.size() && i < 16; ++i) {
        ConfigReader c = list.at(i);
        if (!expectObject(c)) continue;
        c.knownKeys({"point", "normal", "kerf"});
        SceneCut cut;
        if (c.has("point") && c.node()["point"].is_string()) {
          if (c.string("point") == "centroid")
            cut.atCentroid = true;
          else
            c.addError("point \"" + c.string("point") + "\" is not a point", "point",
                       "give [x, y, z] (m) or \"centroid\" (of the voxels selected before the cuts)");
        } else {
          cut.point = readVec3(c, "point");
        }
        cut.normal = readDirection(c, "normal", cut.normal);
        if (!c.has("normal")) c.addError("missing required normal (the side kept)", "normal");
        cut.kerf = c.number("kerf", {.min = 0.0, .max = 0.05}, 0.0);
        g.cuts.push_back(cut);
      }
    }
  }
  g.largestComponent = r.boolean("largest_component", false);
  res.segment = std::move(g);
}

Json segmentJson(const SceneSegment& g) {
  Json j = {{"volume", g.volume}, {std::string(kSelects[static_cast<std::size_t>(g.select)]), g.value}};
  if (g.select == SceneSegment::Select::Label) j["label"] = static_cast<std::int64_t>(g.value);
  if (!g.outside.empty()) j["outside"] = g.outside;
  if (g.near) j["near"] = {{"volume", g.near->volume}, {"distance", g.near->distance}};
  if (g.box) j["box"] = {{"min", toJson(g.box->min)}, {"max", toJson(g.box->max)}};
  if (!g.cuts.empty()) {
    Json cuts = Json::array();
    for (const SceneCut& c : g.cuts)
      cuts.push_back({{"point", c.atCentroid ? Json("centroid") : toJson(c.point)},
                      {"normal", toJson(c.normal)},
                      {"kerf", c.kerf}});
    j["cuts"] = std::move(cuts);
  }
  j["largest_component"] = g.largestComponent;
  return j;
}

void readVoxels(ConfigReader& object, SceneObject& o) {
  ConfigReader r = object.child("voxels");
  if (!expectObject(r)) return;
  r.knownKeys({"volume", "threshold"});
  SceneVoxels v;
  v.volume = r.string("volume");
  v.threshold = r.number("threshold", {}, v.threshold);
  o.voxels = std::move(v);
}

void readBonePlacement(ConfigReader& haptics, SceneHapticsEngine& h) {
  ConfigReader r = haptics.child("bone_placement");
  if (!expectObject(r)) return;
  r.knownKeys({"fragment", "threshold", "coupling_stiffness", "coupling_damping",
               "coupling_angular_stiffness", "coupling_angular_damping", "mass", "density", "max_contacts",
               "contact_level", "iterations", "slop", "baumgarte", "max_torque", "target_pose"});
  SceneBonePlacement b;
  b.fragment = r.string("fragment");
  b.threshold = r.number("threshold", {}, b.threshold);
  b.couplingStiffness = readPositive(r, "coupling_stiffness", b.couplingStiffness, 1e6);
  b.couplingDamping = r.number("coupling_damping", {.min = 0.0, .max = 1e4}, b.couplingDamping);
  b.couplingAngularStiffness = readPositive(r, "coupling_angular_stiffness", b.couplingAngularStiffness, 1e4);
  b.couplingAngularDamping =
      r.number("coupling_angular_damping", {.min = 0.0, .max = 1e2}, b.couplingAngularDamping);
  b.mass = r.number("mass", {.min = 0.0, .max = 100.0}, b.mass);
  b.density = readPositive(r, "density", b.density, 1e5);
  b.maxContacts = static_cast<int>(r.integer("max_contacts", {.min = 1, .max = 4096}, b.maxContacts));
  b.iterations = static_cast<int>(r.integer("iterations", {.min = 1, .max = 100}, b.iterations));
  b.contactLevel = static_cast<int>(r.integer("contact_level", {.min = 0, .max = 4}, b.contactLevel));
  if (r.has("slop")) b.slop = r.number("slop", {.min = 0.0, .max = 0.01});
  b.baumgarte = r.number("baumgarte", {.min = 0.0, .max = 1.0}, b.baumgarte);
  b.maxTorque = readPositive(r, "max_torque", b.maxTorque, 100.0);
  if (r.has("target_pose")) b.target = readPose(r.child("target_pose"));
  h.bonePlacement = std::move(b);
}

void checkBonePlacement(const SceneDesc& scene, ConfigReader root) {
  ConfigReader resources = root.child("resources");
  for (const SceneResource& res : scene.resources)
    if (res.segment) {
      ConfigReader seg = resources.child(res.name).child("segment");
      if (!res.segment->volume.empty()) checkVolume(scene, seg, "volume", res.segment->volume, true);
      if (!res.segment->outside.empty()) checkVolume(scene, seg, "outside", res.segment->outside, true);
      if (res.segment->near && !res.segment->near->volume.empty()) {
        ConfigReader near = seg.child("near");
        checkVolume(scene, near, "volume", res.segment->near->volume, true);
      }
    }

  const auto& h = scene.engines.haptics;
  ConfigReader haptics = root.child("engines").child("haptics");
  const bool placing = h && h->renderer == SceneHapticsEngine::Renderer::BonePlacement;
  if (h && !placing && h->bonePlacement)
    haptics.addError("a \"bone_placement\" block belongs to the bone-placement renderer", "bone_placement",
                     "set \"renderer\": \"bone-placement\" or remove \"bone_placement\"");
  if (placing) {
    if (!h->bonePlacement) {
      haptics.addError("the bone-placement renderer needs its fragment", "bone_placement",
                       "add \"bone_placement\": {\"fragment\": \"<volume resource>\"}");
    } else if (!h->bonePlacement->fragment.empty()) {
      ConfigReader block = haptics.child("bone_placement");
      checkVolume(scene, block, "fragment", h->bonePlacement->fragment, false);
    }
    for (const char* other : {"tool_radius", "force_shading"})
      if (haptics.has(other))
        haptics.addError("the bone-placement renderer's tool is its fragment", other,
                         "remove \"" + std::string(other) + "\"");
    if (h->objects.size() != 1)
      haptics.addError(
          formatString("the bone-placement renderer places its fragment against one object, not %zu",
                       h->objects.size()),
          "objects", "name the fixed fragment");
  }

  ConfigReader objects = root.child("objects");
  for (std::size_t i = 0; i < scene.objects.size() && objects.isArray() && i < objects.size(); ++i) {
    const SceneObject& o = scene.objects[i];
    ConfigReader r = objects.at(i);
    const bool touched =
        placing && std::find(h->objects.begin(), h->objects.end(), o.name) != h->objects.end();
    if (touched && !o.voxels)
      r.addError("the bone-placement renderer touches voxels, and " + inQuotes(o.name) + " has none",
                 "voxels", "add \"voxels\": {\"volume\": \"<volume resource>\"}");
    if (!o.voxels) continue;
    if (!touched)
      r.addError("object " + inQuotes(o.name) + " has voxels but no bone-placement renderer touches them",
                 "voxels",
                 "set the haptics engine's \"renderer\": \"bone-placement\" with \"objects\": [" +
                     inQuotes(o.name) + "], or remove \"voxels\"");
    if (!o.voxels->volume.empty()) {
      ConfigReader v = r.child("voxels");
      checkVolume(scene, v, "volume", o.voxels->volume, false);
    }
    if (o.scale != 1.0)
      r.addError("voxels have the volume's own size", "scale",
                 "remove \"scale\" (the volume's spacing sets it)");
    const std::pair<const char*, bool> others[] = {{"dynamic", o.dynamic},
                                                   {"soft", o.soft.has_value()},
                                                   {"millable", o.millable.has_value()},
                                                   {"critical", o.critical.has_value()},
                                                   {"inclusion", o.inclusion.has_value()}};
    for (const auto& [key, set] : others)
      if (set)
        r.addError("the bone-placement renderer's fixed fragment is a rigid, static voxel model", key,
                   "remove \"" + std::string(key) + "\"");
    if (const SceneMaterial* m = scene.material(o.material); m != nullptr && m->haptic)
      r.addError("voxel contact is rigid (impulses, no spring): material " + inQuotes(o.material) +
                     "'s \"haptic\" block would not be used",
                 "material", "give the object a material without a \"haptic\" block");
  }
}

void writeVoxels(const SceneObject& o, Json& object) {
  if (o.voxels) object["voxels"] = {{"volume", o.voxels->volume}, {"threshold", o.voxels->threshold}};
}

void writeBonePlacement(const SceneBonePlacement& b, Json& haptics) {
  Json j = {{"fragment", b.fragment},
            {"threshold", b.threshold},
            {"coupling_stiffness", b.couplingStiffness},
            {"coupling_damping", b.couplingDamping},
            {"coupling_angular_stiffness", b.couplingAngularStiffness},
            {"coupling_angular_damping", b.couplingAngularDamping},
            {"mass", b.mass},
            {"density", b.density},
            {"max_contacts", b.maxContacts},
            {"iterations", b.iterations},
            {"contact_level", b.contactLevel},
            {"baumgarte", b.baumgarte},
            {"max_torque", b.maxTorque},
            {"target_pose", toJson(b.target)}};
  if (b.slop >= 0) j["slop"] = b.slop;
  haptics["bone_placement"] = std::move(j);
}

}  // namespace scene_parse
}  // namespace dm
