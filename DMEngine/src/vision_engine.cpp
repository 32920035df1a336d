// vision_engine.cpp — a scene's filter graph, one frame per tick
// (vision_engine.hpp).
#include "vision_engine.hpp"

#include <dm/core/config.hpp>
#include <dm/core/log.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/vision/filter_graph.hpp>

#include <algorithm>

#include "frame_slot.hpp"

namespace dm {

namespace {

class VisionEngine final : public Engine, public VisionEngineHandle {
 public:
  VisionEngine(FilterGraph graph, std::string overlay)
      : graph_(std::move(graph)), inputs_(graph_.inputs()), overlay_(std::move(overlay)) {}

  std::string_view name() const noexcept override { return "vision"; }

  bool tick(const TickInfo&) noexcept override {
    try {
      return step();
    } catch (const std::exception& e) {
      error_ = fail(ErrorCode::Internal, e.what(), "engines/vision");
      return false;
    }
  }

  Status shutdown() override {
    if (auto s = graph_.finish(); !s) return s.error().within("engines/vision");
    return ok();
  }

  Error error() const override { return error_; }
  std::shared_ptr<Engine> engine() override { return self_.lock(); }
  const std::vector<std::string>& inputs() const override { return inputs_; }
  void setFrames(std::shared_ptr<FrameSlot> frames) override { frames_ = std::move(frames); }

  bool overlay(Image& image, std::int64_t& frame) const override {
    if (overlay_.empty()) return false;
    auto t = graph_.texture(overlay_);
    if (!t) return false;
    image = t->image;
    frame = t->frame;
    return true;
  }

  nlohmann::json summary() const override {
    nlohmann::json nodes = nlohmann::json::array();
    for (const GraphNodeStats& n : graph_.nodeStats())
      nodes.push_back({{"name", n.name}, {"kind", n.kind}, {"calls", n.calls}, {"seconds", n.seconds}});
    return {{"frames", stepped_}, {"source_ended", ended_}, {"inputs", inputs_}, {"nodes", std::move(nodes)}};
  }

  std::weak_ptr<VisionEngine> self_;

 private:
  bool step() {
    if (ended_) return true;
    if (!inputs_.empty()) {
      double t = 0.0;
      if (!frames_ || !frames_->takeIfNewer(seen_, frame_, t)) return true;  // no new frame: nothing to do
      for (const std::string& input : inputs_)
        if (auto s = graph_.setInput(input, frame_); !s) {
          error_ = s.error().within("engines/vision");
          return false;
        }
    }
    auto more = graph_.step();
    if (!more) {
      error_ = more.error().within("engines/vision/graph");
      return false;
    }
    if (*more) {
      ++stepped_;
    } else {
      ended_ = true;  // a source ended (a video file): the run goes on
    }
    return true;
  }

  FilterGraph graph_;
  std::vector<std::string> inputs_;
  std::string overlay_;  // the "texture" sink drawn over the rendered frames, or empty
  std::shared_ptr<FrameSlot> frames_;
  std::uint64_t seen_ = 0;
  Image frame_;
  std::uint64_t stepped_ = 0;
  bool ended_ = false;
  Error error_;
};

}  // namespace

Result<std::shared_ptr<VisionEngineHandle>> makeVisionEngine(const SceneDesc& scene,
                                                             const std::filesystem::path& out) {
  const SceneVisionEngine& v = *scene.engines.vision;
  auto graph = v.graphFile.empty() ? FilterGraph::parse(v.graph.dump(), "engines/vision/graph")
                                   : FilterGraph::load(v.graphFile);
  if (!graph) return graph.error().within("engines/vision/graph");
  graph->setOutputDirectory(out);  // the sinks write into the run's folder
  if (auto s = graph->validate(); !s) return s.error().within("engines/vision/graph");
  if (!v.overlay.empty()) {
    const std::vector<std::string> order = graph->order();
    const bool found = std::find(order.begin(), order.end(), v.overlay) != order.end();
    if (!found || graph->nodeKind(v.overlay) != "texture")
      return fail(
          ErrorCode::InvalidArgument,
          "\"" + v.overlay + "\" is " + (found ? "not a \"texture\" sink" : "no node") + " of the graph",
          "engines/vision/overlay", "name a node {\"kind\": \"texture\", \"input\": ...}");
  }
  auto e = std::make_shared<VisionEngine>(std::move(*graph), v.overlay);
  e->self_ = e;
  if (!e->inputs().empty() && !scene.engines.render)
    return fail(ErrorCode::InvalidArgument,
                "the graph's \"input\" sources (" + e->inputs().front() +
                    ") take the render engine's frames, and there is none",
                "engines/vision/graph", "add \"render\" under \"engines\", or read a video_file instead");
  return std::shared_ptr<VisionEngineHandle>(e);
}

}  // namespace dm
