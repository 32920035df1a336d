// scene_surgery.cpp — the scene file's surgical keys: bone a burr mills
// ("millable"), the critical structures in it ("critical"), the burr
// renderer's tool ("burr"), a generated CT-like volume to mill ("phantom"),
// their checks against each other and the engines, and their JSON
// (docs/scene-format.md, "Bone surgery").
#include "scene_parse.hpp"

namespace dm::scene_parse {

namespace {

constexpr std::array<std::string_view, 2> kBurrShapes{"sphere", "cylinder"};

double readHardness(ConfigReader& r, double fallback) { return readPositive(r, "hardness", fallback, 1e12); }

// The block `key` of a part inside the bone ({"hardness": Pa}); nullopt when
// it is not an object (the error is recorded).
std::optional<double> readPartHardness(ConfigReader& object, std::string_view key, double fallback) {
  ConfigReader r = object.child(key);
  if (!expectObject(r)) return std::nullopt;
  r.knownKeys({"hardness"});
  return readHardness(r, fallback);
}

// A phantom's number keys: JSON key (under "hu" for the values), the
// member, CalvariumPhantom's field name (validate()'s error `where`) and range.
struct PhantomKey {
  std::string_view json;
  double CalvariumPhantom::*member;
  std::string_view field;
  double min, max;
};
constexpr double kHuMin = -32768.0, kHuMax = 32767.0;
constexpr std::array<PhantomKey, 12> kPhantomLengths{{
    {"spacing", &CalvariumPhantom::spacing, "spacing", 0.0, 0.01},
    {"half_width", &CalvariumPhantom::halfWidth, "halfWidth", 0.0, 1.0},
    {"above", &CalvariumPhantom::above, "above", 0.0, 1.0},
    {"below", &CalvariumPhantom::below, "below", 0.0, 1.0},
    {"radius", &CalvariumPhantom::radius, "radius", 0.0, 10.0},
    {"scalp", &CalvariumPhantom::scalp, "scalp", 0.0, 0.1},
    {"outer_table", &CalvariumPhantom::outerTable, "outerTable", 0.0, 0.1},
    {"diploe", &CalvariumPhantom::diploe, "diploe", 0.0, 0.1},
    {"inner_table", &CalvariumPhantom::innerTable, "innerTable", 0.0, 0.1},
    {"dura", &CalvariumPhantom::dura, "dura", 0.0, 0.1},
    {"texture_hu", &CalvariumPhantom::textureHu, "textureHu", 0.0, kHuMax},
    {"texture_scale", &CalvariumPhantom::textureScale, "textureScale", 0.0, 0.1},
}};
constexpr std::array<PhantomKey, 6> kPhantomValues{{
    {"air", &CalvariumPhantom::airHu, "airHu", kHuMin, kHuMax},
    {"soft_tissue", &CalvariumPhantom::softTissueHu, "softTissueHu", kHuMin, kHuMax},
    {"cortical", &CalvariumPhantom::corticalHu, "corticalHu", kHuMin, kHuMax},
    {"diploe", &CalvariumPhantom::diploeHu, "diploeHu", kHuMin, kHuMax},
    {"dura", &CalvariumPhantom::duraHu, "duraHu", kHuMin, kHuMax},
    {"brain", &CalvariumPhantom::brainHu, "brainHu", kHuMin, kHuMax},
}};
constexpr std::array<std::string_view, 1> kPhantomKinds{"calvarium"};
// Largest generated scan: 1 GiB of int16 voxels.
constexpr double kPhantomMaxBytes = 1024.0 * 1024.0 * 1024.0;

template <std::size_t N>
std::vector<std::string_view> jsonKeys(const std::array<PhantomKey, N>& keys) {
  std::vector<std::string_view> out;
  for (const PhantomKey& k : keys) out.push_back(k.json);
  return out;
}

}  // namespace

void readPhantom(ConfigReader& resource, SceneResource& res) {
  ConfigReader r = resource.child("phantom");
  if (!expectObject(r)) return;
  std::vector<std::string_view> known = jsonKeys(kPhantomLengths);
  for (std::string_view k : {"kind", "hu", "seed"}) known.push_back(k);
  r.knownKeys(known);
  const std::size_t before = r.errors().size();
  readEnum<int>(r, "kind", kPhantomKinds);
  CalvariumPhantom p;
  for (const PhantomKey& k : kPhantomLengths)
    p.*k.member = r.number(k.json, {.min = k.min, .max = k.max}, p.*k.member);
  if (r.has("hu")) {
    ConfigReader hu = r.child("hu");
    if (expectObject(hu)) {
      hu.knownKeys(jsonKeys(kPhantomValues));
      for (const PhantomKey& k : kPhantomValues)
        p.*k.member = hu.number(k.json, {.min = k.min, .max = k.max}, p.*k.member);
    }
  }
  p.seed = static_cast<std::uint32_t>(r.integer("seed", {.min = 0, .max = 4294967295.0}, p.seed));
  if (r.errors().size() != before) return;
  if (auto s = validate(p); !s) {
    // Back from the C++ field to the key the file wrote.
    std::string key;
    for (const PhantomKey& k : kPhantomLengths)
      if (k.field == s.error().where) key = k.json;
    for (const PhantomKey& k : kPhantomValues)
      if (k.field == s.error().where) key = "hu/" + std::string(k.json);
    const std::string& what = s.error().what;
    const std::string field = s.error().where + " ";  // validate() says "<field> <what>"
    r.addError(!key.empty() && what.starts_with(field) ? what.substr(field.size()) : what, key,
               "see docs/phantoms.md");
    return;
  }
  const Vec3i n = calvariumPhantomDims(p);
  const double bytes = 2.0 * n.x() * n.y() * n.z();
  if (bytes > kPhantomMaxBytes) {
    r.addError(formatString("the scan would be %d×%d×%d voxels (%.3g GiB), more than 1 GiB", n.x(), n.y(),
                            n.z(), bytes / kPhantomMaxBytes),
               "spacing", "use larger voxels or a smaller patch");
    return;
  }
  res.phantom = p;
}

Json phantomJson(const CalvariumPhantom& p) {
  Json j = {{"kind", kPhantomKinds[0]}, {"seed", p.seed}};
  for (const PhantomKey& k : kPhantomLengths) j[std::string(k.json)] = p.*k.member;
  Json hu = Json::object();
  for (const PhantomKey& k : kPhantomValues) hu[std::string(k.json)] = p.*k.member;
  j["hu"] = std::move(hu);
  return j;
}

void readMillable(ConfigReader& object, SceneObject& o) {
  ConfigReader r = object.child("millable");
  if (!expectObject(r)) return;
  SceneMillable m;
  if (r.has("volume")) {
    // The bone from a CT's intensities on the CT's own grid.
    r.knownKeys({"volume", "empty", "full", "hardness"});
    std::size_t before = r.errors().size();
    m.volume = r.string("volume");
    if (r.errors().size() == before && m.volume.empty())
      r.addError("no volume named", "volume", "name a \"volume\" resource (the CT)");
    before = r.errors().size();
    m.empty = r.number("empty");
    m.full = r.number("full");
    if (r.errors().size() == before && !(m.empty < m.full))
      r.addError(formatString("the empty intensity (%g) is not below the full one (%g)", m.empty, m.full),
                 "full", "give the intensity of solid bone above that of no bone");
  } else {
    r.knownKeys({"voxel_size", "hardness"});
    m.voxelSize = readPositive(r, "voxel_size", {}, 0.01);
  }
  m.hardness = readHardness(r, m.hardness);
  o.millable = m;
}

void readCritical(ConfigReader& object, SceneObject& o) {
  if (auto h = readPartHardness(object, "critical", SceneCritical{}.hardness)) o.critical = SceneCritical{*h};
}

void readInclusion(ConfigReader& object, SceneObject& o) {
  if (auto h = readPartHardness(object, "inclusion", SceneInclusion{}.hardness))
    o.inclusion = SceneInclusion{*h};
}

void readBurr(ConfigReader& haptics, SceneHapticsEngine& h) {
  ConfigReader r = haptics.child("burr");
  if (!expectObject(r)) return;
  SceneBurr b;
  b.shape = readEnum<SceneBurr::Shape>(r, "shape", kBurrShapes, b.shape).value_or(b.shape);
  if (b.shape == SceneBurr::Shape::Cylinder)
    r.knownKeys({"shape", "radius", "half_length", "rpm", "wear", "walk", "vibration", "vibration_hz",
                 "warning_distance"});
  else
    r.knownKeys({"shape", "radius", "rpm", "wear", "walk", "vibration", "vibration_hz", "warning_distance"});
  b.radius = readPositive(r, "radius", {}, 0.05);
  if (b.shape == SceneBurr::Shape::Cylinder) b.halfLength = readPositive(r, "half_length", {}, 0.05);
  b.rpm = r.number("rpm", {.min = 0.0, .max = 500000.0}, b.rpm);
  b.wear = r.number("wear", {.min = 0.0, .max = 10.0}, b.wear);
  b.walk = r.number("walk", {.min = 0.0, .max = 10.0}, b.walk);
  b.vibration = r.number("vibration", {.min = 0.0, .max = 10.0}, b.vibration);
  const std::size_t before = r.errors().size();
  b.vibrationHz = r.number("vibration_hz", {.min = 0.0, .max = 5000.0}, b.vibrationHz);
  if (r.errors().size() == before && !(b.vibrationHz < 0.5 * h.rateHz))
    r.addError(
        formatString("vibration at %g Hz is not below half the haptic rate (%g Hz)", b.vibrationHz, h.rateHz),
        "vibration_hz", "lower it, or raise the haptics engine's rate_hz");
  b.warningDistance = r.number("warning_distance", {.min = 0.0, .max = 0.1}, b.warningDistance);
  h.burr = b;
}

void checkSurgery(const SceneDesc& scene, ConfigReader root) {
  ConfigReader objects = root.child("objects");
  ConfigReader haptics = root.child("engines").child("haptics");
  const auto& h = scene.engines.haptics;
  const bool burr = h && h->renderer == SceneHapticsEngine::Renderer::Burr;
  if (h && burr) {
    if (!h->burr)
      haptics.addError("the burr renderer needs its tool", "burr",
                       "add \"burr\": {\"shape\": \"sphere\", \"radius\": <m>}");
    if (haptics.has("tool_radius"))
      haptics.addError("the burr renderer's tool is its \"burr\" block", "tool_radius",
                       "remove \"tool_radius\"");
    if (h->forceShading)
      haptics.addError("the burr renderer has no force shading (the bone's surface is its voxels')",
                       "force_shading", "remove \"force_shading\"");
    const SceneObject* bone = h->objects.size() == 1 ? scene.object(h->objects[0]) : nullptr;
    if (h->objects.size() != 1)
      haptics.addError(formatString("the burr renderer mills one object, not %zu", h->objects.size()),
                       "objects", "name the one millable object");
    else if (bone != nullptr && !bone->millable)
      haptics.addError("object " + inQuotes(bone->name) + " is not millable", "objects",
                       "give it \"millable\": {\"voxel_size\": <m>}");
  } else if (h && h->burr) {
    haptics.addError("a \"burr\" block without the burr renderer", "burr",
                     "set \"renderer\": \"burr\", or remove \"burr\"");
  }
  for (std::size_t i = 0; i < scene.objects.size() && objects.isArray() && i < objects.size(); ++i) {
    const SceneObject& o = scene.objects[i];
    ConfigReader r = objects.at(i);
    if (o.millable) {
      const bool milled = burr && std::find(h->objects.begin(), h->objects.end(), o.name) != h->objects.end();
      if (!milled)
        r.addError("millable object " + inQuotes(o.name) + " but no burr renderer mills it", "millable",
                   "set the haptics engine's \"renderer\": \"burr\" with \"objects\": [" + inQuotes(o.name) +
                       "], or remove \"millable\"");
      if (o.dynamic)
        r.addError("a millable object stays where it is (its voxels change, not its pose)", "dynamic",
                   "remove \"dynamic\"");
      if (!o.millable->volume.empty()) {
        ConfigReader m = r.child("millable");
        const SceneResource* res = scene.resource(o.millable->volume);
        if (res == nullptr || res->type != SceneResource::Type::Volume) {
          std::string names;
          for (const SceneResource& x : scene.resources)
            if (x.type == SceneResource::Type::Volume)
              names += (names.empty() ? "" : ", ") + inQuotes(x.name);
          m.addError(
              "resource " + inQuotes(o.millable->volume) + (res ? " is not a volume" : " is not defined"),
              "volume", names.empty() ? "define a \"volume\" resource (the CT)" : "use one of: " + names);
        }
        if (o.scale != 1.0)
          r.addError("a bone from a volume has the volume's own size", "scale",
                     "remove \"scale\" (the volume's spacing sets it)");
      }
      for (const char* key : {"critical", "inclusion"})
        if (r.has(key))
          r.addError("an object is either the bone (\"millable\") or a part inside it", key,
                     "make the part an object of its own");
      if (const SceneMaterial* m = scene.material(o.material); m != nullptr && m->haptic) {
        if (m->haptic->staticFriction > 0 || m->haptic->dynamicFriction > 0)
          r.addError(
              "the burr renderer has no friction: the spinning burr's walk stands for it", "material",
              "set the friction of material " + inQuotes(o.material) + " to 0 and tune the burr's \"walk\"");
      }
    }
    const char* part = o.critical ? "critical" : o.inclusion ? "inclusion" : nullptr;
    if (part != nullptr) {
      const std::string key(part);
      if (!burr)
        r.addError(key + " object " + inQuotes(o.name) + " but no burr renderer", key,
                   "set the haptics engine's \"renderer\": \"burr\", or remove \"" + key + "\"");
      if (o.dynamic) r.addError("a part inside the bone stays where it is", "dynamic", "remove \"dynamic\"");
      if (o.critical && o.inclusion)
        r.addError("an object is a critical structure or an inclusion, not both", "inclusion",
                   "remove one of them");
    }
  }
}

void writeSurgery(const SceneObject& o, Json& object) {
  if (o.millable)
    object["millable"] = o.millable->volume.empty() ? nlohmann::json{{"voxel_size", o.millable->voxelSize},
                                                                     {"hardness", o.millable->hardness}}
                                                    : nlohmann::json{{"volume", o.millable->volume},
                                                                     {"empty", o.millable->empty},
                                                                     {"full", o.millable->full},
                                                                     {"hardness", o.millable->hardness}};
  if (o.critical) object["critical"] = {{"hardness", o.critical->hardness}};
  if (o.inclusion) object["inclusion"] = {{"hardness", o.inclusion->hardness}};
}

void writeBurr(const SceneBurr& b, Json& haptics) {
  Json j = {{"shape", enumName(b.shape, kBurrShapes)},
            {"radius", b.radius},
            {"rpm", b.rpm},
            {"wear", b.wear},
            {"walk", b.walk},
            {"vibration", b.vibration},
            {"vibration_hz", b.vibrationHz},
            {"warning_distance", b.warningDistance}};
  if (b.shape == SceneBurr::Shape::Cylinder) j["half_length"] = b.halfLength;
  haptics["burr"] = std::move(j);
}

}  // namespace dm::scene_parse
