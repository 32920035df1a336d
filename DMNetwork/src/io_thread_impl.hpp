// io_thread_impl.hpp — private: the asio side of dm::IoThread, shared by the
// module's transport sources (tcp.cpp, udp.cpp, stream_pipe.cpp). Never
// installed; asio never reaches a public header.
#pragma once

#include <dm/network/io_thread.hpp>

#include <asio.hpp>
#include <atomic>
#include <deque>
#include <mutex>
#include <string>
#include <thread>

namespace dm {

struct IoThread::Impl {
  explicit Impl(std::string threadName) : name(std::move(threadName)) {}

  /// Runs a user callback, logging and counting anything it throws (a
  /// throwing callback must not take the network thread down).
  template <class F>
  void guard(const char* what, F&& f) noexcept {
    try {
      f();
    } catch (const std::exception& e) {
      tasksThrew.fetch_add(1, std::memory_order_relaxed);
      logThrow(what, e.what());
    } catch (...) {
      tasksThrew.fetch_add(1, std::memory_order_relaxed);
      logThrow(what, "unknown exception");
    }
  }
  void logThrow(const char* what, const char* message) noexcept;
  void drain();

  std::string name;
  asio::io_context io{1};
  std::thread thread;
  std::atomic<std::thread::id> threadId{};
  std::atomic<bool> running{false};
  std::atomic<bool> stopping{false};
  std::atomic<int> users{0};  ///< transports alive on this thread

  std::mutex lifecycle;  ///< serializes start() and stop()
  std::mutex mutex;      ///< guards tasks and drainScheduled
  std::deque<std::function<void()>> tasks;
  bool drainScheduled = false;

  std::atomic<std::uint64_t> tasksRun{0};
  std::atomic<std::uint64_t> tasksDropped{0};
  std::atomic<std::uint64_t> tasksThrew{0};
};

/// Registration of a transport with its IoThread, so that destroying the
/// IoThread first is caught (DM_DEMAND in ~IoThread). Released by the
/// transport's close() (its implementation object may outlive it inside
/// queued handlers) or at destruction, whichever comes first.
class IoUser {
 public:
  explicit IoUser(IoThread& t) : thread_(&t) { t.impl().users.fetch_add(1, std::memory_order_relaxed); }
  ~IoUser() { release(); }
  void release() noexcept {
    if (!released_.exchange(true)) thread_->impl().users.fetch_sub(1, std::memory_order_relaxed);
  }
  IoUser(const IoUser&) = delete;
  IoUser& operator=(const IoUser&) = delete;
  IoThread& thread() const noexcept { return *thread_; }
  asio::io_context& io() const noexcept { return thread_->impl().io; }

 private:
  IoThread* thread_;
  std::atomic<bool> released_{false};
};

/// Parses a numeric IPv4/IPv6 address; `field` names the option for the
/// error message.
inline Result<asio::ip::address> parseAddress(const std::string& text, const std::string& field) {
  std::error_code ec;
  asio::ip::address a = asio::ip::make_address(text, ec);
  if (ec)
    return fail(ErrorCode::InvalidArgument, "'" + text + "' is not a numeric IP address", field,
                "write it as 127.0.0.1, 0.0.0.0, ::1 or ::");
  return a;
}

/// The address of `a` as text, IPv4-mapped IPv6 addresses as plain IPv4.
inline SocketAddress toSocketAddress(const asio::ip::address& a, std::uint16_t port) {
  if (a.is_v6() && a.to_v6().is_v4_mapped())
    return {asio::ip::make_address_v4(asio::ip::v4_mapped, a.to_v6()).to_string(), port};
  return {a.to_string(), port};
}

/// "address:port" ("[::1]:80" for IPv6), for messages.
}  // namespace dm
