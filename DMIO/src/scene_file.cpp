#include <dm/core/endpoint.hpp>
#include <dm/core/filesystem.hpp>
#include <dm/core/units.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/io/scene_file.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <exception>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <utility>

#include "scene_parse.hpp"

namespace dm {

namespace fs = std::filesystem;

namespace {

using namespace scene_parse;

constexpr std::string_view kFormatName = "dmplatform-scene";
constexpr std::size_t kMaxDepth = 64;
constexpr std::size_t kMaxSceneBytes = std::size_t{16} << 20;
// Past this many problems, dangling names get no "did you mean".
constexpr std::size_t kMaxSuggestions = 200;

constexpr std::array<std::string_view, 5> kResourceTypes{"mesh", "volume", "isosurface", "shape", "image"};
constexpr std::array<std::string_view, 6> kShapes{"sphere",   "box",   "capsule",
                                                  "cylinder", "plane", "compound"};
// A compound's parts: the first four of kShapes, in the same order.
constexpr std::array<std::string_view, 4> kPartShapes{"sphere", "box", "capsule", "cylinder"};
constexpr std::array<std::string_view, 2> kMaterialModels{"blinn-phong", "pbr"};
constexpr std::array<std::string_view, 3> kVolumeModes{"composite", "mip", "slice"};
constexpr std::array<std::string_view, 3> kAxes{"axial", "coronal", "sagittal"};
constexpr std::array<std::string_view, 3> kLightTypes{"directional", "point", "spot"};
constexpr std::array<std::string_view, 2> kProjections{"perspective", "orthographic"};
constexpr std::array<std::string_view, 8> kRenderers{
    "god-object", "vps", "sphere-tree", "burr", "needle", "bone-placement", "none", "punch"};

// Finds keys that occur twice in one JSON object: nlohmann keeps only the
// last, which would silently drop e.g. one of two resources named "skin".
// A SAX pass (no document built) tracks the path; each repeat is recorded
// at its parent object through `root`.
class DuplicateKeyFinder final : public Json::json_sax_t {
 public:
  struct Frame {
    bool array = false;
    std::size_t index = 0;
    std::string key;
    std::set<std::string> keys;
  };
  struct Step {
    bool array = false;
    std::size_t index = 0;
    std::string key;
  };
  std::vector<std::pair<std::vector<Step>, std::string>> found;  // path to the object, repeated key

  bool null() override { return element(); }
  bool boolean(bool) override { return element(); }
  bool number_integer(number_integer_t) override { return element(); }
  bool number_unsigned(number_unsigned_t) override { return element(); }
  bool number_float(number_float_t, const string_t&) override { return element(); }
  bool string(string_t&) override { return element(); }
  bool binary(binary_t&) override { return element(); }
  bool start_object(std::size_t) override { return open(false); }
  bool start_array(std::size_t) override { return open(true); }
  bool end_object() override { return close(); }
  bool end_array() override { return close(); }
  bool key(string_t& k) override {
    if (frames_.empty()) return true;
    Frame& f = frames_.back();
    f.key = k;
    if (!f.keys.insert(k).second && found.size() < 100) {
      std::vector<Step> path;
      for (std::size_t i = 0; i + 1 < frames_.size(); ++i)
        path.push_back({frames_[i].array, frames_[i].index, frames_[i].key});
      found.emplace_back(std::move(path), k);
    }
    return true;
  }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception&) override {
    return false;
  }

 private:
  bool element() {
    if (!frames_.empty() && frames_.back().array) ++frames_.back().index;
    return true;
  }
  bool open(bool array) {
    frames_.push_back({array, 0, {}, {}});
    return true;
  }
  bool close() {
    if (!frames_.empty()) frames_.pop_back();
    return element();
  }
  std::vector<Frame> frames_;
};

void reportDuplicateKeys(std::string_view text, ConfigReader& root) {
  DuplicateKeyFinder finder;
  (void)Json::sax_parse(text, &finder, nlohmann::detail::input_format_t::json, /*strict=*/true,
                        /*ignore_comments=*/true);
  for (const auto& [path, key] : finder.found) {
    ConfigReader at = root;
    for (std::size_t i = 0; i < path.size(); ++i)
      at = path[i].array ? at.at(path[i].index) : at.child(path[i].key);
    at.addError("key " + inQuotes(key) + " appears more than once in this object (only the last one counts)",
                key, "remove or rename one of them");
  }
}

// Rejects nesting deeper than kMaxDepth before nlohmann sees the text, so no
// recursive walk (dump, destruction) can run out of stack.
std::optional<std::size_t> tooDeepAt(std::string_view text) {
  std::size_t depth = 0;
  bool inString = false, escaped = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (inString) {
      if (escaped)
        escaped = false;
      else if (c == '\\')
        escaped = true;
      else if (c == '"')
        inString = false;
    } else if (c == '"') {
      inString = true;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxDepth) return i + 1;  // 1-based, like Config::parse
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
  return std::nullopt;
}

class SceneParser {
 public:
  SceneParser(ConfigReader root, fs::path baseDir) : root_(std::move(root)), baseDir_(std::move(baseDir)) {
    scene_.baseDir = baseDir_;
  }

  // False when the document is not a scene of a version this build reads
  // (then nothing else is checked: its other keys would only add noise).
  bool header() {
    if (!root_.isObject()) {
      root_.addError(std::string("a scene is a JSON object, got ") + root_.node().type_name(), {},
                     "start from examples/scenes/head_probe.json");
      return false;
    }
    const std::size_t before = root_.errors().size();
    const std::string format = root_.string("format");
    if (root_.errors().size() == before && format != kFormatName) {
      root_.addError("format is " + inQuotes(format) + ", not " + inQuotes(kFormatName), "format",
                     "this is not a scene file, or set \"format\": \"dmplatform-scene\"");
      return false;
    }
    if (root_.has("version") && root_.node()["version"].is_number_integer()) {
      const long long v = root_.integer("version");
      if (v != 1 && v != kSceneFormatVersion) {
        root_.addError("unsupported scene version " + std::to_string(v), "version",
                       "this build reads versions 1 and " + std::to_string(kSceneFormatVersion));
        badVersion_ = true;
        return false;
      }
      version_ = static_cast<int>(v);
    } else {
      (void)root_.integer("version");
    }
    return true;
  }

  void body() {
    root_.knownKeys({"format", "version", "name", "resources", "materials", "objects", "volumes", "lights",
                     "cameras", "devices", "engines", "outputs", "scripts", "fluids"});
    scene_.name = root_.string("name", std::string());
    resources();
    materials();
    objects();
    volumes();
    lights();
    devices();
    cameras();
    engines();
    outputs();
    if (v2Key(root_, "scripts"))
      readScripts(root_, scene_, [this](ConfigReader& r, const std::string& source, std::string_view key) {
        return resolveSource(r, source, key);
      });
    if (v2Key(root_, "fluids")) readFluids(root_, scene_);
    physicsBodies();
    checkSurgery(scene_, root_);
    checkSoft(scene_, root_);
    checkMembranes(scene_, root_);
    checkIgtl(scene_, root_);
    checkTools6Dof(scene_, root_);
    checkBonePlacement(scene_, root_);
    checkSegmentation(scene_, root_);
  }

  bool badVersion() const { return badVersion_; }
  SceneDesc& scene() { return scene_; }
  ConfigReader& root() { return root_; }

 private:
  using Type = SceneResource::Type;
  using NameIndex = std::map<std::string, std::size_t>;

  // A source leads only into the scene's folder, the mounts, DM_DATA_PATH
  // and the allowed roots (FileSystem::confine): the scene may come from
  // anyone, so it must not make us read any file of the machine.
  fs::path resolveSource(ConfigReader& r, const std::string& source, std::string_view key = "source") {
    std::string named = source;
    const std::size_t colon = source.find(':');
    if (colon != std::string::npos && colon >= 2 && source.find('/') > colon) {
      auto p = FileSystem::global().resolve(source);
      if (!p) {
        // FileSystem has no query for its mounts: its error names an unknown one.
        if (p.error().what.rfind("unknown mount", 0) == 0) r.addError(p.error().what, key, p.error().hint);
        return {};
      }
      named = p->string();
    }
    auto real = FileSystem::global().confine(baseDir_, named, std::string(key));
    if (!real) {
      r.addError(real.error().what, key, real.error().hint);
      return {};
    }
    return *real;
  }

  void readSource(ConfigReader& r, SceneResource& res) {
    const std::size_t before = r.errors().size();
    res.source = r.string("source");
    if (r.errors().size() != before) return;
    if (res.source.empty()) {
      r.addError("source is empty", "source", "give a file path or \"mount:name\"");
      return;
    }
    res.path = resolveSource(r, res.source);
  }

  // A primitive's size keys for `shape` (sphere, box, capsule, cylinder,
  // plane) into radius, height and half extents.
  static void shapeSize(ConfigReader& r, SceneResource::Shape s, double& radius, double& height, Vec3& half) {
    using S = SceneResource::Shape;
    if (s == S::Sphere || s == S::Capsule || s == S::Cylinder) radius = readPositive(r, "radius", {});
    if (s == S::Capsule || s == S::Cylinder) height = readPositive(r, "height", {});
    if (s == S::Box || s == S::Plane) {
      const std::size_t n = s == S::Box ? 3 : 2;
      const std::size_t before = r.errors().size();
      const std::vector<double> h = r.numbers("half_extents", n);
      if (r.errors().size() == before) {
        for (std::size_t i = 0; i < n; ++i) half[static_cast<Eigen::Index>(i)] = h[i];
        if (!(half.head(n).minCoeff() > 0.0))
          r.addError("half extents must be greater than 0", "half_extents",
                     n == 3 ? "give [hx, hy, hz] in metres" : "a plane takes [hx, hy] in metres");
      }
    }
  }

  void shape(ConfigReader& r, SceneResource& res) {
    const auto s = readEnum<SceneResource::Shape>(r, "shape", kShapes);
    if (!s) return;
    res.shape = *s;
    using S = SceneResource::Shape;
    switch (*s) {
      case S::Sphere:
        r.knownKeys({"type", "shape", "radius", "subdivisions"});
        break;
      case S::Box:
      case S::Plane:
        r.knownKeys({"type", "shape", "half_extents", "subdivisions"});
        break;
      case S::Capsule:
      case S::Cylinder:
        r.knownKeys({"type", "shape", "radius", "height", "subdivisions"});
        break;
      case S::Compound:
        r.knownKeys({"type", "shape", "parts", "subdivisions"});
        if (!r.has("parts"))
          r.addError("a compound shape needs its parts", "parts",
                     "give \"parts\": [{\"shape\": \"box\", \"half_extents\": [...], \"pose\": {...}}, ...]");
        else if (v2Key(r, "parts"))
          compoundParts(r, res);
        break;
    }
    shapeSize(r, *s, res.radius, res.height, res.halfExtents);
    res.subdivisions = static_cast<int>(r.integer("subdivisions", {.min = 0, .max = 8}, 3));
  }

  // A compound's "parts": 1..64 primitives, each placed by its pose.
  void compoundParts(ConfigReader& r, SceneResource& res) {
    ConfigReader list = r.child("parts");
    if (!expectArray(list)) return;
    if (list.size() == 0 || list.size() > 64) {
      r.addError(formatString("%zu parts: a compound has 1 to 64", list.size()), "parts",
                 "give at least one part (a single part is that shape, placed)");
      return;
    }
    for (std::size_t i = 0; i < list.size(); ++i) {
      ConfigReader p = list.at(i);
      if (!expectObject(p)) continue;
      p.knownKeys({"shape", "radius", "height", "half_extents", "pose"});
      SceneResource::Part part;
      const auto s = readEnum<SceneResource::Shape>(p, "shape", kPartShapes);
      if (!s) continue;
      part.shape = *s;
      for (const char* key : {"radius", "height", "half_extents"}) {
        const bool wanted =
            std::string_view(key) == "half_extents" ? part.shape == SceneResource::Shape::Box
            : std::string_view(key) == "radius"
                ? part.shape != SceneResource::Shape::Box
                : part.shape == SceneResource::Shape::Capsule || part.shape == SceneResource::Shape::Cylinder;
        if (!wanted && p.has(key))
          p.addError("a " + std::string(kPartShapes[static_cast<std::size_t>(part.shape)]) +
                         " part has no \"" + key + "\"",
                     key, "remove it");
      }
      shapeSize(p, part.shape, part.radius, part.height, part.halfExtents);
      if (p.has("pose")) part.pose = readPose(p.child("pose"));
      res.parts.push_back(part);
    }
  }

  void resources() {
    ConfigReader sec = root_.child("resources");
    if (!expectObject(sec)) return;
    std::vector<std::pair<std::size_t, ConfigReader>> isosurfaces;
    for (auto it = sec.node().begin(); it != sec.node().end(); ++it) {
      ConfigReader r = sec.child(it.key());
      if (!expectObject(r)) continue;
      SceneResource res;
      res.name = it.key();
      if (res.name.empty()) r.addError("empty resource name", {}, "give every resource a name");
      const auto type = readEnum<Type>(r, "type", kResourceTypes);
      if (!type) continue;
      res.type = *type;
      switch (*type) {
        case Type::Mesh: {
          r.knownKeys({"type", "source", "unit", "scale"});
          readSource(r, res);
          const std::size_t before = r.errors().size();
          res.unit = r.string("unit", std::string("m"));
          if (r.errors().size() == before)
            if (auto m = metresPerUnit(res.unit); !m) r.addError(m.error().what, "unit", m.error().hint);
          res.scale = readPositive(r, "scale", 1.0);
          break;
        }
        case Type::Volume:
          if (r.has("segment") && v2Key(r, "segment")) {
            r.knownKeys({"type", "segment"});
            for (const char* other : {"source", "phantom"})
              if (r.has(other))
                r.addError(
                    "a volume is read from \"source\", generated by \"phantom\" or made by \"segment\"",
                    other, "keep only one of them");
            readSegment(r, res);
            break;
          }
          if (r.has("phantom") && v2Key(r, "phantom")) {
            r.knownKeys({"type", "phantom"});
            if (r.has("source"))
              r.addError("a volume is read from \"source\" or generated by \"phantom\", not both", "source",
                         "remove one of them");
            readPhantom(r, res);
            break;
          }
          r.knownKeys({"type", "source"});
          readSource(r, res);
          break;
        case Type::Image:
          r.knownKeys({"type", "source"});
          readSource(r, res);
          break;
        case Type::Isosurface:
          r.knownKeys({"type", "volume", "level", "largest_component", "smooth", "smooth_max_displacement",
                       "downsample"});
          res.volume = r.string("volume");
          res.level = r.number("level");
          res.largestComponent = r.boolean("largest_component", false);
          res.smooth = static_cast<int>(r.integer("smooth", {.min = 0, .max = 100}, 0));
          if (v2Key(r, "smooth_max_displacement")) {
            res.smoothMaxDisplacement = readPositive(r, "smooth_max_displacement", {}, 0.1);
            if (res.smooth == 0)
              r.addError("\"smooth_max_displacement\" bounds smoothing, but \"smooth\" is 0",
                         "smooth_max_displacement", "set \"smooth\": <iterations>, or remove the bound");
          }
          res.downsample = static_cast<int>(r.integer("downsample", {.min = 1, .max = 8}, 1));
          isosurfaces.emplace_back(scene_.resources.size(), r);
          break;
        case Type::Shape:
          shape(r, res);
          break;
      }
      scene_.resources.push_back(std::move(res));
    }
    for (auto& [i, r] : isosurfaces)
      if (!scene_.resources[i].volume.empty())
        checkResource(r, "volume", scene_.resources[i].volume, {Type::Volume}, "a volume");
  }

  // Resources come from a JSON object, so they are sorted by name.
  const SceneResource* findResource(const std::string& name) const {
    const auto it = std::lower_bound(scene_.resources.begin(), scene_.resources.end(), name,
                                     [](const SceneResource& x, const std::string& n) { return x.name < n; });
    return it != scene_.resources.end() && it->name == name ? &*it : nullptr;
  }

  // A reference to a resource of one of `types`; records a dangling or
  // mistyped reference with the closest fitting name.
  void checkResource(ConfigReader& r, std::string_view key, const std::string& name,
                     std::initializer_list<Type> types, const char* kind) {
    auto fits = [&](const SceneResource& x) {
      return std::find(types.begin(), types.end(), x.type) != types.end();
    };
    const SceneResource* res = findResource(name);
    if (res && fits(*res)) return;
    std::vector<std::string> fitting;
    for (const SceneResource& x : scene_.resources)
      if (fits(x)) fitting.push_back(x.name);
    if (res) {
      r.addError("resource " + inQuotes(name) + " is " + (res->type == Type::Image ? "an " : "a ") +
                     enumName(res->type, kResourceTypes) + ", not " + kind,
                 key, fitting.empty() ? "define one under \"resources\"" : "use one of: " + joined(fitting));
      return;
    }
    dangling(r, key, "resource", name, fitting, "resources");
  }

  // At most 10 quoted names, comma-separated.
  static std::string joined(const std::vector<std::string>& names) {
    std::string s;
    for (std::size_t i = 0; i < names.size() && i < 10; ++i)
      s += (s.empty() ? "" : ", ") + inQuotes(names[i]);
    if (names.size() > 10) s += ", ...";
    return s;
  }

  static void dangling(ConfigReader& r, std::string_view key, const char* kind, const std::string& name,
                       const std::vector<std::string>& candidates, const char* section) {
    // Suggestions cost an edit distance per candidate: a file with hundreds
    // of mistakes gets them for the first ones only.
    const std::string near =
        r.errors().size() < kMaxSuggestions ? nearestName(name, candidates) : std::string();
    r.addError(std::string("no ") + kind + " " + inQuotes(name), key,
               !near.empty() ? "did you mean " + inQuotes(near) + "?"
                             : std::string("define it under \"") + section + "\"");
  }

  // A reference to a named element (objects, devices, cameras by name →
  // index); records a dangling one.
  static bool checkName(ConfigReader& r, std::string_view key, const std::string& name,
                        const NameIndex& index, const char* kind, const char* section) {
    if (index.count(name)) return true;
    std::vector<std::string> names;
    if (r.errors().size() < kMaxSuggestions)
      for (const auto& entry : index) names.push_back(entry.first);
    dangling(r, key, kind, name, names, section);
    return false;
  }

  // "name": required, non-empty, unique within `index` (which maps it to
  // `position`, the element's index in its list).
  static std::string uniqueName(ConfigReader& r, NameIndex& index, std::size_t position) {
    const std::size_t before = r.errors().size();
    std::string name = r.string("name");
    if (r.errors().size() != before) return name;
    if (name.empty()) {
      r.addError("name is empty", "name", "give it a unique name");
      return name;
    }
    const std::string& path = r.path();
    if (auto [it, fresh] = index.emplace(name, position); !fresh)
      r.addError("duplicate name " + inQuotes(name) + " (also used by " +
                     path.substr(0, path.rfind('/') + 1) + std::to_string(it->second) + ")",
                 "name", "names must be unique: rename one of them");
    return name;
  }

  void imageRef(ConfigReader& r, std::string_view key, std::string& out) {
    const std::size_t before = r.errors().size();
    out = r.string(key, std::string());
    if (r.errors().size() == before && r.has(key)) checkResource(r, key, out, {Type::Image}, "an image");
  }

  void materials() {
    ConfigReader sec = root_.child("materials");
    if (!expectObject(sec)) return;
    for (auto it = sec.node().begin(); it != sec.node().end(); ++it) {
      ConfigReader r = sec.child(it.key());
      if (!expectObject(r)) continue;
      SceneMaterial m;
      m.name = it.key();
      if (m.name.empty()) r.addError("empty material name", {}, "give every material a name");
      const auto model =
          readEnum<SceneMaterial::Model>(r, "model", kMaterialModels, SceneMaterial::Model::BlinnPhong);
      if (!model) continue;
      m.model = *model;
      if (m.model == SceneMaterial::Model::BlinnPhong) {
        r.knownKeys({"model", "color", "specular", "shininess", "emissive", "texture", "normal_map",
                     "height_map", "height_scale", "haptic"});
        m.specular =
            readColor(r, "specular", {m.specular.x(), m.specular.y(), m.specular.z(), 1.0}, false).head<3>();
        m.shininess = r.number("shininess", {.min = 1.0, .max = 10000.0}, m.shininess);
      } else {
        r.knownKeys({"model", "color", "metallic", "roughness", "emissive", "texture", "normal_map",
                     "height_map", "height_scale", "haptic"});
        m.metallic = r.number("metallic", {.min = 0.0, .max = 1.0}, m.metallic);
        m.roughness = r.number("roughness", {.min = 0.0, .max = 1.0}, m.roughness);
      }
      m.color = readColor(r, "color", m.color, true);
      m.emissive =
          readColor(r, "emissive", Vec4(0.0, 0.0, 0.0, 1.0), false, std::numeric_limits<double>::infinity())
              .head<3>();
      imageRef(r, "texture", m.texture);
      imageRef(r, "normal_map", m.normalMap);
      imageRef(r, "height_map", m.heightMap);
      // The relief depth has no sensible default, so it comes with the map
      // (required), and never without it.
      if (r.has("height_map"))
        m.heightScale = r.number("height_scale", {.min = 0.0, .max = 1.0});
      else if (r.has("height_scale"))
        r.addError("height_scale without a height_map", "height_scale",
                   "add \"height_map\" (an image resource) or remove \"height_scale\"");
      ConfigReader h = r.child("haptic");
      if (expectObject(h)) {
        h.knownKeys({"stiffness", "damping", "static_friction", "dynamic_friction"});
        SceneHapticMaterial hm;
        hm.stiffness = readPositive(h, "stiffness", {}, 1e6);
        hm.damping = h.number("damping", {.min = 0.0, .max = 1e4}, 0.0);
        hm.staticFriction = h.number("static_friction", {.min = 0.0, .max = 10.0}, 0.0);
        const std::size_t before = h.errors().size();
        hm.dynamicFriction = h.number("dynamic_friction", {.min = 0.0, .max = 10.0}, hm.staticFriction);
        if (h.errors().size() == before && hm.dynamicFriction > hm.staticFriction)
          h.addError(formatString("dynamic friction %g is larger than static friction %g", hm.dynamicFriction,
                                  hm.staticFriction),
                     "dynamic_friction", "use dynamic_friction <= static_friction");
        m.haptic = hm;
      }
      materialIndex_.emplace(m.name, scene_.materials.size());
      scene_.materials.push_back(std::move(m));
    }
  }

  void objects() {
    ConfigReader sec = root_.child("objects");
    if (!expectArray(sec)) return;
    for (std::size_t i = 0; i < sec.size(); ++i) {
      ConfigReader r = sec.at(i);
      if (!expectObject(r)) continue;
      r.knownKeys({"name",     "mesh",     "render_mesh",      "material", "pose",
                   "scale",    "visible",  "haptic",           "dynamic",  "mass",
                   "density",  "velocity", "angular_velocity", "collide",  "contact",
                   "millable", "critical", "inclusion",        "soft",     "voxels",
                   "membrane"});
      SceneObject o;
      o.name = uniqueName(r, objectIndex_, scene_.objects.size());
      std::size_t before = r.errors().size();
      o.mesh = r.string("mesh");
      if (r.errors().size() == before)
        checkResource(r, "mesh", o.mesh, {Type::Mesh, Type::Isosurface, Type::Shape},
                      "a mesh, isosurface or shape");
      if (r.has("render_mesh")) {
        before = r.errors().size();
        o.renderMesh = r.string("render_mesh");
        if (r.errors().size() == before)
          checkResource(r, "render_mesh", o.renderMesh, {Type::Mesh, Type::Isosurface, Type::Shape},
                        "a mesh, isosurface or shape");
      }
      o.material = r.string("material", std::string());
      o.pose = readPose(r.child("pose"));
      o.scale = readPositive(r, "scale", 1.0);
      o.visible = r.boolean("visible", true);
      o.haptic = r.boolean("haptic", false);
      o.dynamic = r.boolean("dynamic", false);
      rigidBody(r, o);
      if (v2Key(r, "millable")) readMillable(r, o);
      if (v2Key(r, "critical")) readCritical(r, o);
      if (v2Key(r, "inclusion")) readInclusion(r, o);
      if (v2Key(r, "soft")) readSoft(r, o);
      if (v2Key(r, "membrane")) readMembrane(r, o);
      if (v2Key(r, "voxels")) readVoxels(r, o);
      if (r.has("material") && !o.material.empty() &&
          checkName(r, "material", o.material, materialIndex_, "material", "materials")) {
        if (o.haptic && !o.voxels && !scene_.materials[materialIndex_.at(o.material)].haptic)
          r.addError("object is touchable but material " + inQuotes(o.material) + " has no \"haptic\" block",
                     "material", "add \"haptic\": {\"stiffness\": <N/m>} to the material");
      } else if (o.haptic && o.material.empty() && !o.voxels) {  // voxel contact is rigid: no material needed
        r.addError("a touchable object needs a material with a \"haptic\" block", "haptic",
                   "add \"material\" naming one");
      }
      scene_.objects.push_back(std::move(o));
    }
  }

  // True when `key` is present and this document may use it: keys version 2
  // added are errors in a version-1 file.
  bool v2Key(ConfigReader& r, std::string_view key) {
    if (!r.has(key)) return false;
    if (version_ >= 2) return true;
    r.addError("\"" + std::string(key) + "\" is a version-2 key", key, "set \"version\": 2");
    return false;
  }

  // The rigid-body keys of an object: mass or density, initial velocities
  // (dynamic objects only), and contact (any object that collides).
  void rigidBody(ConfigReader& r, SceneObject& o) {
    const bool density = v2Key(r, "density");
    if (r.has("mass") && density) {
      r.addError("both \"mass\" and \"density\" are given", "density", "give one of them");
    } else if (r.has("mass")) {
      o.mass = readPositive(r, "mass", {}, 1e6);
    } else if (density) {
      o.density = readPositive(r, "density", {}, 1e6);
    } else if (o.dynamic) {
      r.addError("a dynamic object needs a mass", "mass",
                 "add \"mass\": <kg>" + std::string(version_ >= 2 ? " or \"density\": <kg/m³>" : ""));
    }
    if (!o.dynamic && (r.has("mass") || density))
      r.addError("only a dynamic object has a mass", r.has("mass") ? "mass" : "density",
                 "set \"dynamic\": true, or remove it");
    for (const char* key : {"velocity", "angular_velocity"}) {
      if (!v2Key(r, key)) continue;
      (std::string_view(key) == "velocity" ? o.velocity : o.angularVelocity) = readVec3(r, key);
      if (!o.dynamic) r.addError("only a dynamic object moves", key, "set \"dynamic\": true, or remove it");
    }
    if (v2Key(r, "collide")) o.collide = r.boolean("collide");
    if (v2Key(r, "contact")) {
      ConfigReader c = r.child("contact");
      if (expectObject(c)) {
        c.knownKeys({"friction", "restitution"});
        o.friction = c.number("friction", {.min = 0.0, .max = 10.0}, o.friction);
        o.restitution = c.number("restitution", {.min = 0.0, .max = 1.0}, o.restitution);
      }
    }
  }

  // Cross-checks between the objects and the engines, once both are read:
  // dynamic objects need the physics engine and a shape that can move; the
  // physics engine needs something to move; the tool's picture is no body.
  void physicsBodies() {
    ConfigReader objects = root_.child("objects");
    const auto& h = scene_.engines.haptics;
    bool anyMoving = false;  // a dynamic or soft object
    for (std::size_t i = 0; i < scene_.objects.size() && objects.isArray() && i < objects.size(); ++i) {
      const SceneObject o = scene_.objects[i];
      ConfigReader r = objects.at(i);
      const bool proxy = h && h->proxyObject == o.name;
      if (proxy && o.dynamic)
        r.addError("the haptic proxy object " + inQuotes(o.name) + " is moved by the tool, not by physics",
                   "dynamic", "remove \"dynamic\", or show the tool with another object");
      if (proxy && r.has("collide") && o.collide)
        r.addError("the haptic proxy object " + inQuotes(o.name) +
                       " is the tool's picture and collides with nothing",
                   "collide", "remove \"collide\"");
      if (proxy) scene_.objects[i].collide = false;  // what toJson writes back
      if (o.soft || o.membrane) anyMoving = true;
      if (!o.dynamic) continue;
      anyMoving = true;  // a dynamic proxy is reported above, not as "nothing to move" too
      if (proxy) continue;
      if (!scene_.engines.physics)
        r.addError("dynamic object " + inQuotes(o.name) + " but no physics engine runs this scene", "dynamic",
                   "add \"physics\": {} to \"engines\", or remove \"dynamic\"");
      if (const SceneResource* m = scene_.resource(o.mesh)) {
        if (m->type == Type::Shape && m->shape == SceneResource::Shape::Plane)
          r.addError("a plane (a flat rectangle) has no volume and cannot be a dynamic body", "mesh",
                     "use a thin box shape");
      }
    }
    if (scene_.engines.physics && !anyMoving && scene_.fluids.empty())
      root_.child("engines").child("physics").addError(
          "the physics engine has no dynamic or soft object, membrane or fluid to move", {},
          "set \"dynamic\": true and a mass on an object, give one a \"soft\" or \"membrane\" block, add a "
          "fluid, or remove the engine");
  }

  void transferFunction(ConfigReader tf, SceneVolume& v) {
    if (!expectObject(tf)) return;
    tf.knownKeys({"points"});
    ConfigReader pts = tf.child("points", true);
    if (!expectArray(pts)) return;
    if (pts.size() < 2) {
      pts.addError("a transfer function needs at least 2 points, got " + std::to_string(pts.size()), {},
                   "give [value, r, g, b, a] points, e.g. [[0, 0, 0, 0, 0], [255, 1, 1, 1, 1]]");
      return;
    }
    for (std::size_t i = 0; i < pts.size(); ++i) {
      ConfigReader p = pts.at(i);
      const Json& j = p.node();
      if (!j.is_array() || j.size() != 5) {
        p.addError(std::string("expected [value, r, g, b, a], got ") + j.type_name() +
                   (j.is_array() ? " of " + std::to_string(j.size()) : std::string()));
        continue;
      }
      SceneTransferPoint point;
      bool good = true;
      for (std::size_t c = 0; c < 5; ++c) {
        const Json& e = j[c];
        if (!e.is_number() || !std::isfinite(e.get<double>())) {
          p.addError("expected a finite number, got " + std::string(e.type_name()), std::to_string(c));
          good = false;
          continue;
        }
        const double x = e.get<double>();
        if (c == 0) {
          point.value = x;
        } else if (x < 0.0 || x > 1.0) {
          p.addError(formatString("component %g is outside [0, 1]", x), std::to_string(c),
                     "colour and opacity are 0..1");
          good = false;
        } else {
          point.rgba[static_cast<Eigen::Index>(c - 1)] = x;
        }
      }
      if (!good) continue;
      if (!v.transferFunction.empty() && !(point.value > v.transferFunction.back().value))
        p.addError(formatString("value %g does not increase (previous point: %g)", point.value,
                                v.transferFunction.back().value),
                   "0", "sort the points by value; values must strictly increase");
      v.transferFunction.push_back(point);
    }
  }

  void volumes() {
    ConfigReader sec = root_.child("volumes");
    if (!expectArray(sec)) return;
    for (std::size_t i = 0; i < sec.size(); ++i) {
      ConfigReader r = sec.at(i);
      if (!expectObject(r)) continue;
      r.knownKeys({"name", "volume", "mode", "transfer_function", "slice", "visible"});
      SceneVolume v;
      v.name = uniqueName(r, volumeIndex_, scene_.volumes.size());
      const std::size_t before = r.errors().size();
      v.volume = r.string("volume");
      if (r.errors().size() == before) checkResource(r, "volume", v.volume, {Type::Volume}, "a volume");
      v.mode = readEnum<SceneVolume::Mode>(r, "mode", kVolumeModes, SceneVolume::Mode::Composite)
                   .value_or(SceneVolume::Mode::Composite);
      transferFunction(r.child("transfer_function"), v);
      if (r.has("slice") && v.mode != SceneVolume::Mode::Slice) {
        r.addError("\"slice\" applies only to mode \"slice\"", "slice",
                   "remove it, or set \"mode\": \"slice\"");
      } else {
        ConfigReader s = r.child("slice");
        if (expectObject(s)) {
          s.knownKeys({"axis", "position"});
          v.sliceAxis = readEnum<SceneVolume::Axis>(s, "axis", kAxes, SceneVolume::Axis::Axial)
                            .value_or(SceneVolume::Axis::Axial);
          v.slicePosition = s.number("position", {}, 0.0);
        }
      }
      v.visible = r.boolean("visible", true);
      scene_.volumes.push_back(std::move(v));
    }
  }

  void lights() {
    ConfigReader sec = root_.child("lights");
    if (!expectArray(sec)) return;
    using L = SceneLight::Type;
    for (std::size_t i = 0; i < sec.size(); ++i) {
      ConfigReader r = sec.at(i);
      if (!expectObject(r)) continue;
      const auto type = readEnum<L>(r, "type", kLightTypes);
      if (!type) continue;
      SceneLight l;
      l.type = *type;
      switch (*type) {
        case L::Directional:
          r.knownKeys({"type", "direction", "color", "intensity", "shadows"});
          break;
        case L::Point:
          r.knownKeys({"type", "position", "color", "intensity", "range", "shadows"});
          break;
        case L::Spot:
          r.knownKeys({"type", "direction", "position", "color", "intensity", "range", "inner_cone_deg",
                       "outer_cone_deg", "shadows"});
          break;
      }
      if (*type != L::Point) {
        if (!r.has("direction"))
          r.addError("missing required direction", "direction", "add \"direction\": [x, y, z]");
        else
          l.direction = readDirection(r, "direction", l.direction);
      }
      if (*type != L::Directional) {
        l.position = readVec3(r, "position");
        l.range = r.number("range", {.min = 0.0}, 0.0);
      }
      l.color = readColor(r, "color", {1.0, 1.0, 1.0, 1.0}, false).head<3>();
      l.intensity = r.number("intensity", {.min = 0.0}, 1.0);
      if (*type == L::Spot) {
        const std::size_t before = r.errors().size();
        l.innerConeDeg = r.number("inner_cone_deg", {.min = 0.0, .max = 90.0}, l.innerConeDeg);
        l.outerConeDeg = r.number("outer_cone_deg", {.min = 0.0, .max = 90.0}, l.outerConeDeg);
        if (r.errors().size() == before && !(l.innerConeDeg > 0.0 && l.innerConeDeg <= l.outerConeDeg))
          r.addError(formatString("inner cone %g° must be > 0 and <= outer cone %g°", l.innerConeDeg,
                                  l.outerConeDeg),
                     "inner_cone_deg", "light is full inside the inner cone and fades out to the outer cone");
      }
      l.shadows = r.boolean("shadows", false);
      scene_.lights.push_back(l);
    }
  }

  void devices() {
    ConfigReader sec = root_.child("devices");
    if (!expectArray(sec)) return;
    for (std::size_t i = 0; i < sec.size(); ++i) {
      ConfigReader r = sec.at(i);
      if (!expectObject(r)) continue;
      r.knownKeys({"name", "driver", "config", "serve"});
      SceneDevice d;
      d.name = uniqueName(r, deviceIndex_, scene_.devices.size());
      const std::size_t before = r.errors().size();
      d.driver = r.string("driver");
      if (r.errors().size() == before && d.driver.empty())
        r.addError("driver is empty", "driver", "name a registered driver, e.g. \"sim-haptic\"");
      ConfigReader c = r.child("config");
      if (expectObject(c)) {
        for (auto it = c.node().begin(); it != c.node().end(); ++it) {
          const Json& v = it.value();
          bool flat = v.is_primitive() && !v.is_null();
          if (v.is_array())
            flat = std::all_of(v.begin(), v.end(),
                               [](const Json& e) { return e.is_primitive() && !e.is_null(); });
          if (!flat)
            c.addError(
                std::string("driver parameters are strings, numbers, booleans or arrays of them, got ") +
                    v.type_name(),
                it.key());
          // A driver's "file" (a path to follow, a recording to replay) is
          // a source like a resource's: relative to the scene, confined.
          if (it.key() == "file" && v.is_string()) {
            const std::size_t b = c.errors().size();
            fs::path p = resolveSource(c, v.get<std::string>(), "file");
            if (c.errors().size() == b) d.files["file"] = std::move(p);
          }
        }
        d.config = c.node();
      }
      if (r.has("serve")) {
        ConfigReader sv = r.child("serve");
        if (expectObject(sv)) {
          sv.knownKeys({"listen", "timeout", "wave_impedance"});
          SceneDeviceServe serve;
          serve.listen = sv.string("listen", serve.listen);
          if (auto hp = parseHostPort(serve.listen, "listen", true); !hp)
            sv.addError(hp.error().what, "listen",
                        "e.g. \"127.0.0.1:0\" (port 0: any free port) or \"0.0.0.0:47000\"");
          serve.timeout = sv.number("timeout", {.min = 1e-3, .max = 60.0}, serve.timeout);
          serve.waveImpedance = sv.number("wave_impedance", {.min = 0.0, .max = 1e6}, 0.0);
          d.serve = serve;
        }
      }
      scene_.devices.push_back(std::move(d));
    }
    // "@NAME" in a config stands for a served device's address.
    for (std::size_t i = 0; i < scene_.devices.size(); ++i) {
      const SceneDevice& d = scene_.devices[i];
      if (!d.config.is_object()) continue;
      for (auto it = d.config.begin(); it != d.config.end(); ++it) {
        if (!it.value().is_string()) continue;
        const std::string& v = it.value().get_ref<const std::string&>();
        if (v.empty() || v[0] != '@') continue;
        const SceneDevice* target = scene_.device(std::string_view(v).substr(1));
        if (target == nullptr || !target->serve || target == &d)
          sec.at(i).child("config").addError(
              "\"" + v + "\" names no other device with \"serve\"", it.key(),
              "\"@NAME\" stands for the address of the device NAME served in this scene; give NAME a "
              "\"serve\" block");
      }
    }
  }

  void cameraPath(ConfigReader p, SceneCamera& c) {
    if (!expectArray(p)) return;
    if (p.size() == 0) p.addError("a camera path needs at least one key", {}, "remove \"path\" or add keys");
    for (std::size_t i = 0; i < p.size(); ++i) {
      ConfigReader k = p.at(i);
      if (!expectObject(k)) continue;
      k.knownKeys({"t", "position", "target"});
      SceneCameraKey key;
      const std::size_t before = k.errors().size();
      key.t = k.number("t");
      key.position = readVec3(k, "position");
      key.target = readVec3(k, "target");
      if (k.errors().size() != before) continue;
      if (!c.path.empty() && !(key.t > c.path.back().t))
        k.addError(formatString("time %g s does not increase (previous key: %g s)", key.t, c.path.back().t),
                   "t", "keys must be in strictly increasing time");
      c.path.push_back(key);
    }
  }

  void cameras() {
    ConfigReader sec = root_.child("cameras");
    if (!expectArray(sec)) return;
    using P = SceneCamera::Projection;
    for (std::size_t i = 0; i < sec.size(); ++i) {
      ConfigReader r = sec.at(i);
      if (!expectObject(r)) continue;
      SceneCamera c;
      c.name = uniqueName(r, cameraIndex_, scene_.cameras.size());
      const auto proj = readEnum<P>(r, "projection", kProjections, P::Perspective);
      if (!proj) continue;
      c.projection = *proj;
      if (c.projection == P::Perspective) {
        r.knownKeys({"name", "projection", "fov_y_deg", "position", "target", "up", "near", "far", "track",
                     "path", "stereo"});
        const std::size_t before = r.errors().size();
        c.fovYDeg = r.number("fov_y_deg", {.min = 0.0, .max = 180.0}, c.fovYDeg);
        if (r.errors().size() == before && !(c.fovYDeg > 0.0 && c.fovYDeg < 180.0))
          r.addError(formatString("field of view %g° is not between 0° and 180°", c.fovYDeg), "fov_y_deg");
      } else {
        r.knownKeys({"name", "projection", "ortho_height", "position", "target", "up", "near", "far", "track",
                     "path", "stereo"});
        c.orthoHeight = readPositive(r, "ortho_height", c.orthoHeight);
      }
      cameraPath(r.child("path"), c);
      const bool hasPath = !c.path.empty();
      c.position = hasPath ? readVec3(r, "position", c.path.front().position) : readVec3(r, "position");
      c.target = readVec3(r, "target", hasPath ? c.path.front().target : Vec3::Zero());
      c.up = readDirection(r, "up", c.up);
      const std::size_t before = r.errors().size();
      c.near = readPositive(r, "near", c.near);
      c.far = r.number("far", {.min = 0.0}, c.far);
      if (r.errors().size() == before && !(c.far > c.near))
        r.addError(formatString("far plane %g m is not beyond the near plane %g m", c.far, c.near), "far");
      if (r.has("track")) {
        const std::size_t b = r.errors().size();
        c.track = r.string("track");
        if (r.errors().size() == b) checkName(r, "track", c.track, objectIndex_, "object", "objects");
      }
      if (!hasPath && c.track.empty()) {
        const Vec3 view = c.target - c.position;
        if (view.norm() < 1e-9)
          r.addError("target coincides with position", "target", "aim the camera at a point away from it");
        else if (view.normalized().cross(c.up).norm() < 1e-6)
          r.addError("up is parallel to the view direction", "up", "choose an up vector across the view");
      }
      ConfigReader st = r.child("stereo");
      if (expectObject(st)) {
        st.knownKeys({"eye_separation", "convergence"});
        c.stereo = true;
        c.eyeSeparation = readPositive(st, "eye_separation", c.eyeSeparation, 1.0);
        c.convergence = readPositive(st, "convergence", c.convergence);
      }
      scene_.cameras.push_back(std::move(c));
    }
  }

  void touchable(ConfigReader& r, std::string_view key, const std::string& name) {
    if (!checkName(r, key, name, objectIndex_, "object", "objects")) return;
    if (!scene_.objects[objectIndex_.at(name)].haptic)
      r.addError("object " + inQuotes(name) + " is not touchable", key, "set \"haptic\": true on it");
  }

  void hapticsEngine(ConfigReader r) {
    if (!expectObject(r)) return;
    r.knownKeys({"rate_hz", "renderer", "device", "object", "objects", "tool_radius", "device_pose",
                 "max_force", "force_shading", "proxy_object", "burr", "needle", "vps", "sphere_tree",
                 "bone_placement", "punch"});
    SceneHapticsEngine h;
    h.rateHz = r.number("rate_hz", {.min = 100.0, .max = 10000.0}, h.rateHz);
    h.renderer =
        readEnum<SceneHapticsEngine::Renderer>(r, "renderer", kRenderers, h.renderer).value_or(h.renderer);
    const std::size_t before = r.errors().size();
    h.device = r.string("device");
    if (r.errors().size() == before) checkName(r, "device", h.device, deviceIndex_, "device", "devices");
    const bool freeSpace = h.renderer == SceneHapticsEngine::Renderer::None;
    const bool punch = h.renderer == SceneHapticsEngine::Renderer::Punch;
    if (freeSpace || punch) {
      // A tool in free space touches nothing, a punch is bonded to the
      // object its block names: no objects, no proxy to size or shade.
      for (const char* key : {"object", "objects", "tool_radius", "force_shading"})
        if (r.has(key))
          r.addError(freeSpace ? std::string("renderer \"none\" touches nothing: \"") + key + "\" has no use"
                               : std::string("the punch is bonded to the object its block names: \"") + key +
                                     "\" has no use",
                     key, freeSpace ? "remove it, or choose a renderer that touches objects" : "remove it");
    } else if (r.has("object") && r.has("objects")) {
      r.addError("both \"object\" and \"objects\" are given", "object",
                 "list every object under \"objects\"");
    } else if (r.has("object")) {
      const std::size_t b = r.errors().size();
      h.objects.push_back(r.string("object"));
      if (r.errors().size() == b) touchable(r, "object", h.objects.back());
    } else if (r.has("objects")) {
      ConfigReader list = r.child("objects");
      if (expectArray(list)) {
        if (list.size() == 0) list.addError("no objects", {}, "name at least one touchable object");
        for (std::size_t i = 0; i < list.size(); ++i) {
          const Json& e = list.node()[i];
          if (!e.is_string()) {
            list.addError(std::string("expected an object name, got ") + e.type_name(), std::to_string(i));
            continue;
          }
          h.objects.push_back(e.get<std::string>());
          touchable(list, std::to_string(i), h.objects.back());
        }
      }
    } else {
      r.addError("missing required objects", "objects", "add \"objects\": [\"<touchable object>\"]");
    }
    if (!freeSpace && !punch) {
      h.toolRadius = r.number("tool_radius", {.min = 0.0, .max = 0.1}, 0.0);
      h.forceShading = r.boolean("force_shading", false);
    }
    h.devicePose = readPose(r.child("device_pose"));
    h.maxForce = r.number("max_force", {.min = 0.0, .max = 1000.0}, 0.0);
    if (r.has("proxy_object")) {
      const std::size_t b = r.errors().size();
      h.proxyObject = r.string("proxy_object");
      if (r.errors().size() == b &&
          checkName(r, "proxy_object", h.proxyObject, objectIndex_, "object", "objects") &&
          std::find(h.objects.begin(), h.objects.end(), h.proxyObject) != h.objects.end())
        r.addError("the proxy object " + inQuotes(h.proxyObject) + " is also a touched object",
                   "proxy_object", "show the tool with its own object");
    }
    if (v2Key(r, "burr")) readBurr(r, h);
    if (v2Key(r, "needle")) readNeedle(r, h);
    if (v2Key(r, "vps")) readVps(r, h);
    if (v2Key(r, "sphere_tree")) readSphereTree(r, h);
    if (v2Key(r, "bone_placement")) readBonePlacement(r, h);
    if (v2Key(r, "punch")) readPunch(r, h);
    scene_.engines.haptics = std::move(h);
  }

  void engines() {
    ConfigReader sec = root_.child("engines");
    if (!expectObject(sec)) return;
    sec.knownKeys({"haptics", "physics", "render", "monitor", "igtl", "vision", "segmentation"});
    hapticsEngine(sec.child("haptics"));
    if (ConfigReader r = sec.child("physics"); expectObject(r)) {
      r.knownKeys({"rate_hz", "gravity", "sleep", "joints", "backend", "ode"});
      ScenePhysicsEngine p;
      p.rateHz = r.number("rate_hz", {.min = 10.0, .max = 10000.0}, p.rateHz);
      p.gravity = readVec3(r, "gravity", p.gravity);
      if (v2Key(r, "sleep")) p.sleep = r.boolean("sleep");
      if (v2Key(r, "joints")) readJoints(r, p, scene_);
      const bool backendKey = v2Key(r, "backend"), odeKey = v2Key(r, "ode");
      if (backendKey || odeKey) readPhysicsBackend(r, p);
      scene_.engines.physics = p;
    }
    if (ConfigReader r = sec.child("render"); expectObject(r)) {
      r.knownKeys({"rate_hz", "camera", "width", "height", "samples", "hud", "inset"});
      SceneRenderEngine g;
      g.rateHz = r.number("rate_hz", {.min = 1.0, .max = 240.0}, g.rateHz);
      const std::size_t before = r.errors().size();
      g.camera = r.string("camera", std::string());
      if (r.errors().size() == before) {
        if (r.has("camera"))
          checkName(r, "camera", g.camera, cameraIndex_, "camera", "cameras");
        else if (scene_.cameras.empty())
          r.addError("the render engine needs a camera", {}, "add one under \"cameras\"");
      }
      g.width = static_cast<int>(r.integer("width", {.min = 16, .max = 16384}, g.width));
      g.height = static_cast<int>(r.integer("height", {.min = 16, .max = 16384}, g.height));
      const std::size_t b = r.errors().size();
      g.samples = static_cast<int>(r.integer("samples", {.min = 1, .max = 16}, g.samples));
      if (r.errors().size() == b && (g.samples & (g.samples - 1)) != 0)
        r.addError("samples is " + std::to_string(g.samples) + ", not 1, 2, 4, 8 or 16", "samples");
      if (v2Key(r, "hud")) g.hud = r.boolean("hud");
      if (v2Key(r, "inset")) {
        ConfigReader in = r.child("inset");
        if (expectObject(in)) {
          in.knownKeys({"camera", "size"});
          const std::size_t c = in.errors().size();
          g.insetCamera = in.string("camera");
          if (in.errors().size() == c)
            checkName(in, "camera", g.insetCamera, cameraIndex_, "camera", "cameras");
          g.insetSize = in.number("size", {.min = 0.1, .max = 0.9}, g.insetSize);
        }
      }
      scene_.engines.render = g;
    }
    if (ConfigReader r = sec.child("monitor"); expectObject(r)) {
      r.knownKeys({"rate_hz"});
      SceneMonitorEngine m;
      m.rateHz = r.number("rate_hz", {.min = 1.0, .max = 1000.0}, m.rateHz);
      scene_.engines.monitor = m;
    }
    if (v2Key(sec, "igtl")) readIgtl(sec, scene_.engines);
    if (v2Key(sec, "vision")) visionEngine(sec.child("vision"));
    if (v2Key(sec, "segmentation")) readSegmentation(sec, scene_.engines);
  }

  // The vision engine: its rate and its graph, a file (a source like a
  // resource's: relative to the scene, confined) or inline. The graph
  // itself is DMVision's to check, when the engine is built.
  void visionEngine(ConfigReader r) {
    if (!expectObject(r)) return;
    r.knownKeys({"rate_hz", "graph", "overlay"});
    SceneVisionEngine v;
    v.rateHz = r.number("rate_hz", {.min = 1.0, .max = 240.0}, v.rateHz);
    const Json& graph = r.node().contains("graph") ? r.node()["graph"] : Json();
    if (graph.is_string()) {
      v.graphFile = resolveSource(r, graph.get<std::string>(), "graph");
    } else if (graph.is_object()) {
      v.graph = graph;
    } else {
      r.addError(graph.is_null() ? "missing required graph"
                                 : std::string("expected a file name or an object, got ") + graph.type_name(),
                 "graph", "a filter graph file (docs/vision.md) or {\"nodes\": [...]}");
    }
    if (r.has("overlay")) {
      v.overlay = r.string("overlay");
      if (!scene_.engines.render)
        r.addError("the overlay is drawn over the render engine's frames, and there is none", "overlay",
                   "add \"render\" under \"engines\" or remove \"overlay\"");
    }
    scene_.engines.vision = std::move(v);
  }

  void outputs() {
    ConfigReader r = root_.child("outputs");
    if (!expectObject(r)) return;
    r.knownKeys({"directory", "frames", "frame_every", "forces", "plot", "summary", "recording"});
    SceneOutputs& o = scene_.outputs;
    const std::size_t before = r.errors().size();
    o.directory = r.string("directory", o.directory);
    if (r.errors().size() == before && o.directory.empty())
      r.addError("directory is empty", "directory", "name a directory, e.g. \"out/head_probe\"");
    o.frames = r.boolean("frames", false);
    o.frameEvery = static_cast<int>(r.integer("frame_every", {.min = 1, .max = 1000000}, 1));
    o.forces = r.boolean("forces", false);
    o.plot = r.boolean("plot", false);
    o.summary = r.boolean("summary", true);
    if (v2Key(r, "recording")) o.recording = r.boolean("recording");
    if (o.frames && !scene_.engines.render)
      r.addError("frames need a render engine", "frames", "add \"render\" under \"engines\"");
    for (auto [key, on] :
         {std::pair{"forces", o.forces}, std::pair{"plot", o.plot}, std::pair{"recording", o.recording}})
      if (on && !scene_.engines.haptics)
        r.addError(std::string(key) + " needs a haptics engine", key, "add \"haptics\" under \"engines\"");
  }

  ConfigReader root_;
  fs::path baseDir_;
  SceneDesc scene_;
  // Name → index of the first element with it (duplicates are errors).
  NameIndex materialIndex_, objectIndex_, volumeIndex_, deviceIndex_, cameraIndex_;
  bool badVersion_ = false;
  int version_ = kSceneFormatVersion;
};

template <class T>
const T* findNamed(const std::vector<T>& list, std::string_view name) {
  const auto it = std::find_if(list.begin(), list.end(), [&](const T& t) { return t.name == name; });
  return it == list.end() ? nullptr : &*it;
}

std::string paramString(const Json& v) {
  if (v.is_string()) return v.get<std::string>();
  if (v.is_boolean()) return v.get<bool>() ? "1" : "0";
  if (v.is_array()) {
    std::string s;
    for (const Json& e : v) s += (s.empty() ? "" : ",") + paramString(e);
    return s;
  }
  return v.dump();
}

}  // namespace

bool SceneObject::operator==(const SceneObject& o) const {
  return name == o.name && mesh == o.mesh && renderMesh == o.renderMesh && material == o.material &&
         pose.p == o.pose.p && pose.q.coeffs() == o.pose.q.coeffs() && scale == o.scale &&
         visible == o.visible && haptic == o.haptic && dynamic == o.dynamic && mass == o.mass &&
         density == o.density && velocity == o.velocity && angularVelocity == o.angularVelocity &&
         collide == o.collide && friction == o.friction && restitution == o.restitution &&
         millable == o.millable && critical == o.critical && inclusion == o.inclusion && soft == o.soft &&
         voxels == o.voxels && membrane == o.membrane;
}

std::string_view rendererName(SceneHapticsEngine::Renderer renderer) noexcept {
  const auto i = static_cast<std::size_t>(renderer);
  return i < kRenderers.size() ? kRenderers[i] : std::string_view("?");
}

bool SceneHapticsEngine::operator==(const SceneHapticsEngine& o) const {
  return rateHz == o.rateHz && renderer == o.renderer && device == o.device && objects == o.objects &&
         toolRadius == o.toolRadius && devicePose.p == o.devicePose.p &&
         devicePose.q.coeffs() == o.devicePose.q.coeffs() && maxForce == o.maxForce &&
         forceShading == o.forceShading && proxyObject == o.proxyObject && burr == o.burr &&
         needle == o.needle && vps == o.vps && sphereTree == o.sphereTree &&
         bonePlacement == o.bonePlacement && punch == o.punch;
}

const SceneResource* SceneDesc::resource(std::string_view n) const { return findNamed(resources, n); }
const SceneMaterial* SceneDesc::material(std::string_view n) const { return findNamed(materials, n); }
const SceneObject* SceneDesc::object(std::string_view n) const { return findNamed(objects, n); }
const SceneVolume* SceneDesc::volume(std::string_view n) const { return findNamed(volumes, n); }
const SceneCamera* SceneDesc::camera(std::string_view n) const { return findNamed(cameras, n); }
const SceneDevice* SceneDesc::device(std::string_view n) const { return findNamed(devices, n); }

Result<SceneDesc> parseScene(std::string_view json, std::string_view sourceName, const fs::path& baseDir,
                             std::vector<Error>* problems) {
  const std::string source(sourceName.empty() ? "<string>" : sourceName);
  auto give = [&](Error e) -> Result<SceneDesc> {
    if (problems) *problems = {e};
    return e;
  };
  if (auto at = tooDeepAt(json))
    return give(fail(ErrorCode::Parse, "JSON nested deeper than " + std::to_string(kMaxDepth) + " levels",
                     source + ": byte " + std::to_string(*at),
                     "a scene needs a few levels; check the brackets"));
  std::optional<Result<Config>> cfg;
  try {
    cfg.emplace(Config::parse(json, source));
  } catch (const std::exception& e) {
    // Config::parse turns syntax errors into an Error; nlohmann reports a
    // few others (e.g. a number too large for a double) by throwing.
    return give(fail(ErrorCode::Parse, std::string("invalid JSON: ") + e.what(), source,
                     "check the numbers and strings in the file"));
  }
  if (!*cfg) return give(cfg->error());

  SceneParser parser((*cfg)->reader(), baseDir);
  if (parser.header()) {
    parser.body();
    reportDuplicateKeys(json, parser.root());
  }
  if (auto s = parser.root().status(); !s) {
    if (problems) *problems = parser.root().errors();
    Error e = s.error();
    if (parser.badVersion()) e.code = ErrorCode::Version;
    if (problems && parser.badVersion()) problems->front().code = ErrorCode::Version;
    return e;
  }
  if (problems) problems->clear();
  return std::move(parser.scene());
}

Result<SceneDesc> readScene(const fs::path& file, std::vector<Error>* problems) {
  auto bytes = readFile(file, kMaxSceneBytes);
  if (!bytes) {
    Error e = bytes.error();
    if (e.hint.empty())
      e.hint = e.code == ErrorCode::NotFound ? "check the path" : "a scene file is at most 16 MiB of JSON";
    if (problems) *problems = {e};
    return e;
  }
  std::error_code ec;
  fs::path dir = fs::absolute(file, ec).parent_path();
  if (ec) dir = file.parent_path();
  const std::string_view text(reinterpret_cast<const char*>(bytes->data()), bytes->size());
  return parseScene(text, file.string(), dir, problems);
}

std::string formatSceneErrors(const std::vector<Error>& problems) {
  std::string out;
  for (const Error& e : problems) out += e.message() + "\n";
  return out;
}

std::vector<std::pair<std::string, std::string>> deviceParams(const SceneDevice& device) {
  std::vector<std::pair<std::string, std::string>> out;
  if (!device.config.is_object()) return out;
  for (auto it = device.config.begin(); it != device.config.end(); ++it) {
    const auto file = device.files.find(it.key());
    out.emplace_back(it.key(), file != device.files.end() ? file->second.string() : paramString(it.value()));
  }
  return out;
}

Json toJson(const SceneDesc& scene) {
  using Type = SceneResource::Type;
  using S = SceneResource::Shape;
  Json j = {{"format", kFormatName}, {"version", kSceneFormatVersion}, {"name", scene.name}};

  Json resources = Json::object();
  for (const SceneResource& r : scene.resources) {
    Json o = {{"type", enumName(r.type, kResourceTypes)}};
    switch (r.type) {
      case Type::Mesh:
        o["source"] = r.source;
        o["unit"] = r.unit;
        o["scale"] = r.scale;
        break;
      case Type::Volume:
        if (r.segment)
          o["segment"] = segmentJson(*r.segment);
        else if (r.phantom)
          o["phantom"] = phantomJson(*r.phantom);
        else
          o["source"] = r.source;
        break;
      case Type::Image:
        o["source"] = r.source;
        break;
      case Type::Isosurface:
        o["volume"] = r.volume;
        o["level"] = r.level;
        o["largest_component"] = r.largestComponent;
        o["smooth"] = r.smooth;
        if (r.smoothMaxDisplacement < std::numeric_limits<double>::infinity())
          o["smooth_max_displacement"] = r.smoothMaxDisplacement;
        o["downsample"] = r.downsample;
        break;
      case Type::Shape:
        o["shape"] = enumName(r.shape, kShapes);
        if (r.shape == S::Sphere || r.shape == S::Capsule || r.shape == S::Cylinder) o["radius"] = r.radius;
        if (r.shape == S::Capsule || r.shape == S::Cylinder) o["height"] = r.height;
        if (r.shape == S::Box) o["half_extents"] = toJson(r.halfExtents);
        if (r.shape == S::Plane) o["half_extents"] = Json::array({r.halfExtents.x(), r.halfExtents.y()});
        if (r.shape == S::Compound) {
          Json parts = Json::array();
          for (const SceneResource::Part& p : r.parts) {
            Json part = {{"shape", enumName(p.shape, kShapes)}, {"pose", toJson(p.pose)}};
            if (p.shape != S::Box) part["radius"] = p.radius;
            if (p.shape == S::Capsule || p.shape == S::Cylinder) part["height"] = p.height;
            if (p.shape == S::Box) part["half_extents"] = toJson(p.halfExtents);
            parts.push_back(std::move(part));
          }
          o["parts"] = std::move(parts);
        }
        o["subdivisions"] = r.subdivisions;
        break;
    }
    resources[r.name] = std::move(o);
  }
  j["resources"] = std::move(resources);

  Json materials = Json::object();
  for (const SceneMaterial& m : scene.materials) {
    Json o = {{"model", enumName(m.model, kMaterialModels)},
              {"color", toJson(m.color)},
              {"emissive", toJson(m.emissive)}};
    if (m.model == SceneMaterial::Model::BlinnPhong) {
      o["specular"] = toJson(m.specular);
      o["shininess"] = m.shininess;
    } else {
      o["metallic"] = m.metallic;
      o["roughness"] = m.roughness;
    }
    if (!m.texture.empty()) o["texture"] = m.texture;
    if (!m.normalMap.empty()) o["normal_map"] = m.normalMap;
    if (!m.heightMap.empty()) {
      o["height_map"] = m.heightMap;
      o["height_scale"] = m.heightScale;
    }
    if (m.haptic)
      o["haptic"] = {{"stiffness", m.haptic->stiffness},
                     {"damping", m.haptic->damping},
                     {"static_friction", m.haptic->staticFriction},
                     {"dynamic_friction", m.haptic->dynamicFriction}};
    materials[m.name] = std::move(o);
  }
  j["materials"] = std::move(materials);

  Json objects = Json::array();
  for (const SceneObject& o : scene.objects) {
    Json e = {{"name", o.name},       {"mesh", o.mesh},     {"pose", toJson(o.pose)}, {"scale", o.scale},
              {"visible", o.visible}, {"haptic", o.haptic}, {"dynamic", o.dynamic}};
    if (!o.material.empty()) e["material"] = o.material;
    if (!o.renderMesh.empty()) e["render_mesh"] = o.renderMesh;
    if (o.mass > 0.0) e["mass"] = o.mass;
    if (o.density > 0.0) e["density"] = o.density;
    if (o.dynamic) {
      e["velocity"] = toJson(o.velocity);
      e["angular_velocity"] = toJson(o.angularVelocity);
    }
    if (!o.soft && !o.membrane) {  // soft objects and membranes take part in no rigid contact
      e["collide"] = o.collide;
      e["contact"] = {{"friction", o.friction}, {"restitution", o.restitution}};
    }
    writeSurgery(o, e);
    writeSoft(o, e);
    writeMembrane(o, e);
    writeVoxels(o, e);
    objects.push_back(std::move(e));
  }
  j["objects"] = std::move(objects);

  Json volumes = Json::array();
  for (const SceneVolume& v : scene.volumes) {
    Json e = {{"name", v.name},
              {"volume", v.volume},
              {"mode", enumName(v.mode, kVolumeModes)},
              {"visible", v.visible}};
    if (!v.transferFunction.empty()) {
      Json points = Json::array();
      for (const SceneTransferPoint& p : v.transferFunction)
        points.push_back({p.value, p.rgba.x(), p.rgba.y(), p.rgba.z(), p.rgba.w()});
      e["transfer_function"] = {{"points", std::move(points)}};
    }
    if (v.mode == SceneVolume::Mode::Slice)
      e["slice"] = {{"axis", enumName(v.sliceAxis, kAxes)}, {"position", v.slicePosition}};
    volumes.push_back(std::move(e));
  }
  j["volumes"] = std::move(volumes);

  Json lights = Json::array();
  for (const SceneLight& l : scene.lights) {
    Json e = {{"type", enumName(l.type, kLightTypes)},
              {"color", toJson(l.color)},
              {"intensity", l.intensity},
              {"shadows", l.shadows}};
    if (l.type != SceneLight::Type::Point) e["direction"] = toJson(l.direction);
    if (l.type != SceneLight::Type::Directional) {
      e["position"] = toJson(l.position);
      e["range"] = l.range;
    }
    if (l.type == SceneLight::Type::Spot) {
      e["inner_cone_deg"] = l.innerConeDeg;
      e["outer_cone_deg"] = l.outerConeDeg;
    }
    lights.push_back(std::move(e));
  }
  j["lights"] = std::move(lights);

  Json cameras = Json::array();
  for (const SceneCamera& c : scene.cameras) {
    Json e = {{"name", c.name},
              {"projection", enumName(c.projection, kProjections)},
              {"position", toJson(c.position)},
              {"target", toJson(c.target)},
              {"up", toJson(c.up)},
              {"near", c.near},
              {"far", c.far}};
    if (c.projection == SceneCamera::Projection::Perspective)
      e["fov_y_deg"] = c.fovYDeg;
    else
      e["ortho_height"] = c.orthoHeight;
    if (!c.track.empty()) e["track"] = c.track;
    if (!c.path.empty()) {
      Json path = Json::array();
      for (const SceneCameraKey& k : c.path)
        path.push_back({{"t", k.t}, {"position", toJson(k.position)}, {"target", toJson(k.target)}});
      e["path"] = std::move(path);
    }
    if (c.stereo) e["stereo"] = {{"eye_separation", c.eyeSeparation}, {"convergence", c.convergence}};
    cameras.push_back(std::move(e));
  }
  j["cameras"] = std::move(cameras);

  Json devices = Json::array();
  for (const SceneDevice& d : scene.devices) {
    Json o = {{"name", d.name}, {"driver", d.driver}, {"config", d.config}};
    if (d.serve)
      o["serve"] = {{"listen", d.serve->listen},
                    {"timeout", d.serve->timeout},
                    {"wave_impedance", d.serve->waveImpedance}};
    devices.push_back(std::move(o));
  }
  j["devices"] = std::move(devices);

  Json engines = Json::object();
  if (const auto& h = scene.engines.haptics)
    engines["haptics"] = {{"rate_hz", h->rateHz},         {"renderer", enumName(h->renderer, kRenderers)},
                          {"device", h->device},          {"objects", h->objects},
                          {"tool_radius", h->toolRadius}, {"device_pose", toJson(h->devicePose)},
                          {"max_force", h->maxForce},     {"force_shading", h->forceShading}};
  if (scene.engines.haptics && (scene.engines.haptics->renderer == SceneHapticsEngine::Renderer::None ||
                                scene.engines.haptics->renderer == SceneHapticsEngine::Renderer::Punch))
    for (const char* key : {"objects", "tool_radius", "force_shading"}) engines["haptics"].erase(key);
  if (scene.engines.haptics && scene.engines.haptics->punch)
    writePunch(*scene.engines.haptics->punch, engines["haptics"]);
  if (scene.engines.haptics && !scene.engines.haptics->proxyObject.empty())
    engines["haptics"]["proxy_object"] = scene.engines.haptics->proxyObject;
  if (scene.engines.haptics && scene.engines.haptics->burr) {
    // The burr's tool is its block: no proxy radius, no force shading.
    engines["haptics"].erase("tool_radius");
    engines["haptics"].erase("force_shading");
    writeBurr(*scene.engines.haptics->burr, engines["haptics"]);
  }
  if (scene.engines.haptics && scene.engines.haptics->needle) {
    // The needle is its block: no proxy radius, no force shading.
    engines["haptics"].erase("tool_radius");
    engines["haptics"].erase("force_shading");
    writeNeedle(*scene.engines.haptics->needle, engines["haptics"]);
  }
  if (scene.engines.haptics && scene.engines.haptics->vps) {
    // The VPS tool is its block: no proxy radius, no force shading.
    engines["haptics"].erase("tool_radius");
    engines["haptics"].erase("force_shading");
    writeVps(*scene.engines.haptics->vps, engines["haptics"]);
  }
  if (scene.engines.haptics && scene.engines.haptics->sphereTree) {
    engines["haptics"].erase("tool_radius");
    engines["haptics"].erase("force_shading");
    writeSphereTree(*scene.engines.haptics->sphereTree, engines["haptics"]);
  }
  if (scene.engines.haptics && scene.engines.haptics->bonePlacement) {
    engines["haptics"].erase("tool_radius");
    engines["haptics"].erase("force_shading");
    writeBonePlacement(*scene.engines.haptics->bonePlacement, engines["haptics"]);
  }
  if (const auto& p = scene.engines.physics) {
    engines["physics"] = {{"rate_hz", p->rateHz}, {"gravity", toJson(p->gravity)}, {"sleep", p->sleep}};
    if (!p->joints.empty()) engines["physics"]["joints"] = jointsJson(p->joints);
    writePhysicsBackend(*p, engines["physics"]);
  }
  if (const auto& r = scene.engines.render) {
    engines["render"] = {{"rate_hz", r->rateHz},
                         {"width", r->width},
                         {"height", r->height},
                         {"samples", r->samples},
                         {"hud", r->hud}};
    if (!r->camera.empty()) engines["render"]["camera"] = r->camera;
    if (!r->insetCamera.empty())
      engines["render"]["inset"] = {{"camera", r->insetCamera}, {"size", r->insetSize}};
  }
  if (const auto& m = scene.engines.monitor) engines["monitor"] = {{"rate_hz", m->rateHz}};
  if (const auto& g = scene.engines.igtl) writeIgtl(*g, engines);
  if (const auto& v = scene.engines.vision)
    engines["vision"] = {{"rate_hz", v->rateHz},
                         {"graph", v->graphFile.empty() ? v->graph : Json(v->graphFile.string())}};
  if (scene.engines.vision && !scene.engines.vision->overlay.empty())
    engines["vision"]["overlay"] = scene.engines.vision->overlay;
  if (const auto& g = scene.engines.segmentation) writeSegmentation(*g, engines);
  j["engines"] = std::move(engines);

  const SceneOutputs& o = scene.outputs;
  j["outputs"] = {{"directory", o.directory}, {"frames", o.frames}, {"frame_every", o.frameEvery},
                  {"forces", o.forces},       {"plot", o.plot},     {"summary", o.summary},
                  {"recording", o.recording}};
  if (!scene.scripts.empty()) j["scripts"] = scriptsJson(scene.scripts);
  if (!scene.fluids.empty()) j["fluids"] = fluidsJson(scene.fluids);
  return j;
}

}  // namespace dm
