// scene_script.cpp — the scene file's "scripts" (v2): each a named source
// file whose callbacks run during the run at the rate of an engine the scene
// has (never the haptic one), with the arguments it is given; their checks
// and JSON (docs/scene-format.md, "Scripts"; the runtime's side is
// dm/engine/script.hpp).
#include <set>

#include "scene_parse.hpp"

namespace dm::scene_parse {

namespace {

// The engines a script may take its rate from, and whether the scene has
// each (the monitor always runs, at 30 Hz unless the scene sets it).
constexpr std::array<std::string_view, 5> kScriptEngines = {"physics", "monitor", "render", "vision", "igtl"};

bool hasEngine(const SceneEngines& e, std::string_view name) {
  if (name == "physics") return e.physics.has_value();
  if (name == "render") return e.render.has_value();
  if (name == "vision") return e.vision.has_value();
  if (name == "igtl") return e.igtl.has_value();
  return name == "monitor";
}

// Arguments a script gets as they are: an object of at most 256 keys.
constexpr std::size_t kMaxScriptArgs = 256;

}  // namespace

void readScripts(ConfigReader& root, SceneDesc& scene, const SourceResolver& resolve) {
  ConfigReader list = root.child("scripts");
  if (!expectArray(list)) return;
  std::set<std::string, std::less<>> names;
  for (std::size_t i = 0; i < list.size(); ++i) {
    ConfigReader r = list.at(i);
    if (!expectObject(r)) continue;
    r.knownKeys({"name", "source", "engine", "args"});
    SceneScript s;
    s.name = readUniqueName(r, names, "script");
    std::size_t before = r.errors().size();
    s.source = r.string("source");
    if (r.errors().size() == before) {
      const std::string ext = std::filesystem::path(s.source).extension().string();
      if (s.source.empty())
        r.addError("source is empty", "source", "give the script's file, e.g. \"tug.py\"");
      else if (ext.size() < 2)
        r.addError("source " + inQuotes(s.source) + " has no extension, which names its language", "source",
                   "e.g. \"tug.py\" for Python");
      else
        s.path = resolve(r, s.source, "source");
    }
    before = r.errors().size();
    s.engine = r.oneOf("engine",
                       {"haptics", kScriptEngines[0], kScriptEngines[1], kScriptEngines[2], kScriptEngines[3],
                        kScriptEngines[4]},
                       s.engine);
    if (r.errors().size() == before) {
      if (s.engine == "haptics")
        r.addError("a script never runs on the haptic thread", "engine",
                   "name \"physics\" (its rate, e.g. 1 kHz) or \"monitor\"; read the tool's force from the "
                   "script's context");
      else if (!hasEngine(scene.engines, s.engine))
        r.addError("the scene has no " + s.engine + " engine to take the rate from", "engine",
                   "add \"" + s.engine + "\" under \"engines\" or name \"monitor\"");
    }
    if (r.has("args")) {
      const Json& a = r.node()["args"];
      if (!a.is_object())
        r.addError(std::string("expected an object, got ") + a.type_name(), "args",
                   "e.g. {\"force_N\": 0.5}; the script reads them as a dict");
      else if (a.size() > kMaxScriptArgs)
        r.addError(formatString("%zu arguments; at most %zu", a.size(), kMaxScriptArgs), "args");
      else
        s.args = a;
    }
    scene.scripts.push_back(std::move(s));
  }
}

Json scriptsJson(const std::vector<SceneScript>& scripts) {
  Json list = Json::array();
  for (const SceneScript& s : scripts)
    list.push_back({{"name", s.name}, {"source", s.source}, {"engine", s.engine}, {"args", s.args}});
  return list;
}

}  // namespace dm::scene_parse
