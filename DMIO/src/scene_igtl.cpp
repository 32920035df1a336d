// scene_igtl.cpp — the scene file's OpenIGTLink engine ("engines"/"igtl"):
// where it listens, what it publishes under which device names, how many
// clients the run waits for; its checks against the other engines and the
// objects, and its JSON (docs/scene-format.md, "igtl").
#include <dm/core/endpoint.hpp>

#include "scene_parse.hpp"

namespace dm::scene_parse {

namespace {

// OpenIGTLink's device-name field: char[20].
constexpr std::size_t kMaxDeviceName = 20;

// One "publish" entry that names a device: 1..20 characters.
std::string readDeviceName(ConfigReader& r, std::string_view key) {
  if (!r.has(key)) return {};
  const std::size_t before = r.errors().size();
  std::string name = r.string(key);
  if (r.errors().size() != before) return {};
  if (name.empty() || name.size() > kMaxDeviceName) {
    r.addError(formatString("device name of %zu characters; OpenIGTLink allows 1..20", name.size()), key,
               "e.g. \"ToolToScene\"");
    return {};
  }
  return name;
}

}  // namespace

void readIgtl(ConfigReader& engines, SceneEngines& e) {
  ConfigReader r = engines.child("igtl");
  if (!expectObject(r)) return;
  r.knownKeys({"rate_hz", "listen", "allow", "publish", "wait_for_clients", "wait_timeout"});
  SceneIgtlEngine g;
  g.rateHz = r.number("rate_hz", {.min = 1.0, .max = 1000.0}, g.rateHz);
  const std::size_t before = r.errors().size();
  g.listen = r.string("listen", g.listen);
  if (r.errors().size() == before)
    if (auto hp = parseHostPort(g.listen, "listen", true); !hp)
      r.addError(hp.error().what, "listen", "e.g. \"127.0.0.1:18944\" (OpenIGTLink's port) or \"0.0.0.0:0\"");
  if (r.has("allow")) {
    ConfigReader list = r.child("allow");
    if (expectArray(list))
      for (std::size_t i = 0; i < list.size(); ++i) {
        const Json& a = list.node()[i];
        if (a.is_string() && !a.get<std::string>().empty())
          g.allow.push_back(a.get<std::string>());
        else
          list.addError(std::string("expected an address or CIDR block, got ") + a.type_name(),
                        std::to_string(i), "e.g. \"10.0.0.7\" or \"192.168.1.0/24\"");
      }
  }
  ConfigReader pub = r.child("publish");
  if (expectObject(pub)) {
    const std::size_t pubBefore = pub.errors().size();
    pub.knownKeys({"tool", "handle", "force", "bodies", "image"});
    g.tool = readDeviceName(pub, "tool");
    g.handle = readDeviceName(pub, "handle");
    g.force = readDeviceName(pub, "force");
    g.bodies = pub.boolean("bodies", false);
    g.image = readDeviceName(pub, "image");
    if (pub.errors().size() == pubBefore && g.tool.empty() && g.handle.empty() && g.force.empty() &&
        g.image.empty() && !g.bodies)
      pub.addError("publishes nothing", {},
                   "name what to send, e.g. {\"tool\": \"ToolToScene\", \"force\": \"Force\"}");
    if (!g.tool.empty() && g.tool == g.handle)
      pub.addError("tool and handle are both TRANSFORM " + inQuotes(g.tool), "handle", "give them two names");
  } else if (isNull(pub)) {
    r.addError("missing required publish", "publish",
               "add \"publish\": {\"tool\": \"ToolToScene\", \"force\": \"Force\", \"image\": \"Camera\"}");
  }
  g.waitForClients = static_cast<int>(r.integer("wait_for_clients", {.min = 0, .max = 64}, 0));
  g.waitTimeout = r.number("wait_timeout", {.min = 0.1, .max = 3600.0}, g.waitTimeout);
  e.igtl = std::move(g);
}

void checkIgtl(const SceneDesc& scene, ConfigReader root) {
  const auto& g = scene.engines.igtl;
  if (!g) return;
  ConfigReader pub = root.child("engines").child("igtl").child("publish");
  for (const auto& [key, name] : {std::pair{"tool", &g->tool}, {"handle", &g->handle}, {"force", &g->force}})
    if (!name->empty() && !scene.engines.haptics)
      pub.addError(std::string(key) + " comes from the haptics engine, and there is none", key,
                   "add \"haptics\" under \"engines\" or remove \"" + std::string(key) + "\"");
  if (!g->image.empty() && !scene.engines.render)
    pub.addError("image is the render engine's frames, and there is none", "image",
                 "add \"render\" under \"engines\" or remove \"image\"");
  if (!g->bodies) return;
  std::size_t dynamic = 0;
  for (const SceneObject& o : scene.objects) {
    if (!o.dynamic) continue;
    ++dynamic;
    if (o.name.size() > kMaxDeviceName)
      pub.addError("object " + inQuotes(o.name) +
                       " is a body whose name is longer than an OpenIGTLink device "
                       "name (20 characters)",
                   "bodies", "rename the object");
    else if (o.name == g->tool || o.name == g->handle)
      pub.addError("object " + inQuotes(o.name) + " is a body with the name of another TRANSFORM", "bodies",
                   "rename the object or the tool/handle");
  }
  if (!scene.engines.physics || dynamic == 0)
    pub.addError("bodies are the physics engine's dynamic objects, and there are none", "bodies",
                 "make an object \"dynamic\" (with a physics engine) or remove \"bodies\"");
}

void writeIgtl(const SceneIgtlEngine& g, Json& engines) {
  Json pub = Json::object();
  for (const auto& [key, name] :
       {std::pair{"tool", &g.tool}, {"handle", &g.handle}, {"force", &g.force}, {"image", &g.image}})
    if (!name->empty()) pub[key] = *name;
  if (g.bodies) pub["bodies"] = true;
  engines["igtl"] = {{"rate_hz", g.rateHz},
                     {"listen", g.listen},
                     {"publish", std::move(pub)},
                     {"wait_for_clients", g.waitForClients},
                     {"wait_timeout", g.waitTimeout}};
  if (!g.allow.empty()) engines["igtl"]["allow"] = g.allow;
}

}  // namespace dm::scene_parse
