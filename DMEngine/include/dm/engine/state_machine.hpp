// dm/engine/state_machine.hpp — the life cycle of a simulation:
//
//   Created → Loading → Ready → Running ⇄ Paused → Stopping → Stopped
//                          └──────────────────────→ Stopping (stop before start)
//   Error is reachable from every state except Stopped; from Error only
//   Stopping (to release what was loaded) is allowed.
//
// Every transition is checked against that graph (an illegal one is refused
// with a message naming both states and the legal targets), logged through
// dm::log, appended to the history and reported to the observers in the
// order they were added. Transitions are made by one control thread;
// state() may be read from any thread.
//
// @code
//   dm::StateMachine fsm;
//   fsm.onTransition([](const dm::Transition& t) { std::printf("%s\n", dm::toString(t.to)); });
//   if (auto s = fsm.transition(dm::SimState::Loading, "scene.json"); !s) return s;
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace dm {

/// States of a simulation's life cycle (see the file comment).
enum class SimState : std::uint8_t { Created, Loading, Ready, Running, Paused, Stopping, Stopped, Error };

/// "created", "loading", "ready", "running", "paused", "stopping", "stopped", "error".
const char* toString(SimState state) noexcept;

/// Whether the life-cycle graph has the edge from → to.
bool isLegalTransition(SimState from, SimState to) noexcept;

/// One transition as observers and the history see it.
struct Transition {
  SimState from = SimState::Created;
  SimState to = SimState::Created;
  std::string reason;  ///< why (a scene name, an error message, "user"); may be empty
};

/// The checked state machine; see the file comment.
class StateMachine {
 public:
  using Observer = std::function<void(const Transition&)>;

  /// The current state (any thread).
  SimState state() const noexcept { return state_.load(std::memory_order_acquire); }
  /// Moves to `to`, or fails with InvalidArgument ("illegal transition
  /// running -> loading; from running: paused, stopping, error") leaving the
  /// state unchanged. Control thread only.
  Status transition(SimState to, std::string reason = {});
  /// Calls `observer` after every later transition (control thread).
  void onTransition(Observer observer) { observers_.push_back(std::move(observer)); }
  /// Every transition so far, oldest first.
  const std::vector<Transition>& history() const noexcept { return history_; }

 private:
  std::atomic<SimState> state_{SimState::Created};
  std::vector<Observer> observers_;
  std::vector<Transition> history_;
};

}  // namespace dm
