// net_teleop_bench — loopback round-trip latency of the 1 kHz tele-operation
// device stream (dm/network/teleop.hpp) against raw POSIX UDP doing the same
// exchange, in one process on the same machine.
//
//  * ours: a device servo thread sends a State every 1 ms (TeleopDevice);
//    a host servo thread at 1 kHz answers each new state with a Force
//    (TeleopHost); each end's receive thread blocks in recvfrom. The device
//    measures the round trip from the echo in each Force, minus the host's
//    reported hold time — the stream's own statistics, as a user sees them.
//  * raw, two ways, with the same datagram sizes (164 bytes out, 92 back)
//    between plain UDP sockets; the responder blocks in recv() and answers
//    at once: (a) the sender blocks in recv() for each answer (ping-pong,
//    the least a UDP round trip costs, but a servo loop cannot block so);
//    (b) the sender sends every 1 ms and sleeps and a receive thread of its
//    own takes the answers — the stream's thread layout, like for like.
// All are recorded in dm::LatencyHistogram (1.6 % resolution). Prints p50 /
// p99 / p99.9 / max in microseconds and ours/raw ratios (< 1: ours faster).
//
//   build/Bench/net_teleop_bench [seconds per run, default 5]
#include <dm/core/rt_loop.hpp>
#include <dm/network/teleop.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <thread>

namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

std::int64_t nowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
}

/// Runs `step` every millisecond until `stop`.
template <class F>
std::thread every1ms(std::atomic<bool>& stop, F step) {
  return std::thread([&stop, step]() mutable {
    auto next = Clock::now();
    while (!stop.load(std::memory_order_relaxed)) {
      step();
      next += 1ms;
      std::this_thread::sleep_until(next);
    }
  });
}

struct Result {
  std::uint64_t count = 0;
  double p50 = 0, p99 = 0, p999 = 0, max = 0;  // us
  std::uint64_t lost = 0;
  double oneWayUp = 0, oneWayDown = 0;  // us, ours only
};

Result ours(double seconds) {
  dm::HapticInfo info;
  info.servoRateHz = 1000;
  auto device = dm::TeleopDevice::open({}, info);
  if (!device) std::abort();
  auto host = dm::TeleopHost::open({.peer = {"127.0.0.1", (*device)->port()}, .clocksSynchronized = true});
  if (!host || !(*host)->waitForDevice(2s)) std::abort();
  std::atomic<bool> stop{false};
  dm::HapticState state;
  std::thread deviceThread = every1ms(stop, [&] {
    state.timeNs = nowNs();
    (*device)->sendState(state);
  });
  std::int64_t lastSeen = -1;
  std::thread hostThread = every1ms(stop, [&] {
    dm::HapticState s;
    if ((*host)->latestState(s) && s.timeNs != lastSeen) {
      lastSeen = s.timeNs;
      (*host)->sendForce({});
    }
  });
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  stop = true;
  deviceThread.join();
  hostThread.join();
  const dm::TeleopStats d = (*device)->stats();
  const dm::TeleopStats h = (*host)->stats();
  return {d.roundTrip.count, 1e6 * d.roundTrip.p50, 1e6 * d.roundTrip.p99, 1e6 * d.roundTrip.p999,
          1e6 * d.roundTrip.max, h.lost + d.lost, 1e6 * h.oneWay.p50, 1e6 * d.oneWay.p50};
}

int udpSocket(std::uint16_t* port) {
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) std::abort();
  socklen_t n = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  *port = ntohs(a.sin_port);
  timeval tv{0, 100000};  // recv gives up after 100 ms (a lost datagram)
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  return fd;
}

void connectTo(int fd, std::uint16_t port) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(port);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) std::abort();
}

/// Raw POSIX UDP. The responder blocks in recv and answers at once, putting
/// the request's send time and its hold time in the answer. pingPong: the
/// sender blocks in recv for each answer; otherwise it sends every 1 ms and
/// sleeps, and a receive thread of its own takes the answers (the stream's
/// thread structure).
Result raw(double seconds, bool pingPong) {
  std::uint16_t pa = 0, pb = 0;
  const int a = udpSocket(&pa), b = udpSocket(&pb);
  connectTo(a, pb);
  connectTo(b, pa);
  std::atomic<bool> stop{false};
  std::thread responder([&] {
    unsigned char in[256], out[dm::kMessageHeaderBytes + dm::kTeleopForceBytes] = {};
    while (!stop.load(std::memory_order_relaxed)) {
      if (::recv(b, in, sizeof in, 0) <= 0) continue;
      const std::int64_t received = nowNs();
      std::memcpy(out + 8, in, 8);  // the request's send time
      const std::int64_t hold = nowNs() - received;
      std::memcpy(out, &hold, 8);
      ::send(b, out, sizeof out, 0);
    }
  });
  dm::LatencyHistogram h;
  const auto take = [&h](const unsigned char* answer) {
    std::int64_t hold = 0, sent = 0;
    std::memcpy(&hold, answer, 8);
    std::memcpy(&sent, answer + 8, 8);
    h.record(nowNs() - sent - hold);
  };
  std::atomic<bool> stopReceiver{false};
  std::thread receiver;
  if (!pingPong)
    receiver = std::thread([&] {
      unsigned char in[256];
      while (!stopReceiver.load(std::memory_order_relaxed))
        if (::recv(a, in, sizeof in, 0) > 0) take(in);
    });
  unsigned char out[dm::kMessageHeaderBytes + dm::kTeleopStateBytes] = {}, in[256];
  std::uint64_t sent = 0;
  const auto end = Clock::now() + std::chrono::duration<double>(seconds);
  auto next = Clock::now();
  while (Clock::now() < end) {
    const std::int64_t t0 = nowNs();
    std::memcpy(out, &t0, 8);
    ::send(a, out, sizeof out, 0);
    ++sent;
    if (pingPong && ::recv(a, in, sizeof in, 0) > 0) take(in);
    next += 1ms;
    std::this_thread::sleep_until(next);
  }
  std::this_thread::sleep_for(20ms);  // the last answers
  stopReceiver = true;
  if (receiver.joinable()) receiver.join();
  stop = true;
  responder.join();
  ::close(a);
  ::close(b);
  Result r;
  r.count = h.count();
  r.lost = sent - r.count;
  r.p50 = 1e-3 * static_cast<double>(h.percentile(50));
  r.p99 = 1e-3 * static_cast<double>(h.percentile(99));
  r.p999 = 1e-3 * static_cast<double>(h.percentile(99.9));
  r.max = 1e-3 * static_cast<double>(h.max());
  return r;
}

void print(const char* name, const Result& r) {
  std::printf("%-34s %8llu %9.1f %9.1f %9.1f %9.1f %6llu\n", name, static_cast<unsigned long long>(r.count), r.p50,
              r.p99, r.p999, r.max, static_cast<unsigned long long>(r.lost));
}

}  // namespace

int main(int argc, char** argv) {
  const double seconds = argc > 1 ? std::atof(argv[1]) : 5.0;
  if (!(seconds > 0)) {
    std::fprintf(stderr, "usage: net_teleop_bench [seconds per run > 0]\n");
    return 2;
  }
  const Result pingPong = raw(seconds, true);
  const Result sameThreads = raw(seconds, false);
  const Result o = ours(seconds);
  std::printf("1 kHz device stream, loopback round trip (us), %.1f s per run:\n", seconds);
  std::printf("%-34s %8s %9s %9s %9s %9s %6s\n", "", "samples", "p50", "p99", "p99.9", "max", "lost");
  print("raw UDP, sender blocks in recv", pingPong);
  print("raw UDP, stream's thread layout", sameThreads);
  print("DM::Network teleop stream", o);
  std::printf("one-way (synchronized clocks) p50: device->host %.1f us, host->device %.1f us\n", o.oneWayUp,
              o.oneWayDown);
  std::printf("ratio ours/raw (same thread layout): p50 %.2f  p99 %.2f  p99.9 %.2f\n", o.p50 / sameThreads.p50,
              o.p99 / sameThreads.p99, o.p999 / sameThreads.p999);
  std::printf("ratio ours/raw (blocking ping-pong): p50 %.2f  p99 %.2f  p99.9 %.2f\n", o.p50 / pingPong.p50,
              o.p99 / pingPong.p99, o.p999 / pingPong.p999);
  return 0;
}
