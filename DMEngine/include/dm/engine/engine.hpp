// dm/engine/engine.hpp — one engine of a simulation (haptics, physics,
// collision, rendering, vision, network, devices, or user code): loaded once,
// ticked at its own rate by the MasterEngine (dm/engine/master_engine.hpp),
// shut down once.
//
// tick() runs on the engine's real-time thread (or, in lockstep, on the
// thread that advances the virtual clock). An engine that runs at haptic
// rates must not allocate, lock, log synchronously or throw in tick(); it
// reports failure by returning false and explains it through error(), which
// the master reads later from its control thread.
//
// @code
//   auto counter = dm::makeFunctionEngine("counter", [&](const dm::TickInfo& t) { ++n; return true; });
//   master.addEngine(counter, {.rateHz = 100});
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/rt_loop.hpp>

#include <functional>
#include <memory>
#include <string>
#include <string_view>

namespace dm {

/// An engine; see the file comment.
class Engine {
 public:
  virtual ~Engine() = default;
  /// Unique within a MasterEngine: "haptics", "physics", "renderer", ...
  virtual std::string_view name() const noexcept = 0;
  /// Loading: read resources, size every buffer tick() needs. Control thread.
  virtual Status load() { return ok(); }
  /// One step; `tick.dt()` is the engine's period in seconds and
  /// `tick.scheduled_ns` its time on the simulation clock. Returns false when
  /// the engine failed (the master then enters Error and stops ticking it).
  virtual bool tick(const TickInfo& tick) noexcept = 0;
  /// Stopping: flush outputs, release devices. Control thread; called once
  /// for every loaded engine, also after an error.
  virtual Status shutdown() { return ok(); }
  /// Why tick() returned false (control thread, after the engine stopped ticking).
  virtual Error error() const;
};

/// An engine whose tick is a function, for user code and tests. An
/// exception escaping `tick` counts as a failure whose error() carries its
/// message (so keep exceptions out of real-time engines anyway: unwinding
/// allocates).
std::shared_ptr<Engine> makeFunctionEngine(std::string name, std::function<bool(const TickInfo&)> tick);

}  // namespace dm
