// igtl_engine.hpp (private) — the OpenIGTLink server engine of a scene run
// (docs/scene-format.md, "igtl"): a dm::IgtlServer on its own network
// thread that publishes, at the engine's rate, what the scene names — the
// tool (the haptic proxy) and the handle as TRANSFORM, the force sent to
// the hand as SENSOR (N), each dynamic body as TRANSFORM, the rendered
// frames as IMAGE (RGB) — to every client (as PLUS streams: 3D Slicer shows
// what arrives) and for GET_/STT_ queries, and answers those queries.
// Compiled only when DMNetwork exists.
//
// Data flow: the haptics engine → a TripleBuffer of its newest sample; the
// physics engine → its PoseReader::Network triple buffer; the render engine
// → a FrameSlot. The engine ticks on a normal (not real-time) thread: it
// encodes and queues (allocating), and never blocks on a client — a client
// whose queue is full misses messages (counted), the run goes on.
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/engine/engine.hpp>

#include <nlohmann/json.hpp>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace dm {

class FrameSlot;
struct SceneIgtlEngine;

/// What the engine reads from the others (its thread).
struct IgtlFeed {
  /// The newest haptic tick: the tool's pose (the proxy), the handle's
  /// pose and the force sent to the hand, all world, and the tick's scene
  /// time (their timestamp); false before the first.
  std::function<bool(Isometry3& tool, Isometry3& handle, Vec3& force, double& t)> haptics;
  /// The dynamic objects, and their newest poses in that order (false when
  /// no physics step finished since the last call).
  std::vector<std::string> bodies;
  std::function<bool(std::vector<Isometry3>& poses)> bodyPoses;
  /// The render engine's frames; null without a render engine.
  std::shared_ptr<FrameSlot> frames;
};

/// The engine (to add to the master), its address and its counters.
class IgtlEngineHandle {
 public:
  virtual ~IgtlEngineHandle() = default;
  virtual std::shared_ptr<Engine> engine() = 0;
  /// The port listened on (the free one picked for port 0).
  virtual std::uint16_t port() const = 0;
  /// Control thread, before the run: returns once `settings.waitForClients`
  /// clients are connected, or at once when `stop` is raised (the run then
  /// stops too); fails (Timeout) after `settings.waitTimeout`.
  virtual Status waitForClients(const std::atomic<bool>* stop) = 0;
  /// Control thread, after the run: messages published per kind, clients,
  /// messages the clients' queues refused.
  virtual nlohmann::json summary() const = 0;
};

/// Starts the server (listening, before the run, so that clients may
/// connect while the scene loads). Fails naming engines/igtl/listen when
/// the address is bad or the port is taken. `frameBytes`: the size of one
/// RGB frame (width × height × 3; 0 without frames), which a client's send
/// queue must hold twice.
Result<std::shared_ptr<IgtlEngineHandle>> makeIgtlEngine(const SceneIgtlEngine& settings, IgtlFeed feed,
                                                         std::size_t frameBytes);

}  // namespace dm
