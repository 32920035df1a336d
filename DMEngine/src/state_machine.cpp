// The life-cycle state machine (dm/engine/state_machine.hpp).
#include <dm/core/log.hpp>
#include <dm/engine/state_machine.hpp>

#include <array>

namespace dm {
namespace {

constexpr std::array<SimState, 8> kAll = {SimState::Created, SimState::Loading, SimState::Ready,
                                          SimState::Running, SimState::Paused,  SimState::Stopping,
                                          SimState::Stopped, SimState::Error};

}  // namespace

const char* toString(SimState state) noexcept {
  switch (state) {
    case SimState::Created:
      return "created";
    case SimState::Loading:
      return "loading";
    case SimState::Ready:
      return "ready";
    case SimState::Running:
      return "running";
    case SimState::Paused:
      return "paused";
    case SimState::Stopping:
      return "stopping";
    case SimState::Stopped:
      return "stopped";
    case SimState::Error:
      return "error";
  }
  return "unknown";
}

bool isLegalTransition(SimState from, SimState to) noexcept {
  if (to == SimState::Error) return from != SimState::Stopped && from != SimState::Error;
  switch (from) {
    case SimState::Created:
      return to == SimState::Loading;
    case SimState::Loading:
      return to == SimState::Ready;
    case SimState::Ready:
      return to == SimState::Running || to == SimState::Stopping;
    case SimState::Running:
      return to == SimState::Paused || to == SimState::Stopping;
    case SimState::Paused:
      return to == SimState::Running || to == SimState::Stopping;
    case SimState::Stopping:
      return to == SimState::Stopped;
    case SimState::Error:
      return to == SimState::Stopping;
    case SimState::Stopped:
      return false;
  }
  return false;
}

Status StateMachine::transition(SimState to, std::string reason) {
  const SimState from = state();
  if (!isLegalTransition(from, to)) {
    std::string legal;
    for (SimState s : kAll)
      if (isLegalTransition(from, s)) legal += std::string(legal.empty() ? "" : ", ") + toString(s);
    return fail(ErrorCode::InvalidArgument,
                formatString("illegal transition %s -> %s", toString(from), toString(to)), "simulation state",
                legal.empty() ? std::string("no transition leaves ") + toString(from)
                              : std::string("from ") + toString(from) + ": " + legal);
  }
  state_.store(to, std::memory_order_release);
  if (reason.empty())
    log::info("simulation: %s -> %s", toString(from), toString(to));
  else
    log::info("simulation: %s -> %s (%s)", toString(from), toString(to), reason.c_str());
  history_.push_back({from, to, std::move(reason)});
  const Transition& t = history_.back();
  for (const Observer& o : observers_) o(t);
  return ok();
}

}  // namespace dm
