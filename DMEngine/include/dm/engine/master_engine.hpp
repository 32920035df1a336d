// dm/engine/master_engine.hpp — the master engine: owns the engines of a
// simulation, walks them through the life cycle (dm/engine/state_machine.hpp)
// and schedules each at its own rate.
//
// Two run modes:
//  * RealTime: one dm::RealTimeLoop thread per engine at its rate (priority
//    and CPU pinning per engine); poll() from the control thread notices a
//    failed engine and moves the simulation to Error. pause() stops the
//    threads, resume() restarts them; engines keep their state.
//  * Lockstep: advance(seconds) runs every engine on the calling thread on a
//    dm::VirtualClock. Each engine ticks at multiples of its period from the
//    start; ticks are ordered by scheduled time and, at equal times, by the
//    order the engines were added. Nothing depends on the wall clock, so two
//    runs of the same engines give bit-identical results. Tick durations are
//    still measured on the real clock for the statistics.
//
// Engines are added in Created; load() calls each engine's load() in order
// (Created → Loading → Ready; the first failure moves to Error and names the
// engine); stop() calls every loaded engine's shutdown() (→ Stopping →
// Stopped). Transitions are observable through onTransition().
//
// @code
//   dm::MasterEngine master;
//   master.addEngine(physics, {.rateHz = 500});
//   master.addEngine(haptics, {.rateHz = 1000});
//   if (auto s = master.load("head.json"); !s) return s;
//   if (auto s = master.start(dm::RunMode::Lockstep); !s) return s;
//   if (auto s = master.advance(2.0); !s) return s;     // 2 s of simulated time
//   master.stop("done");
// @endcode
#pragma once

#include <dm/core/clock.hpp>
#include <dm/core/result.hpp>
#include <dm/core/rt_loop.hpp>
#include <dm/engine/engine.hpp>
#include <dm/engine/state_machine.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace dm {

/// How an engine is scheduled.
struct EngineSchedule {
  double rateHz = 1000.0;  ///< ticks per second, [0.001, 1e6]
  int priority = 0;        ///< real time: SCHED_FIFO priority 1..99, 0 = normal
  int cpu = -1;            ///< real time: CPU to pin the thread to, -1 = none
  /// Real time: periods a late engine may run back to back to catch up
  /// before it skips them (RealTimeLoopConfig::catch_up); 0 for haptics.
  int catchUp = 0;
};

/// Real-time threads or lockstep on a virtual clock (see the file comment).
enum class RunMode : std::uint8_t { RealTime, Lockstep };

/// Per-engine figures since start() (durations in microseconds).
struct EngineStats {
  std::string name;
  double rateHz = 0.0;                  ///< scheduled rate
  std::uint64_t ticks = 0;              ///< ticks run
  std::uint64_t deadlineMisses = 0;     ///< ticks that ran longer than a period (or started late, real time)
  double achievedHz = 0.0;              ///< ticks / simulated (lockstep) or elapsed (real time) seconds
  LatencyHistogram::Summary execution;  ///< tick durations, µs
  /// Real time: how late each tick started after its deadline, µs (the
  /// scheduler's wake-up latency); lockstep ticks start on time (zeros).
  LatencyHistogram::Summary wakeup;
};

/// The master engine; see the file comment. Control methods from one thread.
class MasterEngine {
 public:
  MasterEngine();
  /// Stops a running simulation (shutting its engines down).
  ~MasterEngine();
  MasterEngine(const MasterEngine&) = delete;
  MasterEngine& operator=(const MasterEngine&) = delete;

  /// Adds an engine (Created only). InvalidArgument for a null engine, a
  /// duplicate name or a bad schedule (naming the engine and field).
  Status addEngine(std::shared_ptr<Engine> engine, const EngineSchedule& schedule);
  /// Created → Loading → Ready, loading each engine in order; on a failure
  /// → Error with the engine's error (its `where` prefixed by the engine name).
  Status load(std::string reason = {});
  /// Ready → Running in `mode`. RealTime: starts the threads (a thread that
  /// cannot start → Error).
  Status start(RunMode mode);
  /// Running → Paused (real time: threads stopped after their current tick).
  Status pause();
  /// Paused → Running.
  Status resume();
  /// Lockstep and Running: runs every tick scheduled in [now, now + seconds)
  /// and leaves the clock at now + seconds. A failed engine → Error, and its
  /// error is returned. InvalidArgument for a negative or non-finite time;
  /// InvalidArgument when not running in lockstep.
  Status advance(double seconds);
  /// Real time: Error when an engine failed since the last call (its error
  /// is returned). Ok otherwise, also in lockstep.
  Status poll();
  /// From Ready, Running, Paused or Error: → Stopping, stops the threads,
  /// shuts down every loaded engine (first failure returned, all are called)
  /// → Stopped.
  Status stop(std::string reason = {});

  SimState state() const noexcept { return fsm_.state(); }
  /// Observes every transition (control thread).
  void onTransition(StateMachine::Observer observer) { fsm_.onTransition(std::move(observer)); }
  const std::vector<Transition>& history() const noexcept { return fsm_.history(); }
  /// The simulation clock in lockstep (ns since start()); it outlives the
  /// engines, which may hold it.
  const VirtualClock& virtualClock() const noexcept { return clock_; }
  /// Statistics per engine, in the order the engines were added.
  std::vector<EngineStats> stats() const;
  /// The error that moved the simulation to Error (empty `what` otherwise).
  const Error& lastError() const noexcept { return lastError_; }

 private:
  struct Slot;
  Status enterError(const Error& error);
  void stopThreads();
  Status startThreads();

  // Declared first, so destroyed last: engines may hold the clock
  // (virtualClock()) and read it as they are destroyed.
  VirtualClock clock_;
  StateMachine fsm_;
  std::vector<std::unique_ptr<Slot>> slots_;
  RunMode mode_ = RunMode::Lockstep;
  std::int64_t realStartNs_ = 0;
  std::size_t loaded_ = 0;  // engines whose load() succeeded
  Error lastError_;
};

}  // namespace dm
