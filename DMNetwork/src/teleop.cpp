// teleop.cpp — the tele-operation device stream (dm/network/teleop.hpp):
// payload codec, the in-process links, the two ends on one shared
// implementation, the device bridge.
//
// Threads: each end's receive thread blocks in recvfrom (no event loop in
// between: half the round trip of an asio receive, docs/performance.md),
// decodes, classifies and publishes (TripleBuffer for the newest value, a
// sequence lock for the echo and the peer address); the servo thread sends
// with one non-blocking sendto on the same descriptor. The descriptor stays
// open until the implementation is destroyed, so a send racing close() never
// reaches a reused descriptor. An in-process end has neither thread nor
// descriptor: its poll() runs the receive path on the reader's thread.
#include <dm/core/clock.hpp>
#include <dm/core/log.hpp>
#include <dm/core/ring.hpp>
#include <dm/core/rt_loop.hpp>
#include <dm/network/teleop.hpp>

#include <pthread.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <limits>
#include <map>
#include <mutex>
#include <thread>
#include <type_traits>

#include "io_thread_impl.hpp"
#include "le_bytes.hpp"

namespace dm {
namespace {

using asio::ip::udp;

// ---- payload codec ------------------------------------------------------------

void putU32(std::byte* p, std::uint32_t v) { detail::putLe(p, v, 4); }
void putU64(std::byte* p, std::uint64_t v) { detail::putLe(p, v, 8); }
void putF64(std::byte* p, double v) { putU64(p, std::bit_cast<std::uint64_t>(v)); }
std::uint32_t getU32(const std::byte* p) { return static_cast<std::uint32_t>(detail::getLe(p, 4)); }
std::uint64_t getU64(const std::byte* p) { return detail::getLe(p, 8); }
double getF64(const std::byte* p) { return std::bit_cast<double>(getU64(p)); }

// Writes n doubles from `v` at p; returns the next position.
std::byte* putVec(std::byte* p, const double* v, int n) {
  for (int i = 0; i < n; ++i) putF64(p + 8 * i, v[i]);
  return p + 8 * n;
}

std::byte* putEcho(std::byte* p, const TeleopEcho& e) {
  putU64(p, static_cast<std::uint64_t>(e.peerSendNs));
  putU64(p + 8, static_cast<std::uint64_t>(e.holdNs));
  return p + 16;
}

// Reads doubles and checks them; names the first bad one.
class Reader {
 public:
  Reader(std::span<const std::byte> payload, const char* type) : p_(payload), type_(type) {}
  double f64() {
    const double v = getF64(p_.data() + at_);
    if (ok_ && !std::isfinite(v)) failAt("is not finite");
    at_ += 8;
    return v;
  }
  Vec3 vec3() {
    Vec3 v;
    for (int i = 0; i < 3; ++i) v[i] = f64();
    return v;
  }
  std::int64_t i64() { return static_cast<std::int64_t>(u64()); }
  std::uint64_t u64() {
    at_ += 8;
    return getU64(p_.data() + at_ - 8);
  }
  std::uint32_t u32() {
    at_ += 4;
    return getU32(p_.data() + at_ - 4);
  }
  std::string str64() {
    const char* s = reinterpret_cast<const char*>(p_.data() + at_);
    const std::size_t n = strnlen(s, 64);
    if (ok_ && n == 64) failAt("string field has no terminating NUL within 64 bytes");
    at_ += 64;
    return std::string(s, std::min<std::size_t>(n, 63));
  }
  void failAt(const char* what) {
    if (!ok_) return;
    ok_ = false;
    error_ = formatString("%s payload byte %zu: %s", type_, at_, what);
    errorAt_ = at_;
  }
  bool ok() const { return ok_; }
  std::size_t offset() const { return at_; }
  Error error() const {
    return Error{ErrorCode::Parse, error_, formatString("datagram byte %zu", kMessageHeaderBytes + errorAt_),
                 "the peer sent a malformed tele-operation message; it was dropped"};
  }

 private:
  std::span<const std::byte> p_;
  const char* type_;
  std::size_t at_ = 0, errorAt_ = 0;
  bool ok_ = true;
  std::string error_;
};

std::size_t payloadBytesOf(std::uint16_t type) {
  switch (type) {
    case kTeleopStateType:
      return kTeleopStateBytes;
    case kTeleopForceType:
      return kTeleopForceBytes;
    case kTeleopHelloType:
      return kTeleopHelloBytes;
    case kTeleopInfoType:
      return kTeleopInfoBytes;
    case kTeleopWaveType:
      return kTeleopWaveBytes;
    default:
      return 0;
  }
}

const char* typeName(std::uint16_t type) {
  switch (type) {
    case kTeleopStateType:
      return "State";
    case kTeleopForceType:
      return "Force";
    case kTeleopHelloType:
      return "Hello";
    case kTeleopInfoType:
      return "Info";
    case kTeleopWaveType:
      return "Wave";
    default:
      return "unknown";
  }
}

// ---- lock-free exchange of small values ------------------------------------

/// A sequence lock over a trivially copyable T: one writer, any number of
/// readers, neither blocks nor allocates (a reader retries while a write is
/// in progress, which takes a few nanoseconds). The value lives in relaxed
/// atomic words, so concurrent access is race-free by the memory model.
template <class T>
class SeqLocked {
  static_assert(std::is_trivially_copyable_v<T>);
  static constexpr std::size_t kWords = (sizeof(T) + 7) / 8;

 public:
  void store(const T& value) noexcept {
    std::array<std::uint64_t, kWords> w{};
    std::memcpy(w.data(), &value, sizeof(T));
    const std::uint32_t s = seq_.load(std::memory_order_relaxed);
    seq_.store(s + 1, std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_release);
    for (std::size_t i = 0; i < kWords; ++i) words_[i].store(w[i], std::memory_order_relaxed);
    seq_.store(s + 2, std::memory_order_release);
  }
  /// False (and `out` untouched) before the first store().
  bool load(T& out) const noexcept {
    std::array<std::uint64_t, kWords> w{};
    for (;;) {
      const std::uint32_t s1 = seq_.load(std::memory_order_acquire);
      if (s1 & 1u) continue;
      for (std::size_t i = 0; i < kWords; ++i) w[i] = words_[i].load(std::memory_order_relaxed);
      std::atomic_thread_fence(std::memory_order_acquire);
      if (seq_.load(std::memory_order_relaxed) != s1) continue;
      if (s1 == 0) return false;
      std::memcpy(static_cast<void*>(&out), w.data(), sizeof(T));
      return true;
    }
  }

 private:
  std::atomic<std::uint32_t> seq_{0};
  std::array<std::atomic<std::uint64_t>, kWords> words_{};
};

struct PeerAddress {
  sockaddr_storage address{};
  socklen_t length = 0;
};

struct EchoSource {
  std::int64_t peerSendNs = 0;  // the peer's send timestamp of the newest message
  std::int64_t receivedNs = 0;  // when it arrived, our clock
};

template <class T>
struct Stamped {
  T value{};
  std::int64_t receivedNs = 0;
  bool valid = false;
};

// CLOCK_MONOTONIC: the stream's timestamps on both ends.
std::int64_t nowNs() noexcept { return RealClock().now(); }

PeerAddress toPeer(const udp::endpoint& e) {
  PeerAddress p;
  std::memcpy(&p.address, e.data(), e.size());
  p.length = static_cast<socklen_t>(e.size());
  return p;
}

LatencyStats summarize(const LatencyHistogram& h, double last) {
  LatencyStats s;
  s.count = h.count();
  if (s.count == 0) return s;
  s.last = last;
  s.min = 1e-9 * static_cast<double>(h.min());
  s.max = 1e-9 * static_cast<double>(h.max());
  s.mean = 1e-9 * h.mean();
  s.p50 = 1e-9 * static_cast<double>(h.percentile(50));
  s.p99 = 1e-9 * static_cast<double>(h.percentile(99));
  s.p999 = 1e-9 * static_cast<double>(h.percentile(99.9));
  return s;
}

}  // namespace

// ---- wire functions -------------------------------------------------------------

std::size_t writeTeleopState(const MessageHeader& header, const TeleopEcho& echo, const HapticState& state,
                             std::span<std::byte> out) noexcept {
  if (out.size() < kMessageHeaderBytes + kTeleopStateBytes) return 0;
  std::byte* p = putEcho(out.data() + kMessageHeaderBytes, echo);
  putU64(p, static_cast<std::uint64_t>(state.timeNs));
  p = putVec(p + 8, state.position.data(), 3);
  const double q[4] = {state.orientation.w(), state.orientation.x(), state.orientation.y(),
                       state.orientation.z()};
  p = putVec(p, q, 4);
  p = putVec(p, state.linearVelocity.data(), 3);
  p = putVec(p, state.angularVelocity.data(), 3);
  putU32(p, state.buttons);
  putU32(p + 4, 0);  // reserved
  MessageHeader h = header;
  h.type = kTeleopStateType;
  return sealMessage(h, out, kTeleopStateBytes);
}

std::size_t writeTeleopForce(const MessageHeader& header, const TeleopEcho& echo, const HapticOutput& force,
                             std::span<std::byte> out) noexcept {
  if (out.size() < kMessageHeaderBytes + kTeleopForceBytes) return 0;
  std::byte* p = putEcho(out.data() + kMessageHeaderBytes, echo);
  p = putVec(p, force.force.data(), 3);
  putVec(p, force.torque.data(), 3);
  MessageHeader h = header;
  h.type = kTeleopForceType;
  return sealMessage(h, out, kTeleopForceBytes);
}

std::size_t writeTeleopHello(const MessageHeader& header, std::span<std::byte> out) noexcept {
  if (out.size() < kMessageHeaderBytes + kTeleopHelloBytes) return 0;
  putU32(out.data() + kMessageHeaderBytes, kTeleopVersion);
  MessageHeader h = header;
  h.type = kTeleopHelloType;
  return sealMessage(h, out, kTeleopHelloBytes);
}

std::size_t writeTeleopWave(const MessageHeader& header, const WaveSample& wave, std::span<std::byte> out) noexcept {
  if (out.size() < kMessageHeaderBytes + kTeleopWaveBytes) return 0;
  std::byte* p = putVec(out.data() + kMessageHeaderBytes, wave.wave.data(), 3);
  putU64(p, wave.sequence);
  putF64(p + 8, wave.energy);
  MessageHeader h = header;
  h.type = kTeleopWaveType;
  return sealMessage(h, out, kTeleopWaveBytes);
}

std::size_t writeTeleopInfo(const MessageHeader& header, const HapticInfo& info,
                            std::span<std::byte> out) noexcept {
  if (out.size() < kMessageHeaderBytes + kTeleopInfoBytes) return 0;
  std::memset(out.data() + kMessageHeaderBytes, 0, kTeleopInfoBytes);
  std::byte* p = out.data() + kMessageHeaderBytes;
  for (const std::string* s : {&info.driver, &info.vendor, &info.model, &info.serial}) {
    std::memcpy(p, s->data(), std::min<std::size_t>(s->size(), 63));
    p += 64;  // the rest stays NUL
  }
  putU32(p, info.capabilities);
  putU32(p + 4, info.buttonCount);
  // An empty box (a default HapticInfo) travels as the point at the origin.
  const Aabb box = info.workspace.isEmpty() ? Aabb(Vec3::Zero(), Vec3::Zero()) : info.workspace;
  p = putVec(p + 8, box.min().data(), 3);
  p = putVec(p, box.max().data(), 3);
  const double limits[5] = {info.maxForce, info.maxTorque, info.maxStiffness, info.maxDamping, info.servoRateHz};
  putVec(p, limits, 5);
  MessageHeader h = header;
  h.type = kTeleopInfoType;
  return sealMessage(h, out, kTeleopInfoBytes);
}

std::vector<std::byte> encodeTeleopInfo(const MessageHeader& header, const HapticInfo& info) {
  std::vector<std::byte> out(kMessageHeaderBytes + kTeleopInfoBytes);
  writeTeleopInfo(header, info, out);
  return out;
}

Result<TeleopPacket> decodeTeleopPacket(std::span<const std::byte> datagram) {
  MessageLimits limits;
  limits.maxPayloadBytes = kTeleopInfoBytes;
  auto m = decodeMessage(datagram, limits);
  if (!m) return std::move(m).error();
  TeleopPacket out;
  out.header = m->header;
  const std::size_t expected = payloadBytesOf(m->header.type);
  if (expected == 0)
    return fail(ErrorCode::Parse, formatString("message type 0x%04X is not a tele-operation type", m->header.type),
                "datagram byte 6",
                "expected State 0x7401, Force 0x7402, Hello 0x7403, Info 0x7404 or Wave 0x7405");
  if (m->payload.size() != expected)
    return fail(ErrorCode::Parse,
                formatString("%s payload is %zu bytes, expected %zu", typeName(m->header.type), m->payload.size(),
                             expected),
                "datagram byte 12", "the peer speaks another layout; update both sides");
  Reader r(m->payload, typeName(m->header.type));
  switch (m->header.type) {
    case kTeleopStateType:
    case kTeleopForceType: {
      out.echo.peerSendNs = r.i64();
      out.echo.holdNs = r.i64();
      if (m->header.type == kTeleopForceType) {
        out.force.force = r.vec3();
        out.force.torque = r.vec3();
        break;
      }
      out.state.timeNs = r.i64();
      out.state.position = r.vec3();
      const std::size_t qAt = r.offset();
      const double w = r.f64(), x = r.f64(), y = r.f64(), z = r.f64();
      out.state.linearVelocity = r.vec3();
      out.state.angularVelocity = r.vec3();
      out.state.buttons = r.u32();
      if (!r.ok()) return r.error();
      const double norm = std::sqrt(w * w + x * x + y * y + z * z);
      if (!(std::abs(norm - 1.0) <= 1e-3))
        return fail(ErrorCode::Parse, formatString("State orientation has norm %g, expected 1", norm),
                    formatString("datagram byte %zu", kMessageHeaderBytes + qAt),
                    "the peer sent a malformed tele-operation message; it was dropped");
      out.state.orientation = Quat(w / norm, x / norm, y / norm, z / norm);
      break;
    }
    case kTeleopWaveType: {
      out.wave.wave = r.vec3();
      out.wave.sequence = r.u64();
      const std::size_t energyAt = r.offset();
      out.wave.energy = r.f64();
      if (!r.ok()) return r.error();
      if (out.wave.energy < 0)
        return fail(ErrorCode::Parse, formatString("Wave energy is %g J, expected >= 0", out.wave.energy),
                    formatString("datagram byte %zu", kMessageHeaderBytes + energyAt),
                    "the peer sent a malformed tele-operation message; it was dropped");
      break;
    }
    case kTeleopHelloType:
      out.version = r.u32();
      if (out.version != kTeleopVersion)
        return fail(ErrorCode::Version,
                    formatString("Hello asks for stream version %u, this build speaks %u", out.version,
                                 kTeleopVersion),
                    "datagram byte 28", "update the older side");
      break;
    case kTeleopInfoType: {
      out.info.driver = r.str64();
      out.info.vendor = r.str64();
      out.info.model = r.str64();
      out.info.serial = r.str64();
      out.info.capabilities = r.u32();
      out.info.buttonCount = r.u32();
      const Vec3 lo = r.vec3(), hi = r.vec3();
      const std::size_t limitsAt = r.offset();
      out.info.maxForce = r.f64();
      out.info.maxTorque = r.f64();
      out.info.maxStiffness = r.f64();
      out.info.maxDamping = r.f64();
      out.info.servoRateHz = r.f64();
      if (!r.ok()) return r.error();
      if (!(lo.array() <= hi.array()).all())
        return fail(ErrorCode::Parse, "Info workspace minimum exceeds its maximum",
                    formatString("datagram byte %zu", kMessageHeaderBytes + 264), "fix the device's workspace");
      if (out.info.maxForce < 0 || out.info.maxTorque < 0 || out.info.maxStiffness < 0 ||
          out.info.maxDamping < 0 || !(out.info.servoRateHz > 0))
        return fail(ErrorCode::Parse, "Info limits must be >= 0 and the servo rate > 0",
                    formatString("datagram byte %zu", kMessageHeaderBytes + limitsAt),
                    "fix the device's reported limits");
      out.info.workspace = Aabb(lo, hi);
      break;
    }
    default:
      break;
  }
  if (!r.ok()) return r.error();
  return out;
}

// ---- in-process links -----------------------------------------------------------

namespace detail {

constexpr std::string_view kInprocPrefix = "inproc:";

/// One datagram in an in-process queue, stamped on the link's clock.
struct InprocDatagram {
  std::int64_t sentNs = 0;
  std::size_t size = 0;
  std::array<std::byte, kTeleopMaxDatagram> bytes{};
};

/// The two queues between a device end and its host end (see the header).
/// Each queue has one producer (the sending end's servo thread, or its
/// control thread before that thread runs) and one consumer (the receiving
/// end's poll()).
struct InprocLink {
  std::string name;
  RealClock wallClock;
  const Clock* clock = &wallClock;
  HapticInfo deviceInfo;
  SpscRing<InprocDatagram, 256> toDevice, toHost;
  std::atomic<bool> deviceOpen{true}, hostAttached{false};
};

/// The process's in-process links by name; a name is free again once its
/// device end closed.
class InprocRegistry {
 public:
  static InprocRegistry& instance() {
    static InprocRegistry registry;
    return registry;
  }

  Result<std::shared_ptr<InprocLink>> open(const std::string& name, const Clock* clock,
                                           const HapticInfo& info) {
    std::lock_guard lock(mutex_);
    if (auto it = links_.find(name); it != links_.end())
      if (auto alive = it->second.lock(); alive && alive->deviceOpen.load())
        return fail(ErrorCode::Network, "an in-process device \"" + name + "\" is already open",
                    "TeleopDevice inproc:" + name, "give each served device a name of its own");
    auto link = std::make_shared<InprocLink>();
    link->name = name;
    if (clock != nullptr) link->clock = clock;
    link->deviceInfo = info;
    links_[name] = link;
    return link;
  }

  Result<std::shared_ptr<InprocLink>> join(const std::string& name) {
    std::lock_guard lock(mutex_);
    const auto it = links_.find(name);
    std::shared_ptr<InprocLink> link = it == links_.end() ? nullptr : it->second.lock();
    if (!link || !link->deviceOpen.load())
      return fail(ErrorCode::NotFound, "no in-process device \"" + name + "\" is open",
                  "TeleopHost inproc:" + name,
                  "open its TeleopDevice (a scene's served device) before the host");
    if (link->hostAttached.exchange(true))
      return fail(ErrorCode::Busy, "another host streams with in-process device \"" + name + "\"",
                  "TeleopHost inproc:" + name, "close the other host first");
    return link;
  }

  void close(const InprocLink& link) {
    std::lock_guard lock(mutex_);
    if (auto it = links_.find(link.name); it != links_.end() && it->second.lock().get() == &link)
      links_.erase(it);
  }

 private:
  std::mutex mutex_;
  std::map<std::string, std::weak_ptr<InprocLink>, std::less<>> links_;
};

// ---- the shared implementation --------------------------------------------------

/// Everything both ends share; Role picks which stream is received.
struct TeleopEnd {
  enum class Role : std::uint8_t { Host, Device };

  TeleopEnd(Role r, TeleopOptions o)
      : role(r), options(std::move(o)), timeoutNs(static_cast<std::int64_t>(options.timeoutSeconds * 1e9)) {}
  ~TeleopEnd() {
    close();
    if (fd >= 0) ::close(fd);
  }

  Status bind() {
    const std::string where = std::string(role == Role::Host ? "TeleopHost " : "TeleopDevice ") +
                              describe(options.local);
    if (!(options.timeoutSeconds > 0) || !std::isfinite(options.timeoutSeconds))
      return fail(ErrorCode::InvalidArgument, formatString("timeoutSeconds is %g", options.timeoutSeconds), where,
                  "give a timeout > 0 (0.1 s is typical at 1 kHz)");
    const std::string& linkAddress = role == Role::Host ? options.peer.address : options.local.address;
    if (linkAddress.starts_with(kInprocPrefix)) return bindInproc(linkAddress.substr(kInprocPrefix.size()));
    if (options.clock != nullptr)
      return fail(
          ErrorCode::InvalidArgument, "a clock was given for a socket", where,
          "datagrams arrive on the wall clock: leave TeleopOptions::clock null, or use an inproc: link");
    auto address = parseAddress(options.local.address, where + ": local.address");
    if (!address) return address.error();
    for (const std::string& a : options.allow)
      if (auto parsed = parseAddress(a, where + ": allow entry"); !parsed) return parsed.error();
    if (role == Role::Host) {
      auto peerAddress = parseAddress(options.peer.address, where + ": peer.address");
      if (!peerAddress) return peerAddress.error();
      if (options.peer.port == 0)
        return fail(ErrorCode::InvalidArgument, "peer port is 0", where, "give the device server's port");
      hostPeer = udp::endpoint(*peerAddress, options.peer.port);
      peer.store(toPeer(*hostPeer));
    }
    const udp::endpoint endpoint(*address, options.local.port);
    fd = ::socket(endpoint.protocol().family(), SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (fd < 0 || ::bind(fd, endpoint.data(), static_cast<socklen_t>(endpoint.size())) != 0) {
      const int err = errno;
      return fail(ErrorCode::Network, std::string("cannot bind: ") + std::strerror(err), where,
                  err == EADDRINUSE ? "another program uses this port: pick another or port 0"
                                    : "use a local address of this machine");
    }
    udp::endpoint bound;
    socklen_t length = static_cast<socklen_t>(bound.capacity());
    ::getsockname(fd, bound.data(), &length);
    bound.resize(length);
    port = bound.port();
    // The receive thread wakes at least this often to notice close().
    const timeval wake{0, kWakeMicroseconds};
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &wake, sizeof wake);
    name = std::string(role == Role::Host ? "TeleopHost " : "TeleopDevice ") +
           describe({options.local.address, port});
    if (options.emulate) {
      // The emulator's thread becomes the one that handles datagrams; each
      // packet carries its sender's address in front.
      emulatorThread = std::make_unique<IoThread>("dm-teleop-emu");
      if (auto s = emulatorThread->start(); !s) return s;
      auto e = LinkEmulator::create(*emulatorThread, *options.emulate, [this](std::span<const std::byte> p) {
        if (p.size() < sizeof(PeerAddress)) return;
        PeerAddress sender;
        std::memcpy(static_cast<void*>(&sender), p.data(), sizeof sender);
        std::memcpy(from.data(), &sender.address, sender.length);
        from.resize(sender.length);
        onDatagram(p.subspan(sizeof sender));
      });
      if (!e) return std::move(e).error();
      emulator = std::move(*e);
    }
    receiver = std::thread([this] { receiveLoop(); });
    return ok();
  }

  // The in-process link `linkName` (see the header): no socket, no thread.
  Status bindInproc(const std::string& linkName) {
    name = std::string(role == Role::Host ? "TeleopHost " : "TeleopDevice ") + std::string(kInprocPrefix) +
           linkName;
    if (linkName.empty())
      return fail(ErrorCode::InvalidArgument, "the in-process link has no name", name,
                  "write \"inproc:NAME\"");
    if (!options.allow.empty())
      return fail(ErrorCode::InvalidArgument,
                  "an allow list names IP addresses; an in-process link has no address", name,
                  "remove the allow list");
    auto link = role == Role::Device ? InprocRegistry::instance().open(linkName, options.clock, localInfo)
                                     : InprocRegistry::instance().join(linkName);
    if (!link) return std::move(link).error();
    inproc = std::move(*link);
    if (role == Role::Host) {
      if (options.clock != nullptr && options.clock != inproc->clock) {
        inproc->hostAttached.store(false);
        inproc.reset();  // not attached: close() leaves the link alone
        return fail(ErrorCode::InvalidArgument, "the host names a clock other than its device's", name,
                    "leave TeleopOptions::clock null on the host: it takes the device's");
      }
      hostPeer = udp::endpoint();  // the one peer of a link has no address
      peer.store(toPeer(*hostPeer));
    }
    clock = inproc->clock;
    options.clocksSynchronized = true;  // both ends read the link's one clock
    if (options.emulate) {
      // Datagrams are at most kTeleopMaxDatagram: size the slots for that.
      LinkEmulatorOptions o = *options.emulate;
      o.maxPacketBytes = kTeleopMaxDatagram;
      auto e = SteppedLinkEmulator::create(o);
      if (!e) return std::move(e).error();
      stepped = std::move(*e);
    }
    return ok();
  }

  // The reader thread: an in-process end takes what arrived and handles
  // what is due on the link's clock.
  void poll() noexcept {
    if (!inproc || closed.load(std::memory_order_acquire)) return;
    auto& in = role == Role::Host ? inproc->toHost : inproc->toDevice;
    while (in.tryPop(incoming)) {
      const std::span<const std::byte> datagram(incoming.bytes.data(), incoming.size);
      if (stepped) {
        if (!stepped->submit(datagram, incoming.sentNs)) malformed.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      from = udp::endpoint();
      onDatagram(datagram);
    }
    if (!stepped) return;
    std::span<const std::byte> due;
    while (stepped->popDue(linkNow(), due)) {
      from = udp::endpoint();
      onDatagram(due);
    }
  }

  std::int64_t linkNow() const noexcept { return clock->now(); }

  void receiveLoop() {
    pthread_setname_np(pthread_self(), role == Role::Host ? "dm-teleop-host" : "dm-teleop-dev");
    std::array<std::byte, sizeof(PeerAddress) + kTeleopMaxDatagram + 1> packet{};  // emulation only
    while (!closed.load(std::memory_order_acquire)) {
      udp::endpoint sender;
      socklen_t length = static_cast<socklen_t>(sender.capacity());
      const ssize_t n = ::recvfrom(fd, buffer.data(), buffer.size(), 0, sender.data(), &length);
      if (n < 0) continue;  // the wake-up timeout, or an ICMP error for an earlier send
      sender.resize(length);
      const std::span<const std::byte> datagram(buffer.data(), static_cast<std::size_t>(n));
      if (emulator) {
        const PeerAddress p = toPeer(sender);
        std::memcpy(packet.data(), &p, sizeof p);
        std::memcpy(packet.data() + sizeof p, datagram.data(), datagram.size());
        (void)emulator->submit(std::span<const std::byte>(packet.data(), sizeof p + datagram.size()));
        continue;
      }
      from = sender;
      onDatagram(datagram);
    }
  }

  // Logs at most one refusal per second per end, with a count of the rest.
  void refuse(std::atomic<std::uint64_t>& counter, const std::string& why) {
    counter.fetch_add(1, std::memory_order_relaxed);
    const std::int64_t t = nowNs();
    ++suppressed;
    if (t - lastRefusalLogNs < 1'000'000'000) return;
    lastRefusalLogNs = t;
    log::warn("%s: dropped a datagram from %s: %s (%llu dropped since the last report)", name.c_str(),
              describe(toSocketAddress(from.address(), from.port())).c_str(), why.c_str(),
              static_cast<unsigned long long>(suppressed));
    suppressed = 0;
  }

  bool allowed(const udp::endpoint& e) const {
    if (options.allow.empty()) return true;
    for (const std::string& a : options.allow) {
      std::error_code ec;
      if (asio::ip::make_address(a, ec) == e.address() && !ec) return true;
    }
    return false;
  }

  void onDatagram(std::span<const std::byte> bytes) {
    const std::int64_t now = linkNow();
    if (bytes.size() > kTeleopMaxDatagram) return refuse(malformed, "larger than any tele-operation message");
    auto packet = decodeTeleopPacket(bytes);
    if (!packet) return refuse(malformed, packet.error().message());
    const std::uint16_t type = packet->header.type;
    if (role == Role::Host) {
      if (from != *hostPeer) return refuse(foreign, "not the device this host streams with");
      if (type == kTeleopInfoType) {
        std::lock_guard lock(infoMutex);
        deviceInfo = packet->info;
        infoArrived.notify_all();
        return;
      }
      if (type == kTeleopWaveType) return queueWave(packet->wave);
      if (type != kTeleopStateType) return refuse(foreign, std::string(typeName(type)) + " is sent by hosts");
      return onStream(*packet, now);
    }
    // Device side: the host is whoever is allowed and talks, unless the
    // current host is still alive.
    if (type != kTeleopHelloType && type != kTeleopForceType && type != kTeleopWaveType)
      return refuse(foreign, std::string(typeName(type)) + " is sent by devices");
    if (!allowed(from)) return refuse(foreign, "sender is not in the allow list");
    if (!devicePeer || from != *devicePeer) {
      if (devicePeer && now - lastPeerNs < timeoutNs) return refuse(foreign, "another host is streaming");
      if (devicePeer)
        log::info("%s: host %s replaces %s, silent for %.3f s", name.c_str(),
                  describe(toSocketAddress(from.address(), from.port())).c_str(),
                  describe(toSocketAddress(devicePeer->address(), devicePeer->port())).c_str(),
                  1e-9 * static_cast<double>(now - lastPeerNs));
      devicePeer = from;
      peer.store(toPeer(from));
      resetTiming();
    }
    lastPeerNs = now;
    peerAliveNs.store(now, std::memory_order_release);
    if (type == kTeleopHelloType) {
      std::array<std::byte, kTeleopMaxDatagram> answer;
      const std::size_t n =
          writeTeleopInfo({.sequence = infoSequence++, .timestampNs = linkNow()}, localInfo, answer);
      sendRaw(std::span<const std::byte>(answer.data(), n));
      return;
    }
    if (type == kTeleopWaveType) return queueWave(packet->wave);
    onStream(*packet, now);
  }

  // Waves carry their own sequence and energy; WaveReceiver sorts them out.
  void queueWave(const WaveSample& w) {
    if (waves.tryPush(w))
      wavesIn.fetch_add(1, std::memory_order_relaxed);
    else
      wavesDropped.fetch_add(1, std::memory_order_relaxed);
  }

  void resetTiming() {
    tracker.reset();
    havePrevious = false;
    filterCount = 0;
  }

  // A State (host) or Force (device) that passed every check.
  void onStream(const TeleopPacket& p, std::int64_t now) {
    const ArrivalInfo arrival = tracker.observe(p.header.sequence);
    if (arrival.kind == Arrival::Duplicate) return void(duplicates.fetch_add(1, std::memory_order_relaxed));
    if (arrival.kind == Arrival::Stale) return void(stale.fetch_add(1, std::memory_order_relaxed));
    if (arrival.kind == Arrival::Late) late.fetch_add(1, std::memory_order_relaxed);
    received.fetch_add(1, std::memory_order_relaxed);
    lastAcceptNs.store(now, std::memory_order_release);
    const std::int64_t sentNs = p.header.timestampNs;
    // RFC 3550 §6.4.1: D = (Rj − Ri) − (Sj − Si), J += (|D| − J)/16.
    if (havePrevious) {
      const double d = static_cast<double>((now - previousReceiveNs) - (sentNs - previousSendNs));
      jitterNs += (std::abs(d) - jitterNs) / 16.0;
      jitterBits.store(std::bit_cast<std::uint64_t>(jitterNs), std::memory_order_relaxed);
    }
    havePrevious = true;
    previousReceiveNs = now;
    previousSendNs = sentNs;
    // NTP: t1 = echo (our send), t2 = t3 − hold (peer receive), t3 = sentNs, t4 = now.
    if (p.echo.holdNs >= 0) {
      const std::int64_t rtt = (now - p.echo.peerSendNs) - p.echo.holdNs;
      if (rtt >= 0 && rtt < 10'000'000'000) {
        roundTrip.record(rtt);
        lastRoundTrip.store(rtt, std::memory_order_relaxed);
        const std::int64_t theta = ((sentNs - p.echo.holdNs - p.echo.peerSendNs) + (sentNs - now)) / 2;
        filter[filterNext] = {rtt, theta};
        filterNext = (filterNext + 1) % filter.size();
        filterCount = std::min(filterCount + 1, filter.size());
        std::size_t best = 0;
        for (std::size_t i = 1; i < filterCount; ++i)
          if (filter[i].first < filter[best].first) best = i;
        if (!options.clocksSynchronized) offsetNs.store(filter[best].second, std::memory_order_relaxed);
        offsetKnown = true;
      }
    }
    if (options.clocksSynchronized || offsetKnown) {
      const std::int64_t oneWayNs =
          std::max<std::int64_t>(0, now - (sentNs - offsetNs.load(std::memory_order_relaxed)));
      oneWay.record(oneWayNs);
      lastOneWay.store(oneWayNs, std::memory_order_relaxed);
    }
    lost.store(tracker.stats().missing, std::memory_order_relaxed);
    if (arrival.kind == Arrival::Late) return;  // older than what the servo thread already has
    echo.store({sentNs, now});
    if (role == Role::Host) {
      auto& slot = states.writeBuffer();
      slot = {p.state, now, true};
      states.publish();
    } else {
      auto& slot = forces.writeBuffer();
      slot = {p.force, now, true};
      forces.publish();
    }
  }

  // Real-time safe: one non-blocking sendto, or one push into an
  // in-process queue whose other end is there.
  bool sendRaw(std::span<const std::byte> bytes) noexcept {
    PeerAddress p;
    if (closed.load(std::memory_order_acquire) || !peer.load(p)) {
      sendFailed.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    if (inproc) {
      const bool there = role == Role::Host ? inproc->deviceOpen.load(std::memory_order_acquire)
                                            : inproc->hostAttached.load(std::memory_order_acquire);
      auto& out = role == Role::Host ? inproc->toDevice : inproc->toHost;
      bool pushed = false;
      if (there && bytes.size() <= kTeleopMaxDatagram) {
        InprocDatagram& d = outgoing;
        d.sentNs = linkNow();
        d.size = bytes.size();
        std::memcpy(d.bytes.data(), bytes.data(), bytes.size());
        pushed = out.tryPush(d);
      }
      (pushed ? sent : sendFailed).fetch_add(1, std::memory_order_relaxed);
      return pushed;
    }
    const ssize_t n = ::sendto(fd, bytes.data(), bytes.size(), MSG_DONTWAIT | MSG_NOSIGNAL,
                               reinterpret_cast<const sockaddr*>(&p.address), p.length);
    if (n != static_cast<ssize_t>(bytes.size())) {
      sendFailed.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    sent.fetch_add(1, std::memory_order_relaxed);
    return true;
  }

  TeleopEcho currentEcho(std::int64_t now) const noexcept {
    EchoSource e;
    if (!echo.load(e)) return {};
    return {e.peerSendNs, now - e.receivedNs};
  }

  template <class Write, class Value>
  bool sendStream(Write write, const Value& value) noexcept {
    std::array<std::byte, kMessageHeaderBytes + kTeleopStateBytes> datagram;
    const std::int64_t now = linkNow();
    const MessageHeader header{.sequence = sequence.fetch_add(1, std::memory_order_relaxed), .timestampNs = now};
    const std::size_t n = write(header, currentEcho(now), value, std::span<std::byte>(datagram));
    return sendRaw(std::span<const std::byte>(datagram.data(), n));
  }

  bool sendWave(const WaveSample& w) noexcept {
    std::array<std::byte, kMessageHeaderBytes + kTeleopWaveBytes> datagram;
    const MessageHeader header{.sequence = waveSequence.fetch_add(1, std::memory_order_relaxed),
                               .timestampNs = linkNow()};
    const std::size_t n = writeTeleopWave(header, w, datagram);
    return sendRaw(std::span<const std::byte>(datagram.data(), n));
  }

  // Host: a state arrived within the timeout. Device: a Hello, Force or
  // Wave came from the current host within it.
  bool linkUp() const noexcept {
    const std::int64_t last = (role == Role::Host ? lastAcceptNs : peerAliveNs).load(std::memory_order_acquire);
    return last != kNever && linkNow() - last < timeoutNs;
  }

  TeleopStats stats() const {
    TeleopStats s;
    s.sent = sent.load(std::memory_order_relaxed);
    s.sendFailed = sendFailed.load(std::memory_order_relaxed);
    s.received = received.load(std::memory_order_relaxed);
    s.malformed = malformed.load(std::memory_order_relaxed);
    s.foreign = foreign.load(std::memory_order_relaxed);
    s.duplicates = duplicates.load(std::memory_order_relaxed);
    s.late = late.load(std::memory_order_relaxed);
    s.stale = stale.load(std::memory_order_relaxed);
    s.lost = lost.load(std::memory_order_relaxed);
    s.wavesIn = wavesIn.load(std::memory_order_relaxed);
    s.wavesDropped = wavesDropped.load(std::memory_order_relaxed);
    const double arrived = static_cast<double>(s.received);
    s.lossRatio = s.lost + s.received > 0 ? static_cast<double>(s.lost) / (static_cast<double>(s.lost) + arrived) : 0;
    s.roundTrip = summarize(roundTrip, 1e-9 * static_cast<double>(lastRoundTrip.load(std::memory_order_relaxed)));
    s.oneWay = summarize(oneWay, 1e-9 * static_cast<double>(lastOneWay.load(std::memory_order_relaxed)));
    s.jitter = 1e-9 * std::bit_cast<double>(jitterBits.load(std::memory_order_relaxed));
    s.clockOffset = 1e-9 * static_cast<double>(offsetNs.load(std::memory_order_relaxed));
    s.linkUp = linkUp();
    const std::int64_t last = lastAcceptNs.load(std::memory_order_acquire);
    s.sinceLastReceive = last == kNever ? -1.0 : 1e-9 * static_cast<double>(linkNow() - last);
    return s;
  }

  // Stops the receive thread (within kWakeMicroseconds) and the emulator;
  // the descriptor stays open until destruction (see the file comment).
  void close() {
    if (inproc && !closed.load()) {
      if (role == Role::Device) {
        inproc->deviceOpen.store(false, std::memory_order_release);
        InprocRegistry::instance().close(*inproc);
      } else {
        inproc->hostAttached.store(false, std::memory_order_release);
      }
    }
    closed.store(true, std::memory_order_release);
    if (receiver.joinable()) receiver.join();
    if (emulator) emulator->close();
    if (emulatorThread) emulatorThread->stop();
    std::lock_guard lock(infoMutex);
    infoArrived.notify_all();
  }

  static constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::min();
  static constexpr int kWakeMicroseconds = 20'000;

  const Role role;
  TeleopOptions options;
  std::string name;
  int fd = -1;
  std::thread receiver;
  std::unique_ptr<IoThread> emulatorThread;  // declared before the emulator: destroyed after it
  std::unique_ptr<LinkEmulator> emulator;
  std::uint16_t port = 0;
  const std::int64_t timeoutNs;
  std::atomic<bool> closed{false};
  RealClock wallClock;
  const Clock* clock = &wallClock;  // an in-process link's, or the wall clock

  // In-process link (see the header): the queues, the emulator on the
  // link's clock, and one datagram's room for each direction (the reader's
  // and the sender's thread).
  std::shared_ptr<InprocLink> inproc;
  std::unique_ptr<SteppedLinkEmulator> stepped;
  InprocDatagram incoming, outgoing;

  // The handling thread only: the receive thread, the emulator's, or poll()'s.
  std::array<std::byte, kTeleopMaxDatagram + 1> buffer{};
  udp::endpoint from;
  std::optional<udp::endpoint> hostPeer;    // host: the device (fixed)
  std::optional<udp::endpoint> devicePeer;  // device: the current host
  std::int64_t lastPeerNs = 0;
  std::uint32_t infoSequence = 0;
  HapticInfo localInfo;  // device: the answer to Hello
  SequenceTracker tracker;
  bool havePrevious = false, offsetKnown = false;
  std::int64_t previousReceiveNs = 0, previousSendNs = 0;
  double jitterNs = 0;
  std::array<std::pair<std::int64_t, std::int64_t>, 16> filter{};  // (round trip, offset), NTP clock filter
  std::size_t filterNext = 0, filterCount = 0;
  std::int64_t lastRefusalLogNs = kNever / 2;
  std::uint64_t suppressed = 0;

  // Receive thread → servo thread.
  SeqLocked<PeerAddress> peer;
  SeqLocked<EchoSource> echo;
  TripleBuffer<Stamped<HapticState>> states;
  TripleBuffer<Stamped<HapticOutput>> forces;
  SpscRing<WaveSample, 1024> waves;
  std::atomic<std::int64_t> lastAcceptNs{kNever}, peerAliveNs{kNever};

  // Servo thread.
  std::atomic<std::uint32_t> sequence{0}, waveSequence{0};

  // Statistics: written by one thread each, read by stats().
  std::atomic<std::uint64_t> sent{0}, sendFailed{0}, received{0}, malformed{0}, foreign{0}, duplicates{0}, late{0},
      stale{0}, lost{0}, wavesIn{0}, wavesDropped{0};
  LatencyHistogram roundTrip, oneWay;
  std::atomic<std::int64_t> lastRoundTrip{0}, lastOneWay{0}, offsetNs{0};
  std::atomic<std::uint64_t> jitterBits{0};

  // Host: the device's Info.
  mutable std::mutex infoMutex;
  std::condition_variable infoArrived;
  std::optional<HapticInfo> deviceInfo;
};

}  // namespace detail

// ---- TeleopHost -------------------------------------------------------------------

struct TeleopHost::Impl : detail::TeleopEnd {
  using TeleopEnd::TeleopEnd;
};

TeleopHost::TeleopHost(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
TeleopHost::~TeleopHost() { close(); }

Result<std::unique_ptr<TeleopHost>> TeleopHost::open(TeleopOptions options) {
  auto impl = std::make_unique<Impl>(detail::TeleopEnd::Role::Host, std::move(options));
  if (auto s = impl->bind(); !s) return std::move(s).error();
  return std::unique_ptr<TeleopHost>(new TeleopHost(std::move(impl)));
}

Result<HapticInfo> TeleopHost::waitForDevice(std::chrono::milliseconds timeout) {
  if (impl_->inproc) {
    // The link holds its device's Info; the Hello makes the device side
    // stream to this host from its next poll.
    if (!impl_->inproc->deviceOpen.load() || !sendHello())
      return fail(ErrorCode::Network, "the in-process device closed", impl_->name, "open it again");
    std::lock_guard lock(impl_->infoMutex);
    impl_->deviceInfo = impl_->inproc->deviceInfo;
    return *impl_->deviceInfo;
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  std::unique_lock lock(impl_->infoMutex);
  impl_->deviceInfo.reset();
  while (!impl_->deviceInfo && !impl_->closed.load()) {
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline) break;
    lock.unlock();
    sendHello();
    lock.lock();
    impl_->infoArrived.wait_until(lock, std::min(deadline, now + std::chrono::milliseconds(50)),
                                  [&] { return impl_->deviceInfo.has_value() || impl_->closed.load(); });
  }
  if (impl_->deviceInfo) return *impl_->deviceInfo;
  return fail(ErrorCode::Timeout,
              formatString("no answer from the device side at %s within %lld ms",
                           describe(impl_->options.peer).c_str(), static_cast<long long>(timeout.count())),
              impl_->name, "start the device side (TeleopDevice / dm-teleop-device) and check address and firewall");
}

std::optional<HapticInfo> TeleopHost::deviceInfo() const {
  std::lock_guard lock(impl_->infoMutex);
  return impl_->deviceInfo;
}

bool TeleopHost::sendForce(const HapticOutput& force) noexcept { return impl_->sendStream(writeTeleopForce, force); }

bool TeleopHost::sendHello() noexcept {
  std::array<std::byte, kMessageHeaderBytes + kTeleopHelloBytes> datagram;
  const std::size_t n = writeTeleopHello({.timestampNs = impl_->linkNow()}, datagram);
  return impl_->sendRaw(std::span<const std::byte>(datagram.data(), n));
}

bool TeleopHost::sendWave(const WaveSample& wave) noexcept { return impl_->sendWave(wave); }
bool TeleopHost::popWave(WaveSample& wave) noexcept { return impl_->waves.tryPop(wave); }

bool TeleopHost::latestState(HapticState& state, std::int64_t* ageNs) noexcept {
  const auto& s = impl_->states.read();
  if (!s.valid) return false;
  state = s.value;
  if (ageNs) *ageNs = impl_->linkNow() - s.receivedNs;
  return true;
}

bool TeleopHost::linkUp() const noexcept { return impl_->linkUp(); }
void TeleopHost::poll() noexcept { impl_->poll(); }
const Clock& TeleopHost::clock() const noexcept { return *impl_->clock; }
bool TeleopHost::onSuppliedClock() const noexcept {
  return impl_->inproc != nullptr && impl_->inproc->clock != &impl_->inproc->wallClock;
}
std::uint16_t TeleopHost::port() const noexcept { return impl_->port; }
TeleopStats TeleopHost::stats() const { return impl_->stats(); }
void TeleopHost::close() { impl_->close(); }

// ---- TeleopDevice -----------------------------------------------------------------

struct TeleopDevice::Impl : detail::TeleopEnd {
  using TeleopEnd::TeleopEnd;
};

TeleopDevice::TeleopDevice(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
TeleopDevice::~TeleopDevice() { close(); }

Result<std::unique_ptr<TeleopDevice>> TeleopDevice::open(TeleopOptions options, HapticInfo info) {
  auto impl = std::make_unique<Impl>(detail::TeleopEnd::Role::Device, std::move(options));
  impl->localInfo = std::move(info);
  if (auto s = impl->bind(); !s) return std::move(s).error();
  return std::unique_ptr<TeleopDevice>(new TeleopDevice(std::move(impl)));
}

bool TeleopDevice::sendState(const HapticState& state) noexcept {
  return impl_->sendStream(writeTeleopState, state);
}

bool TeleopDevice::sendWave(const WaveSample& wave) noexcept { return impl_->sendWave(wave); }
bool TeleopDevice::popWave(WaveSample& wave) noexcept { return impl_->waves.tryPop(wave); }

bool TeleopDevice::latestForce(HapticOutput& force, std::int64_t* ageNs) noexcept {
  const auto& f = impl_->forces.read();
  if (!f.valid) return false;
  force = f.value;
  if (ageNs) *ageNs = impl_->linkNow() - f.receivedNs;
  return true;
}

bool TeleopDevice::linkUp() const noexcept { return impl_->linkUp(); }
void TeleopDevice::poll() noexcept { impl_->poll(); }
const Clock& TeleopDevice::clock() const noexcept { return *impl_->clock; }
std::uint16_t TeleopDevice::port() const noexcept { return impl_->port; }
TeleopStats TeleopDevice::stats() const { return impl_->stats(); }
void TeleopDevice::close() { impl_->close(); }

// ---- TeleopDeviceBridge -------------------------------------------------------------

TeleopDeviceBridge::TeleopDeviceBridge(HapticDevice& device, TeleopDevice& link,
                                       TeleopBridgeOptions options) noexcept
    : device_(device), link_(link), timeoutNs_(static_cast<std::int64_t>(options.timeoutSeconds * 1e9)) {
  // HapticDevice::open guarantees a positive finite servo rate.
  if (options.waveImpedance > 0.0 && std::isfinite(options.waveImpedance))
    wave_.emplace(WavePortOptions{.impedance = options.waveImpedance,
                                  .dt = 1.0 / device.info().servoRateHz,
                                  .policy = options.wavePolicy});
}

DeviceStatus TeleopDeviceBridge::step(std::int64_t nowNs) noexcept {
  const double period = 1.0 / device_.info().servoRateHz;
  const double elapsed = lastStepNs_ ? 1e-9 * static_cast<double>(nowNs - *lastStepNs_) : period;
  lastStepNs_ = nowNs;
  link_.poll();
  // Command first, so that servo() sends a force of age 0 in this period.
  HapticOutput force;
  bool live = false;
  if (wave_) {
    // Master port: ẋm of the last servo, the waves that arrived since.
    WaveSample w;
    while (link_.popWave(w)) wave_->receive(w);
    force.force = wave_->step(device_.state().linearVelocity);
    live = link_.linkUp();
  } else {
    std::int64_t age = 0;
    live = link_.latestForce(force, &age) && age < timeoutNs_;
  }
  if (!live) {
    force = HapticOutput{};
    ++zeroed_;
  }
  device_.command(force.force, force.torque, nowNs);
  // First-order low pass over kMeanForceSeconds of what the device was told.
  const double alpha = std::clamp(elapsed / kMeanForceSeconds, 0.0, 1.0);
  if (force.force.allFinite()) meanForce_ += alpha * (force.force - meanForce_);
  const DeviceStatus status = device_.servo(nowNs);
  if (status == DeviceStatus::Ok) link_.sendState(device_.state());
  if (wave_) link_.sendWave(wave_->outgoing());
  return status;
}

}  // namespace dm
