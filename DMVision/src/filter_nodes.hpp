// Internal: the node interface behind dm::FilterGraph and the table of node
// kinds (sources, filters, sinks) implemented on OpenCV in filter_nodes.cpp.
#pragma once

#include <dm/vision/filter_graph.hpp>

#include <filesystem>
#include <map>
#include <mutex>
#include <opencv2/core.hpp>

namespace dm::graph {

/// How the channels of an image value are to be read.
enum class ColorSpace : std::uint8_t { Gray, Rgb, Bgr, Rgba, Bgra, Hsv, Lab, Other };

/// A value on an edge. Only the member matching `type` is meaningful.
struct Value {
  PortType type = PortType::Image;
  cv::Mat mat;
  ColorSpace space = ColorSpace::Gray;
  std::shared_ptr<const Volume> volume;
  double scalar = 0;
  std::vector<Vec2f> points;
};

/// Before a node writes its output buffer: if anyone else (a slot, a
/// callback's copy) still holds it, let go of it so OpenCV allocates a new
/// one instead of overwriting pixels someone is reading.
inline void ownOutput(cv::Mat& m) {
  if (m.u != nullptr && m.u->refcount > 1) m.release();
}

/// The dm::Image sharing `m`'s memory (kept alive by a reference to it);
/// empty for pixel types dm::Image has no name for.
Image imageOf(const cv::Mat& m);

/// Latest image of a "slot" or "texture" sink, shared with readers on other threads.
struct SlotState {
  mutable std::mutex mutex;
  cv::Mat mat;
  std::int64_t frame = -1;
  ColorSpace space = ColorSpace::Gray;
};

/// The image the host gives an "input" source (FilterGraph::setInput),
/// shared with the host's thread.
struct InputState {
  mutable std::mutex mutex;
  Image image;  ///< empty until the first setInput()
};

/// Where nodes find things owned by the graph.
struct NodeContext {
  std::string name;
  std::map<std::string, GraphCallback, std::less<>>* callbacks = nullptr;
  std::map<std::string, std::shared_ptr<SlotState>, std::less<>>* slots = nullptr;
  std::map<std::string, std::shared_ptr<InputState>, std::less<>>* inputs = nullptr;
  std::filesystem::path outputDir;  ///< where sinks' relative paths go (empty: the working directory)
};

/// A sink's path: relative ones under the graph's output directory.
inline std::string outputPath(const NodeContext& c, std::string path) {
  if (c.outputDir.empty() || path.empty() || std::filesystem::path(path).is_absolute()) return path;
  return (c.outputDir / path).string();
}

class Node {
 public:
  virtual ~Node() = default;
  /// Sources: the next frame into `out`; false at the end of the stream.
  virtual Result<bool> read(Value& out, std::int64_t frame);
  /// Filters and sinks: `in` holds one value per input, in order.
  virtual Status process(std::span<const Value* const> in, Value& out, std::int64_t frame);
  /// Sinks: called once after the last frame (close files).
  virtual Status finish() { return ok(); }
};

/// One node kind: its public description, the parameter keys it accepts
/// and its factory. The factory reads parameters through `params`
/// (recording every problem there) and may return null when it found one.
struct KindInfo {
  GraphNodeKind info;
  std::vector<std::string_view> keys;
  std::unique_ptr<Node> (*make)(ConfigReader& params, const NodeContext& context);
};

const std::vector<KindInfo>& kindTable();
const KindInfo* findKind(std::string_view kind);

}  // namespace dm::graph
