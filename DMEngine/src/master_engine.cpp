// The master engine (dm/engine/master_engine.hpp) and function engines
// (dm/engine/engine.hpp).
#include <dm/core/clock.hpp>
#include <dm/core/log.hpp>
#include <dm/engine/master_engine.hpp>

#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <limits>
#include <utility>

namespace dm {

Error Engine::error() const {
  return fail(ErrorCode::Internal, "the engine reported a failure without saying why", std::string(name()));
}

namespace {

class FunctionEngine final : public Engine {
 public:
  FunctionEngine(std::string name, std::function<bool(const TickInfo&)> fn)
      : name_(std::move(name)), fn_(std::move(fn)) {}
  std::string_view name() const noexcept override { return name_; }
  bool tick(const TickInfo& t) noexcept override {
    try {
      if (fn_(t)) return true;
      what_ = "the tick function returned false";
    } catch (const std::exception& e) {
      what_ = std::string("the tick function threw: ") + e.what();
    } catch (...) {
      what_ = "the tick function threw a non-standard exception";
    }
    return false;
  }
  Error error() const override { return fail(ErrorCode::Internal, what_, name_); }

 private:
  std::string name_;
  std::function<bool(const TickInfo&)> fn_;
  std::string what_ = "no failure";
};

std::int64_t steadyNowNs() noexcept {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// The real-time loop an engine's schedule asks for.
RealTimeLoopConfig loopConfig(const EngineSchedule& schedule, std::string_view engineName) {
  RealTimeLoopConfig config;
  config.rate_hz = schedule.rateHz;
  config.priority = schedule.priority;
  config.cpu = schedule.cpu;
  config.catch_up = schedule.catchUp;
  config.name = "dm-" + std::string(engineName);
  return config;
}

}  // namespace

std::shared_ptr<Engine> makeFunctionEngine(std::string name, std::function<bool(const TickInfo&)> tick) {
  return std::make_shared<FunctionEngine>(std::move(name), std::move(tick));
}

struct MasterEngine::Slot {
  std::shared_ptr<Engine> engine;
  EngineSchedule schedule;
  std::int64_t periodNs = 0;
  // lockstep
  std::int64_t nextNs = 0;
  std::uint64_t ticks = 0, misses = 0;
  LatencyHistogram histogram;
  // real time
  std::unique_ptr<RealTimeLoop> loop;
  std::atomic<bool> failed{false};
  std::uint64_t earlierTicks = 0, earlierMisses = 0;  // from runs before the last resume
};

MasterEngine::MasterEngine() = default;

MasterEngine::~MasterEngine() {
  const SimState s = state();
  if (s == SimState::Running || s == SimState::Paused || s == SimState::Ready || s == SimState::Error) {
    if (Status st = stop("master engine destroyed"); !st) log::warn("%s", st.error().message().c_str());
  }
}

Status MasterEngine::addEngine(std::shared_ptr<Engine> engine, const EngineSchedule& schedule) {
  if (state() != SimState::Created)
    return fail(ErrorCode::InvalidArgument,
                formatString("engines are added in state created, not %s", toString(state())), "addEngine");
  if (!engine) return fail(ErrorCode::InvalidArgument, "null engine", "addEngine");
  const std::string name(engine->name());
  for (const auto& s : slots_)
    if (s->engine->name() == name)
      return fail(ErrorCode::InvalidArgument, "an engine named '" + name + "' was already added", name,
                  "give each engine a unique name");
  if (Status s = RealTimeLoop::validate(loopConfig(schedule, name)); !s) return s.error().within(name);
  auto slot = std::make_unique<Slot>();
  slot->engine = std::move(engine);
  slot->schedule = schedule;
  slot->periodNs = static_cast<std::int64_t>(std::llround(1e9 / schedule.rateHz));
  slots_.push_back(std::move(slot));
  return ok();
}

Status MasterEngine::enterError(const Error& error) {
  lastError_ = error;
  if (Status s = fsm_.transition(SimState::Error, error.message()); !s) return s;
  return error;
}

Status MasterEngine::load(std::string reason) {
  if (Status s = fsm_.transition(SimState::Loading, std::move(reason)); !s) return s;
  for (const auto& slot : slots_) {
    if (Status s = slot->engine->load(); !s)
      return enterError(s.error().within(std::string(slot->engine->name())));
    ++loaded_;
  }
  return fsm_.transition(SimState::Ready);
}

Status MasterEngine::startThreads() {
  for (const auto& slotPtr : slots_) {
    Slot* slot = slotPtr.get();
    if (slot->failed.load()) continue;
    slot->loop = std::make_unique<RealTimeLoop>(loopConfig(slot->schedule, slot->engine->name()), [slot](const TickInfo& t) {
      if (slot->failed.load(std::memory_order_relaxed)) return;
      if (!slot->engine->tick(t)) {
        slot->failed.store(true, std::memory_order_release);
        slot->loop->requestStop();
      }
    });
    if (Status s = slot->loop->start(); !s) {
      stopThreads();
      return s.error().within(std::string(slot->engine->name()));
    }
  }
  return ok();
}

void MasterEngine::stopThreads() {
  for (const auto& slot : slots_) {
    if (!slot->loop) continue;
    slot->loop->stop();
    const RealTimeLoopStats st = slot->loop->stats();
    slot->earlierTicks += st.ticks;
    slot->earlierMisses += st.deadline_misses;
  }
}

Status MasterEngine::start(RunMode mode) {
  if (state() != SimState::Ready)
    return fsm_.transition(SimState::Running);  // refused with the legal targets named
  mode_ = mode;
  clock_.set(0);
  realStartNs_ = steadyNowNs();
  for (const auto& slot : slots_) {
    slot->nextNs = 0;
    slot->ticks = slot->misses = slot->earlierTicks = slot->earlierMisses = 0;
    slot->histogram.reset();
    slot->failed.store(false);
  }
  if (mode == RunMode::RealTime)
    if (Status s = startThreads(); !s) return enterError(s.error());
  return fsm_.transition(SimState::Running, mode == RunMode::RealTime ? "real time" : "lockstep");
}

Status MasterEngine::pause() {
  if (state() != SimState::Running) return fsm_.transition(SimState::Paused);
  if (mode_ == RunMode::RealTime) stopThreads();
  return fsm_.transition(SimState::Paused);
}

Status MasterEngine::resume() {
  if (state() != SimState::Paused) return fsm_.transition(SimState::Running);
  if (mode_ == RunMode::RealTime)
    if (Status s = startThreads(); !s) return enterError(s.error());
  return fsm_.transition(SimState::Running, "resumed");
}

Status MasterEngine::advance(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0.0)
    return fail(ErrorCode::InvalidArgument, formatString("advance by %g s", seconds), "advance",
                "give a finite time >= 0");
  if (state() != SimState::Running || mode_ != RunMode::Lockstep)
    return fail(ErrorCode::InvalidArgument,
                formatString("advance() needs a lockstep simulation in state running, not %s%s",
                             toString(state()), mode_ == RunMode::RealTime ? " (real time)" : ""),
                "advance");
  const std::int64_t end = clock_.now() + secondsToNanos(seconds);
  for (;;) {
    Slot* next = nullptr;
    for (const auto& slot : slots_)
      if (next == nullptr || slot->nextNs < next->nextNs) next = slot.get();
    if (next == nullptr || next->nextNs >= end) break;
    clock_.set(next->nextNs);
    TickInfo info;
    info.index = next->ticks;
    info.scheduled_ns = info.start_ns = next->nextNs;
    info.period_ns = next->periodNs;
    const std::int64_t t0 = steadyNowNs();
    const bool healthy = next->engine->tick(info);
    const std::int64_t took = steadyNowNs() - t0;
    next->histogram.record(took);
    next->misses += took > next->periodNs;
    ++next->ticks;
    next->nextNs += next->periodNs;
    if (!healthy) return enterError(next->engine->error().within(std::string(next->engine->name())));
  }
  clock_.set(end);
  return ok();
}

Status MasterEngine::poll() {
  if (mode_ != RunMode::RealTime) return ok();
  const SimState s = state();
  if (s != SimState::Running && s != SimState::Paused) return ok();
  for (const auto& slot : slots_)
    if (slot->failed.load(std::memory_order_acquire)) {
      stopThreads();
      return enterError(slot->engine->error().within(std::string(slot->engine->name())));
    }
  return ok();
}

Status MasterEngine::stop(std::string reason) {
  if (Status s = fsm_.transition(SimState::Stopping, std::move(reason)); !s) return s;
  if (mode_ == RunMode::RealTime) stopThreads();
  Status first = ok();
  for (std::size_t i = 0; i < loaded_; ++i) {
    Status s = slots_[i]->engine->shutdown();
    if (!s && first) first = s.error().within(std::string(slots_[i]->engine->name()));
  }
  loaded_ = 0;
  if (Status s = fsm_.transition(SimState::Stopped); !s) return s;
  return first;
}

std::vector<EngineStats> MasterEngine::stats() const {
  std::vector<EngineStats> out;
  const double lockstepSeconds = nanosToSeconds(clock_.now());
  const double realSeconds = nanosToSeconds(steadyNowNs() - realStartNs_);
  for (const auto& slot : slots_) {
    EngineStats s;
    s.name = std::string(slot->engine->name());
    s.rateHz = slot->schedule.rateHz;
    if (mode_ == RunMode::Lockstep) {
      s.ticks = slot->ticks;
      s.deadlineMisses = slot->misses;
      s.execution = slot->histogram.summary();
      s.achievedHz = lockstepSeconds > 0 ? static_cast<double>(s.ticks) / lockstepSeconds : 0.0;
    } else {
      s.ticks = slot->earlierTicks;
      s.deadlineMisses = slot->earlierMisses;
      if (slot->loop) {
        const RealTimeLoopStats st = slot->loop->stats();
        if (st.running) s.ticks += st.ticks, s.deadlineMisses += st.deadline_misses;
        s.execution = st.execution;
        s.wakeup = st.wakeup;
      }
      s.achievedHz = realSeconds > 0 ? static_cast<double>(s.ticks) / realSeconds : 0.0;
    }
    out.push_back(std::move(s));
  }
  return out;
}

}  // namespace dm
