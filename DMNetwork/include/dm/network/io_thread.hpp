// dm/network/io_thread.hpp — the network thread: one event loop on one thread.
//
// Every transport of DM::Network (TcpServer, TcpClient, UdpEndpoint,
// LinkEmulator) runs its socket work and its callbacks on an IoThread: one
// asio event loop driven by one named thread ("a network thread per engine").
// Other threads hand work to it with post(); the transports' send() calls do
// so internally. Callbacks run on this thread and must not block: they hand
// data on (to the haptic loop through dm::SpscRing, see dm/core/ring.hpp) and
// return.
//
// stop() is prompt: it lets the task that is running finish, joins the
// thread and discards the tasks still queued, reporting how many (nothing is
// lost silently). Socket state survives a stop; start() again resumes it.
// asio stays inside the module's sources (pimpl).
//
// @code
//   dm::IoThread net("dm-net");
//   if (auto s = net.start(); !s) return s;
//   net.post([] { dm::log::info("on the network thread"); });
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>

namespace dm {

/// An IP address (numeric "127.0.0.1", "::1", or a host name where a
/// function says it resolves names) and a port in host byte order.
struct SocketAddress {
  std::string address;     ///< numeric IPv4/IPv6 address (or host name where resolved)
  std::uint16_t port = 0;  ///< port; 0 asks for an ephemeral one when binding
};

/// "127.0.0.1:5005", or "[::1]:5005" for IPv6: for messages and logs. O(1).
std::string describe(const SocketAddress& address);

/// What stop() left undone.
struct IoStopReport {
  std::size_t tasksDropped = 0;  ///< posted tasks that never ran and were discarded
};

/// Statistics of an IoThread since construction.
struct IoThreadStats {
  std::uint64_t tasksRun = 0;      ///< posted tasks that ran
  std::uint64_t tasksDropped = 0;  ///< posted tasks discarded by stop()
  std::uint64_t tasksThrew = 0;    ///< tasks or callbacks that threw (logged and swallowed)
};

/// One asio event loop on one named thread. Thread-safe: every member may be
/// called from any thread, except that stop() and the destructor must not be
/// called from the network thread itself (that would join itself; stop()
/// returns an error report of 0 and does nothing then). Transports created on
/// an IoThread must be destroyed before it (checked with DM_DEMAND).
class IoThread {
 public:
  /// `name`: thread name for diagnostics (first 15 characters, see `top -H`).
  /// Nothing runs until start().
  explicit IoThread(std::string name = "dm-net");
  /// Stops the thread (discarding queued tasks) and releases the event loop.
  ~IoThread();
  IoThread(const IoThread&) = delete;
  IoThread& operator=(const IoThread&) = delete;

  /// Starts the thread; ok if it is already running. Fails (Internal) only
  /// when the system refuses a new thread.
  Status start();
  /// Stops promptly: the task or callback running finishes, queued tasks are
  /// discarded and counted, the thread is joined. Idempotent.
  IoStopReport stop();
  /// True between start() and stop().
  bool running() const noexcept;
  /// True when called from the network thread.
  bool onThread() const noexcept;
  /// True once stop() has begun and until the next start(): a long task can
  /// poll it to finish early (stop() waits for the running task).
  bool stopRequested() const noexcept;

  /// Queues `task` to run on the network thread, in posting order. Allocates
  /// and takes a short lock: not for real-time threads. While stopped, tasks
  /// wait for the next start() (or are discarded and counted by stop()).
  void post(std::function<void()> task);

  /// Runs `task` on the network thread and waits for it; runs it inline when
  /// called on the network thread or while the thread is stopped. For
  /// set-up and tear-down, not for data.
  void runAndWait(const std::function<void()>& task);

  IoThreadStats stats() const;
  const std::string& name() const noexcept;

  /// Implementation (the asio context); opaque outside the module.
  struct Impl;
  /// For the module's transports only.
  Impl& impl() noexcept { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
