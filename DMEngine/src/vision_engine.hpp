// vision_engine.hpp (private) — the vision engine of a scene run
// (docs/scene-format.md, "vision"): a DMVision FilterGraph stepped one frame
// per tick on its own (normal) thread. Its "input" sources get the render
// engine's newest frame through a FrameSlot — a simulated endoscope's video
// into the same filters a real one goes through — and it steps only when a
// new frame came; a graph without inputs (a video file) steps every tick
// until its source ends. Sinks write what the graph says (files, videos,
// CSV), relative paths into the run's output folder.
// Compiled only when DMVision exists.
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>
#include <dm/engine/engine.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace dm {

class FrameSlot;
struct SceneDesc;

class VisionEngineHandle {
 public:
  virtual ~VisionEngineHandle() = default;
  virtual std::shared_ptr<Engine> engine() = 0;
  /// The graph's "input" sources (they want the render engine's frames).
  virtual const std::vector<std::string>& inputs() const = 0;
  /// Where the render engine puts its frames for the inputs (before the
  /// run; not needed without inputs).
  virtual void setFrames(std::shared_ptr<FrameSlot> frames) = 0;
  /// The newest image of the scene's overlay sink (a "texture" sink) and
  /// its frame number; false before the first or without an overlay. Any
  /// thread (the render engine's).
  virtual bool overlay(Image& image, std::int64_t& frame) const = 0;
  /// Control thread, after the run: frames stepped, whether a source ended,
  /// and per node its calls and time.
  virtual nlohmann::json summary() const = 0;
};

/// Loads and validates the scene's graph (engines/vision/graph: a file or
/// inline), its sinks' relative paths under `out` (the run's folder); fails
/// naming the graph's JSON path before anything runs.
Result<std::shared_ptr<VisionEngineHandle>> makeVisionEngine(const SceneDesc& scene,
                                                             const std::filesystem::path& out);

}  // namespace dm
