// dm/vision/filter_graph.hpp — image and video pipelines as a graph of typed
// nodes, described in code or in JSON, validated before running and executed
// in parallel where the graph allows.
//
// A node has a kind (a source, a filter or a sink; FilterGraph::kinds() lists
// them), a unique name, parameters and named inputs. Values flowing along the
// edges are typed: Image, Volume, Number (a scalar) or PointSet. validate() checks every
// parameter (errors carry the JSON path, e.g. "/nodes/3/ksize", and a "did
// you mean" for misspelt kinds and keys), every input name and port type, and
// that the graph has no cycle. run() then pulls one frame from every source
// per step (a frame ends when any source ends) and evaluates the graph: nodes
// whose inputs are ready run concurrently as oneTBB tasks, and the
// sources read the next frame while the current one is filtered. A host
// that ticks the graph instead calls step() (one frame, nodes in order) and
// feeds "input" sources its own images (setInput: a scene's rendered
// frames).
//
// Images keep OpenCV's memory: a sink hands out a dm::Image wrapping the
// node's output buffer with shared ownership, so a camera frame reaches a
// renderer texture with no copy and no conversion: a "texture" sink keeps
// the latest frame with its frame number and channel order
// (FilterGraph::texture), and the render thread hands it to
// SceneRenderer::updateTexture (any stride; BGR sampled through a swizzle). A node never overwrites a buffer someone still holds: it
// allocates a fresh one for the next frame instead. Colour images are RGB
// unless a source is told "order": "bgr" (OpenCV's own order, saving one
// conversion per frame); nodes that care about the order know it.
//
// JSON form (paths go through dm::FileSystem, so "opencv:vtest.avi" works):
//   {"nodes": [
//     {"name": "video", "kind": "video_file", "path": "opencv:vtest.avi"},
//     {"name": "gray",  "kind": "color", "input": "video", "code": "gray"},
//     {"name": "fg",    "kind": "background_subtraction", "input": "gray"},
//     {"name": "save",  "kind": "file", "input": "fg", "pattern": "out/fg_%04d.png", "every": 25}
//   ]}
// "input" names one upstream node; "inputs" (an array) names several, in
// the order the node expects them.
//
// @code
//   auto g = dm::FilterGraph::load("pipeline.json");
//   if (!g) return g.error();
//   g->setCallback("edges", [](const dm::GraphValue& v, std::int64_t frame) { use(*v.image); });
//   auto stats = g->run({.maxFrames = 100});
// @endcode
#pragma once

#include <dm/core/config.hpp>
#include <dm/core/image.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

/// The type of a value on a graph edge.
enum class PortType : std::uint8_t { Image, Volume, Number, PointSet };
const char* toString(PortType t) noexcept;

/// A value as a sink callback sees it. Exactly the member matching `type` is
/// set. The image wraps the producing node's buffer: copy the dm::Image
/// (shared ownership, no pixel copy) to keep it past the callback.
struct GraphValue {
  PortType type = PortType::Image;
  const Image* image = nullptr;
  const Volume* volume = nullptr;
  double scalar = 0;
  std::span<const Vec2f> points;  ///< pixel coordinates (x right, y down)
};

/// The latest frame of a "texture" sink: the image shares the producing
/// node's buffer (it stays valid while held; the node writes its next frame
/// elsewhere), `frame` tells a reader whether it changed, and `bgr` whether
/// the channels are in OpenCV's B,G,R(,A) order (a source with "order":
/// "bgr"), which SceneRenderer samples through a swizzle instead of
/// converting (SceneTextureOptions::bgr).
struct GraphTexture {
  Image image;
  std::int64_t frame = -1;
  bool bgr = false;
};

/// Called by a "callback" sink on the graph's worker threads, once per frame
/// in frame order (never concurrently with itself).
using GraphCallback = std::function<void(const GraphValue& value, std::int64_t frame)>;

/// Options for FilterGraph::run.
struct GraphRunOptions {
  std::int64_t maxFrames = -1;  ///< stop after this many frames (-1: when a source ends)
  bool parallel = true;         ///< false: evaluate nodes one by one in topological order
};

/// Per-node timing from run().
struct GraphNodeStats {
  std::string name;
  std::string kind;
  std::int64_t calls = 0;
  double seconds = 0;  ///< total time inside the node
};

/// What run() did.
struct GraphRunStats {
  std::int64_t frames = 0;
  double seconds = 0;  ///< wall time of the run
  double framesPerSecond = 0;
  std::vector<GraphNodeStats> nodes;  ///< in the order the nodes were added
};

/// One node kind: its inputs' and output's types, for documentation and
/// error messages. A sink has no output.
struct GraphNodeKind {
  std::string kind;
  std::string role;              ///< "source", "filter" or "sink"
  std::vector<PortType> inputs;  ///< one per input, in order
  bool anyInputType = false;     ///< one input of any type (callback sinks)
  std::optional<PortType> output;
  std::string summary;
};

/// A typed node graph over OpenCV (see the file comment). Movable, not
/// copyable. Not thread-safe except where noted: build, validate and run
/// from one thread; slot() may be called from any thread during run().
class FilterGraph {
 public:
  FilterGraph();
  ~FilterGraph();
  FilterGraph(FilterGraph&&) noexcept;
  FilterGraph& operator=(FilterGraph&&) noexcept;

  /// Builds a graph from {"nodes": [...]} and validates it. Errors carry the
  /// JSON path of every problem found (all of them, not just the first).
  static Result<FilterGraph> fromConfig(const Config& config);
  static Result<FilterGraph> parse(std::string_view json, std::string source = "<string>");
  static Result<FilterGraph> load(const std::filesystem::path& file);

  /// Adds a node in code; `params` is the node's JSON object without
  /// "name"/"kind"/"input(s)". Checked by validate().
  void add(std::string name, std::string kind, Json params = Json::object(),
           std::vector<std::string> inputs = {});
  /// Sets the function a "callback" sink calls. Fails if `sink` is not a
  /// callback node.
  Status setCallback(std::string_view sink, GraphCallback callback);

  /// Checks parameters, inputs, port types and cycles and prepares the
  /// nodes (opens files and devices). Called by run() when needed.
  Status validate();
  /// Runs until a source ends or options.maxFrames; stops at the first node
  /// error, which names the node, its kind and the frame.
  Result<GraphRunStats> run(const GraphRunOptions& options = {});

  /// Frame by frame, for a host that ticks the graph (a scene's vision
  /// engine): step() reads one frame from every source and runs every node
  /// on it, one after another in topological order; false (and nothing
  /// run) once a source has ended, and on every call after. An error names
  /// the node, its kind and the frame. finish() closes the sinks (files)
  /// after the last step. Don't mix with run() on one graph.
  /// @code
  ///   (void)graph.setInput("endoscope", renderedFrame);
  ///   if (auto more = graph.step(); !more) return more.error();
  /// @endcode
  Result<bool> step();
  Status finish();
  /// Where the sinks' relative paths ("file" patterns, "video_writer" and
  /// "csv" paths) go, instead of the working directory (a scene run: its
  /// output folder). Before validate().
  void setOutputDirectory(std::filesystem::path dir);
  /// Gives the "input" source `source` the image its reads return from now
  /// on (8-bit gray, RGB or RGBA; shared, not copied: replace it, never
  /// write into it). NotFound for another name. Thread-safe; after validate().
  Status setInput(std::string_view source, const Image& image);
  /// The names of the "input" sources (after validate()).
  std::vector<std::string> inputs() const;
  /// Per-node calls and time so far (step() or run()).
  std::vector<GraphNodeStats> nodeStats() const;

  /// The latest image a "slot" sink received, sharing its memory; nullopt
  /// before the first frame. Thread-safe.
  std::optional<Image> slot(std::string_view name) const;
  /// The latest frame a "texture" (or "slot") sink received, for a renderer
  /// thread to upload once per render frame without converting it:
  /// @code
  ///   if (auto t = graph.texture("endoscope"); t && t->frame != shown) {
  ///     scene.updateTexture(tex, t->image);  // texture made with {.bgr = t->bgr, .mipmaps = false}
  ///     shown = t->frame;
  ///   }
  /// @endcode
  /// nullopt before the first frame or for other names. Thread-safe.
  std::optional<GraphTexture> texture(std::string_view name) const;
  /// Node names in topological order (after validate()).
  std::vector<std::string> order() const;
  /// The kind of node `name` ("" when there is none).
  std::string nodeKind(std::string_view name) const;

  /// Every node kind the graph knows.
  static const std::vector<GraphNodeKind>& kinds();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
