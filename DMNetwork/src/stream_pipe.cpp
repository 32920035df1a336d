// stream_pipe.cpp — dm::LinkEmulator: a min-heap of scheduled deliveries
// behind one steady timer on the network thread; dm::SteppedLinkEmulator:
// the same heap over fixed packet slots, popped on the caller's clock. Both
// draw fates from one FateSource: a seeded mt19937_64 with hand-written
// (portable) uniform and normal transforms.
#include <dm/core/log.hpp>
#include <dm/network/stream_pipe.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>
#include <queue>
#include <random>
#include <vector>

#include "io_thread_impl.hpp"

namespace dm {

namespace {

using SteadyClock = std::chrono::steady_clock;

/// What happens to one packet; the draws happen in the same order for
/// every packet, whatever their outcome, so one packet's fate never shifts
/// another's.
struct Fate {
  bool lost = false, late = false, duplicated = false;
  std::chrono::microseconds first{0},
      second{0};  // latency of the packet and of its copy, reorderDelay included
};

class FateSource {
 public:
  explicit FateSource(const LinkEmulatorOptions& o) : options_(o), rng_(o.seed) {}

  Fate next() noexcept {
    Fate f;
    f.lost = uniform() < options_.lossProbability;
    f.late = uniform() < options_.reorderProbability;
    f.duplicated = uniform() < options_.duplicateProbability;
    const auto extra = f.late ? options_.reorderDelay : std::chrono::microseconds(0);
    f.first = latency() + extra;
    f.second = latency() + extra;
    return f;
  }

 private:
  /// Uniform on [0, 1) from the top 53 bits (the same on every platform,
  /// unlike std::uniform_real_distribution).
  double uniform() noexcept { return static_cast<double>(rng_() >> 11) * 0x1.0p-53; }

  std::chrono::microseconds latency() noexcept {
    const double j = static_cast<double>(options_.jitter.count());
    double extra = 0.0;
    if (j > 0.0) {
      if (options_.jitterModel == JitterModel::Uniform) {
        extra = uniform() * j;
      } else {
        // Box-Muller; 1 - u is in (0, 1], so the logarithm is finite.
        const double r = std::sqrt(-2.0 * std::log(1.0 - uniform()));
        extra = std::min(std::abs(r * std::cos(2.0 * M_PI * uniform())) * j, 6.0 * j);
      }
    }
    return options_.delay + std::chrono::microseconds(static_cast<std::int64_t>(std::llround(extra)));
  }

  LinkEmulatorOptions options_;
  std::mt19937_64 rng_;
};

Status checkOptions(const LinkEmulatorOptions& options) {
  const std::string where = "LinkEmulator options";
  const auto probability = [&](double p, const char* field) -> Status {
    if (!(p >= 0.0 && p <= 1.0))
      return fail(ErrorCode::InvalidArgument, formatString("%s is %g", field, p), where + ": " + field,
                  "give a probability in [0, 1]");
    return ok();
  };
  for (auto s : {probability(options.lossProbability, "lossProbability"),
                 probability(options.duplicateProbability, "duplicateProbability"),
                 probability(options.reorderProbability, "reorderProbability")})
    if (!s) return s.error();
  if (options.delay.count() < 0 || options.jitter.count() < 0 || options.reorderDelay.count() < 0)
    return fail(ErrorCode::InvalidArgument,
                formatString("delay %lld us, jitter %lld us, reorderDelay %lld us",
                             static_cast<long long>(options.delay.count()),
                             static_cast<long long>(options.jitter.count()),
                             static_cast<long long>(options.reorderDelay.count())),
                where, "times must be >= 0");
  if (options.maxInFlight == 0 || options.maxPacketBytes == 0)
    return fail(ErrorCode::InvalidArgument, "maxInFlight or maxPacketBytes is 0", where, "both must be >= 1");
  return ok();
}

struct Delivery {
  SteadyClock::time_point due;
  std::uint64_t sequence = 0;  // ties keep submission order
  std::shared_ptr<const std::vector<std::byte>> bytes;
  bool operator>(const Delivery& o) const { return due != o.due ? due > o.due : sequence > o.sequence; }
};

}  // namespace

struct LinkEmulator::Impl : std::enable_shared_from_this<LinkEmulator::Impl> {
  Impl(IoThread& t, LinkEmulatorOptions o, Deliver d)
      : user(t), options(o), deliver(std::move(d)), fates(o), timer(t.impl().io) {}

  /// Network thread: (re)arms the timer for the earliest delivery.
  void arm() {
    SteadyClock::time_point due;
    {
      std::lock_guard lock(mutex);
      if (closed || heap.empty()) {
        armedDue = SteadyClock::time_point::max();
        return;
      }
      due = heap.top().due;
      armedDue = due;
    }
    timer.expires_at(due);
    timer.async_wait([self = shared_from_this()](std::error_code ec) {
      if (ec) return;  // re-armed for an earlier delivery, or closed
      self->fire();
    });
  }

  void fire() {
    std::vector<Delivery> ready;
    {
      std::lock_guard lock(mutex);
      if (closed) return;
      const SteadyClock::time_point now = SteadyClock::now();
      while (!heap.empty() && heap.top().due <= now) {
        ready.push_back(heap.top());
        heap.pop();
      }
    }
    for (std::size_t i = 0; i < ready.size(); ++i) {
      if (closed.load()) {  // close() ran from inside a delivery: the rest is discarded
        discarded.fetch_add(ready.size() - i, std::memory_order_relaxed);
        pending.fetch_sub(ready.size() - i, std::memory_order_release);
        return;
      }
      const Delivery& d = ready[i];
      if (deliver) user.thread().impl().guard("LinkEmulator deliver", [&] { deliver(*d.bytes); });
      delivered.fetch_add(1, std::memory_order_relaxed);
      pending.fetch_sub(1, std::memory_order_release);  // after the delivery: inFlight 0 means all done
    }
    arm();
  }

  IoUser user;
  const LinkEmulatorOptions options;
  Deliver deliver;
  FateSource fates;  // under mutex
  asio::steady_timer timer;

  mutable std::mutex mutex;  // guards fates, heap, armedDue, counters below that are not atomic
  std::priority_queue<Delivery, std::vector<Delivery>, std::greater<>> heap;
  SteadyClock::time_point armedDue = SteadyClock::time_point::max();
  std::uint64_t nextSequence = 0;
  std::atomic<std::uint64_t> pending{0};  // scheduled and not yet delivered or discarded
  std::atomic<bool> closed{false};
  std::atomic<std::uint64_t> submitted{0}, lost{0}, duplicated{0}, reordered{0}, delivered{0}, refused{0},
      discarded{0};
};

LinkEmulator::LinkEmulator(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}

LinkEmulator::~LinkEmulator() { close(); }

Result<std::unique_ptr<LinkEmulator>> LinkEmulator::create(IoThread& thread, LinkEmulatorOptions options,
                                                           Deliver deliver) {
  if (auto s = checkOptions(options); !s) return s.error();
  return std::unique_ptr<LinkEmulator>(
      new LinkEmulator(std::make_shared<Impl>(thread, options, std::move(deliver))));
}

Status LinkEmulator::submit(std::span<const std::byte> packet) {
  Impl& m = *impl_;
  if (packet.size() > m.options.maxPacketBytes) {
    m.refused.fetch_add(1, std::memory_order_relaxed);
    return fail(ErrorCode::InvalidArgument,
                formatString("packet of %zu bytes exceeds maxPacketBytes %zu", packet.size(),
                             m.options.maxPacketBytes),
                "LinkEmulator::submit", "raise LinkEmulatorOptions::maxPacketBytes");
  }
  auto bytes = std::make_shared<const std::vector<std::byte>>(packet.begin(), packet.end());
  bool rearm = false;
  {
    std::lock_guard lock(m.mutex);
    if (m.closed.load()) return fail(ErrorCode::Network, "emulator is closed", "LinkEmulator::submit");
    if (m.heap.size() >= m.options.maxInFlight) {
      m.refused.fetch_add(1, std::memory_order_relaxed);
      return fail(ErrorCode::Busy, formatString("%zu deliveries in flight", m.heap.size()),
                  "LinkEmulator::submit", "submit slower, or raise maxInFlight");
    }
    m.submitted.fetch_add(1, std::memory_order_relaxed);
    const Fate fate = m.fates.next();
    if (fate.lost) {
      m.lost.fetch_add(1, std::memory_order_relaxed);
    } else {
      const SteadyClock::time_point now = SteadyClock::now();
      if (fate.late) m.reordered.fetch_add(1, std::memory_order_relaxed);
      m.heap.push({now + fate.first, m.nextSequence++, bytes});
      m.pending.fetch_add(1, std::memory_order_relaxed);
      if (fate.duplicated && m.heap.size() < m.options.maxInFlight) {
        m.duplicated.fetch_add(1, std::memory_order_relaxed);
        m.heap.push({now + fate.second, m.nextSequence++, bytes});
        m.pending.fetch_add(1, std::memory_order_relaxed);
      }
      if (m.heap.top().due < m.armedDue) {
        m.armedDue = m.heap.top().due;
        rearm = true;
      }
    }
  }
  if (rearm) asio::post(m.user.io(), [self = impl_] { self->arm(); });
  return ok();
}

void LinkEmulator::close() {
  Impl& m = *impl_;
  if (m.closed.load()) return;
  m.user.thread().runAndWait([&] {
    std::lock_guard lock(m.mutex);
    if (m.closed.exchange(true)) return;
    m.discarded.fetch_add(m.heap.size(), std::memory_order_relaxed);
    m.pending.fetch_sub(m.heap.size(), std::memory_order_relaxed);
    m.heap = {};
    m.timer.cancel();
  });
  m.user.release();
}

LinkEmulatorStats LinkEmulator::stats() const {
  const Impl& m = *impl_;
  // Read first, so that a zero guarantees the counters below include every
  // delivery (the acquire pairs with the release after each delivery).
  const std::uint64_t inFlight = m.pending.load(std::memory_order_acquire);
  return {m.submitted.load(), m.lost.load(),    m.duplicated.load(), m.reordered.load(),
          m.delivered.load(), m.refused.load(), m.discarded.load(),  inFlight};
}

// ---- SteppedLinkEmulator ------------------------------------------------------

struct SteppedLinkEmulator::Impl {
  explicit Impl(const LinkEmulatorOptions& o)
      : options(o),
        fates(o),
        bytes(o.maxInFlight * o.maxPacketBytes),
        sizes(o.maxInFlight, 0),
        copies(o.maxInFlight, 0) {
    heap.reserve(o.maxInFlight);
    freeSlots.reserve(o.maxInFlight);
    for (std::size_t i = o.maxInFlight; i-- > 0;) freeSlots.push_back(static_cast<std::uint32_t>(i));
  }

  struct Due {
    std::int64_t dueNs = 0;
    std::uint64_t sequence = 0;  // ties keep submission order
    std::uint32_t slot = 0;
    bool operator>(const Due& o) const { return dueNs != o.dueNs ? dueNs > o.dueNs : sequence > o.sequence; }
  };

  void schedule(std::int64_t dueNs, std::uint32_t slot) noexcept {
    heap.push_back({dueNs, nextSequence++, slot});
    std::push_heap(heap.begin(), heap.end(), std::greater<>{});
    ++copies[slot];
  }

  void release(std::uint32_t slot) noexcept {
    if (--copies[slot] == 0) freeSlots.push_back(slot);
  }

  const LinkEmulatorOptions options;
  FateSource fates;
  std::vector<std::byte> bytes;  // maxInFlight slots of maxPacketBytes
  std::vector<std::size_t> sizes;
  std::vector<std::uint8_t> copies;  // deliveries still pending per slot (a duplicate shares its slot)
  std::vector<std::uint32_t> freeSlots;
  std::vector<Due> heap;  // capacity maxInFlight: every pending delivery holds a slot
  std::uint64_t nextSequence = 0;
  std::optional<std::uint32_t> popped;  // the slot popDue's span points into
  LinkEmulatorStats counts;
};

SteppedLinkEmulator::SteppedLinkEmulator(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
SteppedLinkEmulator::~SteppedLinkEmulator() = default;

Result<std::unique_ptr<SteppedLinkEmulator>> SteppedLinkEmulator::create(LinkEmulatorOptions options) {
  if (auto s = checkOptions(options); !s) return s.error();
  if (options.maxInFlight > (std::size_t{1} << 26) || options.maxPacketBytes > (std::size_t{1} << 26) ||
      options.maxInFlight * options.maxPacketBytes > (std::size_t{1} << 26))
    return fail(ErrorCode::InvalidArgument,
                formatString("maxInFlight %zu x maxPacketBytes %zu is over 64 MiB", options.maxInFlight,
                             options.maxPacketBytes),
                "SteppedLinkEmulator options",
                "its slots are allocated up front: lower maxPacketBytes to the largest packet sent");
  return std::unique_ptr<SteppedLinkEmulator>(new SteppedLinkEmulator(std::make_unique<Impl>(options)));
}

bool SteppedLinkEmulator::submit(std::span<const std::byte> packet, std::int64_t nowNs) noexcept {
  Impl& m = *impl_;
  // maxInFlight deliveries pending (a duplicate shares its packet's slot,
  // and is dropped when the heap is full, as LinkEmulator does).
  if (packet.size() > m.options.maxPacketBytes || m.freeSlots.empty() ||
      m.heap.size() >= m.options.maxInFlight) {
    ++m.counts.refused;
    return false;
  }
  ++m.counts.submitted;
  const Fate fate = m.fates.next();
  if (fate.lost) {
    ++m.counts.lost;
    return true;
  }
  const std::uint32_t slot = m.freeSlots.back();
  m.freeSlots.pop_back();
  std::memcpy(m.bytes.data() + slot * m.options.maxPacketBytes, packet.data(), packet.size());
  m.sizes[slot] = packet.size();
  if (fate.late) ++m.counts.reordered;
  const auto ns = [](std::chrono::microseconds us) { return static_cast<std::int64_t>(us.count()) * 1000; };
  m.schedule(nowNs + ns(fate.first), slot);
  if (fate.duplicated && m.heap.size() < m.options.maxInFlight) {
    ++m.counts.duplicated;
    m.schedule(nowNs + ns(fate.second), slot);
  }
  return true;
}

bool SteppedLinkEmulator::popDue(std::int64_t nowNs, std::span<const std::byte>& packet) noexcept {
  Impl& m = *impl_;
  if (m.popped) {
    m.release(*m.popped);
    m.popped.reset();
  }
  if (m.heap.empty() || m.heap.front().dueNs > nowNs) return false;
  std::pop_heap(m.heap.begin(), m.heap.end(), std::greater<>{});
  const std::uint32_t slot = m.heap.back().slot;
  m.heap.pop_back();
  m.popped = slot;
  ++m.counts.delivered;
  packet = std::span<const std::byte>(m.bytes.data() + slot * m.options.maxPacketBytes, m.sizes[slot]);
  return true;
}

LinkEmulatorStats SteppedLinkEmulator::stats() const noexcept {
  LinkEmulatorStats s = impl_->counts;
  s.inFlight = impl_->heap.size();
  return s;
}

}  // namespace dm
