// dm::FilterGraph: building, validation (parameters, inputs, types, cycles)
// and execution on oneTBB tasks by dependency counting, with the sources reading the next
// frame while the current one is filtered.
#include <oneapi/tbb/task_group.h>

#include <atomic>
#include <chrono>
#include <functional>
#include <map>
#include <opencv2/core.hpp>
#include <optional>

#include "filter_nodes.hpp"

namespace dm {

const char* toString(PortType t) noexcept {
  switch (t) {
    case PortType::Image:
      return "image";
    case PortType::Volume:
      return "volume";
    case PortType::Number:
      return "number";
    case PortType::PointSet:
      return "point set";
  }
  return "?";
}

namespace {

using Clock = std::chrono::steady_clock;

struct NodeEntry {
  std::string name;
  std::string kind;
  Json params;                      // without name/kind/input(s)
  std::vector<std::string> inputs;  // names
  std::string path;                 // JSON path for errors ("/nodes/3"), or "node \"x\""
  // Set by validate():
  const graph::KindInfo* info = nullptr;
  std::unique_ptr<graph::Node> node;
  std::vector<std::size_t> in;  // indices of the inputs
  std::int64_t calls = 0;
  double seconds = 0;
};

bool isSource(const NodeEntry& e) { return e.info->info.role == "source"; }

std::string withArticle(PortType t) {
  return (t == PortType::Image ? "an " : "a ") + std::string(toString(t));
}

// One filter or sink on the frame's values (inputs by index into `values`),
// timed; an OpenCV exception becomes an error.
Status processNode(NodeEntry& e, const std::vector<graph::Value>& values, graph::Value& out,
                   std::int64_t frame) {
  const graph::Value* ins[2] = {nullptr, nullptr};
  for (std::size_t k = 0; k < e.in.size(); ++k) ins[k] = &values[e.in[k]];
  const auto t0 = Clock::now();
  Status s = ok();
  try {
    s = e.node->process(std::span<const graph::Value* const>(ins, e.in.size()), out, frame);
  } catch (const std::exception& ex) {
    s = fail(ErrorCode::Internal, std::string("OpenCV: ") + ex.what(), "", "check the input's size and type");
  }
  e.seconds += std::chrono::duration<double>(Clock::now() - t0).count();
  ++e.calls;
  return s;
}

// One source's next frame, timed; an OpenCV exception becomes an error.
Result<bool> readSource(NodeEntry& e, graph::Value& out, std::int64_t frame) {
  const auto t0 = Clock::now();
  Result<bool> r = false;
  try {
    r = e.node->read(out, frame);
  } catch (const std::exception& ex) {
    r = fail(ErrorCode::Io, std::string("OpenCV: ") + ex.what(), "");
  }
  e.seconds += std::chrono::duration<double>(Clock::now() - t0).count();
  ++e.calls;
  return r;
}

// An error of node `e` at `frame`, located as run() locates them.
Error atNode(const NodeEntry& e, Error err, std::int64_t frame) {
  err.where = "node \"" + e.name + "\" (" + e.kind + "), frame " + std::to_string(frame) +
              (err.where.empty() ? "" : ": " + err.where);
  return err;
}

}  // namespace

struct FilterGraph::Impl {
  std::string source = "<code>";
  std::vector<NodeEntry> nodes;
  std::vector<std::size_t> order;  // topological
  bool validated = false;
  std::map<std::string, GraphCallback, std::less<>> callbacks;
  std::map<std::string, std::shared_ptr<graph::SlotState>, std::less<>> slots;
  std::map<std::string, std::shared_ptr<graph::InputState>, std::less<>> inputs;
  std::filesystem::path outputDir;  // sinks' relative paths go here
  // step(): the values of the frame being stepped, its number, whether a
  // source has ended.
  std::vector<graph::Value> stepValues;
  std::int64_t stepFrame = 0;
  bool stepEnded = false;

  Error located(const std::string& where, std::string what, std::string hint = {}) const {
    return Error{ErrorCode::InvalidArgument, std::move(what), source + ": " + where, std::move(hint)};
  }
};

FilterGraph::FilterGraph() : impl_(std::make_unique<Impl>()) {}
FilterGraph::~FilterGraph() = default;
FilterGraph::FilterGraph(FilterGraph&&) noexcept = default;
FilterGraph& FilterGraph::operator=(FilterGraph&&) noexcept = default;

const std::vector<GraphNodeKind>& FilterGraph::kinds() {
  static const std::vector<GraphNodeKind> list = [] {
    std::vector<GraphNodeKind> l;
    for (const auto& k : graph::kindTable()) l.push_back(k.info);
    return l;
  }();
  return list;
}

void FilterGraph::add(std::string name, std::string kind, Json params, std::vector<std::string> inputs) {
  NodeEntry e;
  e.path = "node \"" + name + "\"";
  e.name = std::move(name);
  e.kind = std::move(kind);
  e.params = params.is_null() ? Json::object() : std::move(params);
  e.inputs = std::move(inputs);
  impl_->nodes.push_back(std::move(e));
  impl_->validated = false;
}

Result<FilterGraph> FilterGraph::fromConfig(const Config& config) {
  FilterGraph g;
  g.impl_->source = config.source();
  ConfigReader root = config.reader();
  root.knownKeys({"nodes"});
  ConfigReader nodes = root.child("nodes", true);
  if (nodes.node().is_null() || !nodes.isArray()) {
    if (!nodes.node().is_null()) root.addError("must be an array of node objects", "nodes");
    if (auto s = root.status(); !s) return s.error();
  }
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    ConfigReader n = nodes.at(i);
    if (!n.isObject()) {
      n.addError("a node must be an object with name, kind and parameters");
      continue;
    }
    NodeEntry e;
    e.path = n.path();
    e.name = n.string("name");
    e.kind = n.string("kind");
    if (n.has("input") && n.has("inputs")) n.addError("give either input or inputs, not both", "inputs");
    if (n.has("input")) {
      e.inputs.push_back(n.string("input"));
    } else if (n.has("inputs")) {
      const Json& list = n.node()["inputs"];
      if (!list.is_array()) {
        n.addError("must be an array of node names", "inputs");
      } else {
        for (std::size_t k = 0; k < list.size(); ++k) {
          if (list[k].is_string())
            e.inputs.push_back(list[k].get<std::string>());
          else
            n.addError("must be a node name", "inputs/" + std::to_string(k));
        }
      }
    }
    e.params = n.node();
    for (const char* key : {"name", "kind", "input", "inputs"}) e.params.erase(key);
    g.impl_->nodes.push_back(std::move(e));
  }
  if (auto s = root.status(); !s) return s.error();
  if (auto s = g.validate(); !s) return s.error();
  return g;
}

Result<FilterGraph> FilterGraph::parse(std::string_view json, std::string source) {
  auto cfg = Config::parse(json, std::move(source));
  if (!cfg) return cfg.error();
  return fromConfig(*cfg);
}

Result<FilterGraph> FilterGraph::load(const std::filesystem::path& file) {
  auto cfg = Config::load(file);
  if (!cfg) return cfg.error();
  return fromConfig(*cfg);
}

Status FilterGraph::setCallback(std::string_view sink, GraphCallback callback) {
  for (const auto& e : impl_->nodes) {
    if (e.name != sink) continue;
    if (e.kind != "callback")
      return fail(ErrorCode::InvalidArgument,
                  "node \"" + e.name + "\" is a " + e.kind + ", not a callback sink",
                  "FilterGraph::setCallback");
    impl_->callbacks[e.name] = std::move(callback);
    return ok();
  }
  return fail(ErrorCode::NotFound, "no node named \"" + std::string(sink) + "\"", "FilterGraph::setCallback");
}

Status FilterGraph::validate() {
  Impl& g = *impl_;
  std::vector<Error> problems;
  auto problem = [&](const NodeEntry& e, std::string key, std::string what, std::string hint = {}) {
    problems.push_back(g.located(e.path + (key.empty() ? "" : "/" + key), std::move(what), std::move(hint)));
  };
  std::vector<std::string_view> kindNames;
  for (const auto& k : graph::kindTable()) kindNames.push_back(k.info.kind);

  // Names and kinds; then each node's parameters through its factory.
  std::map<std::string, std::size_t, std::less<>> byName;
  for (std::size_t i = 0; i < g.nodes.size(); ++i) {
    NodeEntry& e = g.nodes[i];
    e.node.reset();
    e.in.clear();
    if (e.name.empty()) problem(e, "name", "a node needs a non-empty name");
    if (!e.name.empty() && !byName.emplace(e.name, i).second)
      problem(e, "name", "the name \"" + e.name + "\" is used twice", "node names must be unique");
    e.info = graph::findKind(e.kind);
    if (e.info == nullptr) {
      const std::string near = closestMatch(e.kind, kindNames);
      problem(e, "kind", "unknown node kind \"" + e.kind + "\"",
              near.empty() ? "FilterGraph::kinds() lists them" : "did you mean \"" + near + "\"?");
      continue;
    }
    ConfigReader params(e.params, g.source, e.path);
    std::vector<std::string_view> keys = e.info->keys;
    params.knownKeys(keys);
    graph::NodeContext context{e.name, &g.callbacks, &g.slots, &g.inputs, g.outputDir};
    try {
      e.node = e.info->make(params, context);
    } catch (const std::exception& ex) {  // OpenCV throws cv::Exception on what it refuses
      params.addError(std::string("OpenCV refused the parameters: ") + ex.what());
    }
    for (const Error& err : params.errors()) problems.push_back(err);
    if (!params.errors().empty()) e.node.reset();
  }

  // Inputs: they exist, their count and their types match the kind.
  for (NodeEntry& e : g.nodes) {
    if (e.info == nullptr) continue;
    const auto& want = e.info->info.inputs;
    const std::size_t expected = e.info->info.anyInputType ? 1 : want.size();
    if (e.inputs.size() != expected) {
      problem(e, e.inputs.size() > 1 ? "inputs" : "input",
              e.kind + " takes " + std::to_string(expected) + " input" + (expected == 1 ? "" : "s") +
                  ", got " + std::to_string(e.inputs.size()),
              expected == 0 ? "sources have no input" : "name the upstream node(s) in \"input\"/\"inputs\"");
      continue;
    }
    for (std::size_t k = 0; k < e.inputs.size(); ++k) {
      const std::string key = expected > 1 ? "inputs/" + std::to_string(k) : "input";
      auto it = byName.find(e.inputs[k]);
      if (it == byName.end()) {
        std::vector<std::string_view> names;
        for (const auto& [n, idx] : byName) names.push_back(n);
        const std::string near = closestMatch(e.inputs[k], names);
        problem(e, key, "no node named \"" + e.inputs[k] + "\"",
                near.empty() ? "" : "did you mean \"" + near + "\"?");
        continue;
      }
      const NodeEntry& from = g.nodes[it->second];
      e.in.push_back(it->second);
      if (from.info == nullptr) continue;
      if (!from.info->info.output) {
        problem(e, key, "\"" + from.name + "\" is a sink and has no output");
        continue;
      }
      if (!e.info->info.anyInputType && *from.info->info.output != want[k])
        problem(e, key,
                e.kind + " needs " + (want.size() > 1 ? "input " + std::to_string(k) + " to be " : "") +
                    withArticle(want[k]) + ", but \"" + from.name + "\" (" + from.kind + ") gives " +
                    withArticle(*from.info->info.output));
    }
  }

  // Cycles (Kahn's algorithm; what is left over lies on or behind a cycle).
  g.order.clear();
  if (problems.empty()) {
    const std::size_t n = g.nodes.size();
    std::vector<int> pending(n, 0);
    std::vector<std::vector<std::size_t>> out(n);
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j : g.nodes[i].in) {
        ++pending[i];
        out[j].push_back(i);
      }
    std::vector<std::size_t> ready;
    for (std::size_t i = 0; i < n; ++i)
      if (pending[i] == 0) ready.push_back(i);
    while (!ready.empty()) {
      const std::size_t i = ready.back();
      ready.pop_back();
      g.order.push_back(i);
      for (std::size_t k : out[i])
        if (--pending[k] == 0) ready.push_back(k);
    }
    if (g.order.size() != n) {
      // Walk inputs from a node left over until a node repeats: that is a cycle.
      std::size_t at = 0;
      while (pending[at] == 0) ++at;
      std::vector<std::size_t> walk;
      std::vector<int> seen(n, -1);
      while (seen[at] < 0) {
        seen[at] = int(walk.size());
        walk.push_back(at);
        for (std::size_t j : g.nodes[at].in)
          if (pending[j] > 0) {
            at = j;
            break;
          }
      }
      // The walk follows inputs, against the data flow: print it reversed.
      std::string cycle;
      for (std::size_t k = walk.size(); k-- > std::size_t(seen[at]);) cycle += g.nodes[walk[k]].name + " -> ";
      cycle += g.nodes[walk.back()].name;
      problem(g.nodes[at], "input", "the graph has a cycle: " + cycle,
              "a node cannot depend on its own output");
      g.order.clear();
    }
  }
  bool anySource = false, anySink = false;
  for (const NodeEntry& e : g.nodes)
    if (e.info != nullptr) {
      anySource |= isSource(e);
      anySink |= e.info->info.role == "sink";
    }
  if (!g.nodes.empty() && problems.empty() && !anySource)
    problems.push_back(
        g.located("/nodes", "the graph has no source", "add e.g. a video_file or image_file node"));
  if (g.nodes.empty()) problems.push_back(g.located("/nodes", "the graph has no nodes"));
  (void)anySink;  // a graph of only sources and filters is allowed: run() still times it

  if (problems.empty()) {
    g.validated = true;
    return ok();
  }
  return combineErrors(problems);
}

std::vector<std::string> FilterGraph::order() const {
  std::vector<std::string> names;
  for (std::size_t i : impl_->order) names.push_back(impl_->nodes[i].name);
  return names;
}

std::optional<GraphTexture> FilterGraph::texture(std::string_view name) const {
  auto it = impl_->slots.find(name);
  if (it == impl_->slots.end()) return std::nullopt;
  GraphTexture t;
  cv::Mat m;
  graph::ColorSpace space;
  {
    std::lock_guard lock(it->second->mutex);
    m = it->second->mat;
    t.frame = it->second->frame;
    space = it->second->space;
  }
  if (m.empty()) return std::nullopt;
  t.image = graph::imageOf(m);
  t.bgr = space == graph::ColorSpace::Bgr || space == graph::ColorSpace::Bgra;
  return t;
}

std::optional<Image> FilterGraph::slot(std::string_view name) const {
  auto it = impl_->slots.find(name);
  if (it == impl_->slots.end()) return std::nullopt;
  cv::Mat m;
  {
    std::lock_guard lock(it->second->mutex);
    m = it->second->mat;
  }
  if (m.empty()) return std::nullopt;
  return graph::imageOf(m);
}

Result<GraphRunStats> FilterGraph::run(const GraphRunOptions& options) {
  Impl& g = *impl_;
  if (!g.validated)
    if (auto s = validate(); !s) return s.error();
  const std::size_t n = g.nodes.size();
  std::vector<graph::Value> values(n);
  std::vector<std::size_t> sources, work;
  for (std::size_t i : g.order) (isSource(g.nodes[i]) ? sources : work).push_back(i);
  for (NodeEntry& e : g.nodes) e.calls = 0, e.seconds = 0;

  std::mutex errorMutex;
  std::optional<Error> firstError;
  std::atomic<bool> failed{false};
  auto recordError = [&](const NodeEntry& e, const Error& err, std::int64_t frame) {
    std::lock_guard lock(errorMutex);
    if (firstError) return;
    firstError = atNode(e, err, frame);
    failed = true;
  };

  std::int64_t frame = 0;
  auto runNode = [&](std::size_t i) {
    if (failed.load(std::memory_order_relaxed)) return;
    if (Status s = processNode(g.nodes[i], values, values[i], frame); !s)
      recordError(g.nodes[i], s.error(), frame);
  };

  // Dependency counting over oneTBB tasks: a filter or sink runs once all of
  // its upstream filters of this frame are done (source values are in place
  // before the frame starts). A finished node runs one ready successor itself
  // and spawns the others, so a chain costs no task hand-offs.
  std::vector<int> indegree(n, 0);
  std::vector<std::vector<std::size_t>> successors(n);
  for (std::size_t i : work) {
    std::vector<std::size_t> linked;
    for (std::size_t j : g.nodes[i].in)
      if (!isSource(g.nodes[j]) && std::find(linked.begin(), linked.end(), j) == linked.end()) {
        linked.push_back(j);
        successors[j].push_back(i);
      }
    indegree[i] = int(linked.size());
  }
  std::unique_ptr<std::atomic<int>[]> pending(new std::atomic<int>[n]);
  tbb::task_group tasks;
  struct Scheduler {
    const std::vector<std::vector<std::size_t>>& successors;
    std::atomic<int>* pending;
    tbb::task_group& tasks;
    const std::function<void(std::size_t)>& run;
    void execute(std::size_t i) const {
      for (;;) {
        run(i);
        std::optional<std::size_t> next;
        for (std::size_t k : successors[i]) {
          if (pending[k].fetch_sub(1, std::memory_order_acq_rel) != 1) continue;
          if (!next)
            next = k;
          else
            tasks.run([this, k] { execute(k); });
        }
        if (!next) return;
        i = *next;
      }
    }
  };
  const std::function<void(std::size_t)> runOne = runNode;
  const Scheduler scheduler{successors, pending.get(), tasks, runOne};
  auto runFrame = [&] {
    for (std::size_t i : work) pending[i].store(indegree[i], std::memory_order_relaxed);
    for (std::size_t i : work)
      if (indegree[i] == 0) tasks.run([&scheduler, i] { scheduler.execute(i); });
    tasks.wait();
  };

  // Two buffers per source: one being filtered, one being read.
  std::vector<graph::Value> next(n);
  auto readSources = [&](std::int64_t k, bool& more) {
    more = true;
    for (std::size_t i : sources) {
      NodeEntry& e = g.nodes[i];
      Result<bool> r = readSource(e, next[i], k);
      if (!r) {
        recordError(e, r.error(), k);
        more = false;
        return;
      }
      if (!*r) {
        more = false;
        return;
      }
    }
  };

  const auto t0 = Clock::now();
  bool more = true;
  readSources(0, more);
  tbb::task_group prefetch;
  while (more && !failed && (options.maxFrames < 0 || frame < options.maxFrames)) {
    for (std::size_t i : sources) std::swap(values[i], next[i]);
    const bool wantNext = options.maxFrames < 0 || frame + 1 < options.maxFrames;
    bool nextMore = false;
    if (wantNext) prefetch.run([&, k = frame + 1] { readSources(k, nextMore); });
    if (options.parallel) {
      runFrame();
    } else {
      for (std::size_t i : work) runNode(i);
    }
    prefetch.wait();
    ++frame;
    more = wantNext && nextMore;
  }
  for (std::size_t i : g.order)
    if (auto s = g.nodes[i].node->finish(); !s) recordError(g.nodes[i], s.error(), frame);
  if (firstError) return *firstError;

  GraphRunStats stats;
  stats.frames = frame;
  stats.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  stats.framesPerSecond = stats.seconds > 0 ? double(frame) / stats.seconds : 0;
  for (const NodeEntry& e : g.nodes) stats.nodes.push_back({e.name, e.kind, e.calls, e.seconds});
  return stats;
}

void FilterGraph::setOutputDirectory(std::filesystem::path dir) {
  impl_->outputDir = std::move(dir);
  impl_->validated = false;
}

std::string FilterGraph::nodeKind(std::string_view name) const {
  for (const NodeEntry& e : impl_->nodes)
    if (e.name == name) return e.kind;
  return {};
}

Status FilterGraph::setInput(std::string_view source, const Image& image) {
  auto it = impl_->inputs.find(source);
  if (it == impl_->inputs.end())
    return fail(
        ErrorCode::NotFound, "no \"input\" node named \"" + std::string(source) + "\"", impl_->source,
        "validate() the graph first; inputs: " + [&] {
          std::string names;
          for (const auto& [name, state] : impl_->inputs) names += (names.empty() ? "" : ", ") + name;
          return names.empty() ? std::string("none") : names;
        }());
  std::lock_guard lock(it->second->mutex);
  it->second->image = image;
  return ok();
}

std::vector<std::string> FilterGraph::inputs() const {
  std::vector<std::string> names;
  for (const auto& [name, state] : impl_->inputs) names.push_back(name);
  return names;
}

Result<bool> FilterGraph::step() {
  Impl& g = *impl_;
  if (!g.validated)
    if (auto s = validate(); !s) return s.error();
  if (g.stepEnded) return false;
  g.stepValues.resize(g.nodes.size());
  const std::int64_t frame = g.stepFrame;
  for (std::size_t i : g.order) {
    NodeEntry& e = g.nodes[i];
    if (isSource(e)) {
      Result<bool> r = readSource(e, g.stepValues[i], frame);
      if (!r) return atNode(e, r.error(), frame);
      if (!*r) {
        g.stepEnded = true;
        return false;
      }
    } else if (Status s = processNode(e, g.stepValues, g.stepValues[i], frame); !s) {
      return atNode(e, s.error(), frame);
    }
  }
  ++g.stepFrame;
  return true;
}

Status FilterGraph::finish() {
  Impl& g = *impl_;
  if (!g.validated) return ok();
  for (std::size_t i : g.order)
    if (auto s = g.nodes[i].node->finish(); !s) return atNode(g.nodes[i], s.error(), g.stepFrame);
  return ok();
}

std::vector<GraphNodeStats> FilterGraph::nodeStats() const {
  std::vector<GraphNodeStats> stats;
  for (const NodeEntry& e : impl_->nodes) stats.push_back({e.name, e.kind, e.calls, e.seconds});
  return stats;
}

}  // namespace dm
