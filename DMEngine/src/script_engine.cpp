// script_engine.cpp — the script language registry and the engine that
// ticks a scene's script over its channels (script_engine.hpp).
#include "script_engine.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <mutex>

namespace dm {

namespace {

struct Languages {
  std::mutex m;
  std::map<std::string, ScriptLoader, std::less<>> loaders;
};
Languages& languages() {
  static Languages l;
  return l;
}

bool finite(const Vec3& v) { return v.allFinite(); }

}  // namespace

std::string_view toString(ScriptEvent::Type type) noexcept {
  switch (type) {
    case ScriptEvent::Type::ContactBegan:
      return "contact_began";
    case ScriptEvent::Type::ContactEnded:
      return "contact_ended";
    case ScriptEvent::Type::Puncture:
      return "puncture";
  }
  return "?";
}

void registerScriptLanguage(std::string extension, ScriptLoader loader) {
  Languages& l = languages();
  std::lock_guard lock(l.m);
  l.loaders[std::move(extension)] = std::move(loader);
}

void unregisterScriptLanguage(std::string_view extension) {
  Languages& l = languages();
  std::lock_guard lock(l.m);
  if (auto it = l.loaders.find(extension); it != l.loaders.end()) l.loaders.erase(it);
}

Result<std::unique_ptr<ScriptInstance>> loadScript(const SceneScript& script) {
  const std::string ext = script.path.extension().string();
  ScriptLoader loader;
  std::string known;
  {
    Languages& l = languages();
    std::lock_guard lock(l.m);
    if (auto it = l.loaders.find(ext); it != l.loaders.end()) loader = it->second;
    for (const auto& [e, _] : l.loaders) known += (known.empty() ? "" : ", ") + e;
  }
  if (!loader)
    return fail(ErrorCode::Unsupported, "no script language for \"" + ext + "\" in this program",
                "scripts/" + script.name + "/source",
                known.empty()
                    ? "this build has no script language (Python needs pybind11-dev and python3-dev)"
                    : "this program runs " + known + " scripts");
  auto instance = loader(script);
  if (!instance) return instance.error().within("scripts/" + script.name);
  if (!*instance)
    return fail(ErrorCode::Internal, "the " + ext + " loader returned no script", "scripts/" + script.name);
  return std::move(*instance);
}

// The context a script's callbacks get: reads the feed's newest values
// (one reader: the script's thread), writes its held forces.
struct ScriptEngine::Context final : ScriptContext {
  Context(const SceneScript& s, ScriptFeed& f, std::vector<std::string> b, bool tool,
          std::vector<std::pair<std::string, std::string>> in)
      : scriptName(s.name),
        scriptArgs(s.args),
        feed(f),
        moving(std::move(b)),
        withTool(tool),
        held(moving.size()),
        inlets(std::move(in)),
        rates(inlets.size(), std::numeric_limits<double>::quiet_NaN()) {}
  const std::string& name() const noexcept override { return scriptName; }
  double time() const noexcept override { return now; }
  const nlohmann::json& args() const noexcept override { return scriptArgs; }
  const std::vector<std::string>& bodies() const noexcept override { return moving; }
  Result<ScriptBody> body(std::string_view body) const override {
    const std::size_t i = index(body);
    if (i == moving.size()) return notMoving(body);
    return feed.bodies.readBuffer()[i];
  }
  Status setBodyForce(std::string_view body, const Vec3& force, const Vec3& torque) override {
    const std::size_t i = index(body);
    if (i == moving.size()) return notMoving(body);
    if (!finite(force) || !finite(torque))
      return dm::fail(ErrorCode::InvalidArgument, "a force or torque that is not finite",
                      "set_force(\"" + std::string(body) + "\")");
    held[i] = {force, torque};
    dirty = true;
    return ok();
  }
  Status setInletFlowRate(std::string_view fluid, std::string_view inlet, double rate) override {
    const std::string where =
        "set_inlet_flow_rate(\"" + std::string(fluid) + "\", \"" + std::string(inlet) + "\")";
    std::size_t i = 0;
    while (i < inlets.size() && (inlets[i].first != fluid || inlets[i].second != inlet)) ++i;
    if (i == inlets.size())
      return dm::fail(ErrorCode::NotFound,
                      "no inlet \"" + std::string(inlet) + "\" of a fluid \"" + std::string(fluid) + "\"",
                      where,
                      inlets.empty() ? "the scene has no fluid inlets" : "the scene's \"fluids\" name them");
    if (!(rate >= 0.0 && rate <= 1e-3))
      return dm::fail(ErrorCode::InvalidArgument, formatString("flow rate %g m³/s", rate), where,
                      "0 to 1e-3 m³/s (1 ml/s is 1e-6)");
    rates[i] = rate;
    dirty = true;
    return ok();
  }
  bool hasTool() const noexcept override { return withTool; }
  ScriptTool tool() const override { return feed.tool.readBuffer().tool; }
  void setMetric(const std::string& key, nlohmann::json value) override {
    metricValues[key] = std::move(value);
  }
  const nlohmann::json& metrics() const noexcept override { return metricValues; }

  std::size_t index(std::string_view body) const {
    return static_cast<std::size_t>(std::find(moving.begin(), moving.end(), body) - moving.begin());
  }
  Error notMoving(std::string_view body) const {
    return dm::fail(ErrorCode::NotFound, "no moving body \"" + std::string(body) + "\"",
                    "script " + scriptName,
                    moving.empty() ? "the scene has no dynamic objects (or no physics engine)"
                                   : "the moving bodies are the scene's dynamic objects");
  }
  // Takes the newest values the other threads published (once per tick).
  void update() {
    feed.bodies.update();
    feed.tool.update();
  }
  // Hands the held forces to physics when the script changed one.
  void publish() {
    if (!dirty) return;
    feed.forces.writeBuffer() = held;  // same size: no allocation
    feed.forces.publish();
    if (!rates.empty()) {
      feed.inletRates.writeBuffer() = rates;  // same size
      feed.inletRates.publish();
    }
    dirty = false;
  }

  std::string scriptName;
  nlohmann::json scriptArgs;
  ScriptFeed& feed;
  std::vector<std::string> moving;
  bool withTool;
  std::vector<ScriptForce> held;
  std::vector<std::pair<std::string, std::string>> inlets;  // {fluid, inlet}, scene order
  std::vector<double> rates;                                // per inlet, NaN: not set
  bool dirty = false;
  double now = 0.0;
  nlohmann::json metricValues = nlohmann::json::object();
};

ScriptEngine::ScriptEngine(const SceneScript& script, std::unique_ptr<ScriptInstance> instance,
                           std::vector<std::string> bodies, bool hasTool, ScriptNames names)
    : engineName_("script:" + script.name),
      feed_(std::make_unique<ScriptFeed>(bodies.size(), names.inlets.size())),
      instance_(std::move(instance)),
      names_(std::move(names)) {
  context_ = std::make_unique<Context>(script, *feed_, std::move(bodies), hasTool, names_.inlets);
  pending_.reserve(1024 + 256);
}

ScriptEngine::~ScriptEngine() = default;

bool ScriptEngine::fail(Error e) noexcept {
  error_ = std::move(e);
  return false;
}

// The events since the last call from both threads, in time order (each
// ring is in order already; a stable sort keeps ties in it). False when the
// script failed on one (error_ holds why).
bool ScriptEngine::deliverEvents(Context& c) {
  pending_.clear();
  ScriptEventRecord r;
  while (feed_->toolEvents.tryPop(r)) pending_.push_back(r);
  while (feed_->physicsEvents.tryPop(r)) pending_.push_back(r);
  std::stable_sort(pending_.begin(), pending_.end(),
                   [](const ScriptEventRecord& a, const ScriptEventRecord& b) { return a.time < b.time; });
  for (const ScriptEventRecord& e : pending_) {
    ScriptEvent ev{.type = e.type, .time = e.time, .value = e.value};
    if (e.type == ScriptEvent::Type::Puncture) {
      if (e.source >= 0 && std::size_t(e.source) < names_.soft.size()) {
        ev.object = names_.soft[std::size_t(e.source)];
        if (names_.layer) ev.layer = names_.layer(std::size_t(e.source), e.layer);
      }
    } else if (e.source >= 0 && std::size_t(e.source) < names_.touched.size()) {
      ev.object = names_.touched[std::size_t(e.source)];
    }
    ++events_;
    if (auto s = instance_->event(c, ev); !s) return fail(s.error().within(std::string(toString(e.type))));
  }
  return true;
}

bool ScriptEngine::tick(const TickInfo& info) noexcept {
  try {
    Context& c = *context_;
    c.now = clock_.seconds(info);
    c.update();
    if (!started_) {
      started_ = true;
      if (auto s = instance_->start(c); !s) return fail(s.error().within("start"));
    }
    if (!deliverEvents(c)) return false;
    if (auto s = instance_->tick(c); !s) return fail(s.error().within(formatString("tick at %.6f s", c.now)));
    c.publish();
    ++ticks_;
    return true;
  } catch (const std::exception& e) {
    return fail(dm::fail(ErrorCode::Internal, e.what(), "script " + context_->scriptName));
  } catch (...) {
    return fail(dm::fail(ErrorCode::Internal, "an unknown exception", "script " + context_->scriptName));
  }
}

const nlohmann::json& ScriptEngine::metrics() const noexcept { return context_->metricValues; }

Result<nlohmann::json> ScriptEngine::finish(double time) {
  Context& c = *context_;
  c.now = time;
  c.update();
  // Events the other threads pushed after this engine's last tick (the
  // engines stop one by one) reach the script before it finishes.
  if (started_ && !deliverEvents(c)) return error_;
  if (auto s = instance_->finish(c); !s) return s.error().within(engineName_ + " finish");
  return nlohmann::json{{"ticks", ticks_},
                        {"events", events_},
                        {"events_dropped", feed_->droppedEvents.load(std::memory_order_relaxed)},
                        {"metrics", c.metricValues}};
}

}  // namespace dm
