// io_thread.cpp — dm::IoThread: one asio::io_context run by one named thread.
#include <dm/core/log.hpp>

#include <pthread.h>

#include <chrono>
#include <future>
#include <system_error>
#include <utility>
#include <vector>

#include "io_thread_impl.hpp"

namespace dm {

void IoThread::Impl::logThrow(const char* what, const char* message) noexcept {
  try {
    dm::log::error("network thread '%s': %s threw: %s (caught; callbacks must not throw)", name.c_str(), what,
                   message);
  } catch (...) {
  }
}

void IoThread::Impl::drain() {
  for (;;) {
    std::function<void()> task;
    {
      std::lock_guard lock(mutex);
      if (stopping.load(std::memory_order_acquire) || tasks.empty()) {
        drainScheduled = false;
        return;
      }
      task = std::move(tasks.front());
      tasks.pop_front();
    }
    guard("a posted task", task);
    tasksRun.fetch_add(1, std::memory_order_relaxed);
  }
}

IoThread::IoThread(std::string name) : impl_(std::make_unique<Impl>(std::move(name))) {}

IoThread::~IoThread() {
  stop();
  DM_DEMAND(impl_->users.load() == 0, "IoThread destroyed while transports still use it; destroy them first");
}

Status IoThread::start() {
  Impl& m = *impl_;
  if (onThread()) return ok();  // running, by definition
  std::lock_guard life(m.lifecycle);
  if (m.running.exchange(true)) return ok();
  m.stopping.store(false, std::memory_order_release);
  m.io.restart();
  {
    std::lock_guard lock(m.mutex);
    if (!m.tasks.empty() && !m.drainScheduled) {
      m.drainScheduled = true;
      asio::post(m.io, [&m] { m.drain(); });
    }
  }
  try {
    m.thread = std::thread([&m] {
      m.threadId.store(std::this_thread::get_id());
      // Keeps run() alive while there is no socket work yet.
      auto guardWork = asio::make_work_guard(m.io);
      for (;;) {
        try {
          m.io.run();
          break;
        } catch (const std::exception& e) {
          // asio only rethrows what a handler threw; keep serving.
          m.tasksThrew.fetch_add(1, std::memory_order_relaxed);
          m.logThrow("a handler", e.what());
          if (m.stopping.load()) break;
        }
      }
      m.threadId.store(std::thread::id{});
    });
  } catch (const std::system_error& e) {
    m.running.store(false);
    return fail(ErrorCode::Internal, std::string("cannot create the network thread: ") + e.what(),
                "IoThread '" + m.name + "'", "check the process's thread limit (ulimit -u)");
  }
  const std::string shortName = m.name.substr(0, 15);  // the kernel's limit
  if (!shortName.empty()) pthread_setname_np(m.thread.native_handle(), shortName.c_str());
  return ok();
}

IoStopReport IoThread::stop() {
  Impl& m = *impl_;
  IoStopReport report;
  if (onThread()) {
    dm::log::error("IoThread '%s': stop() called on the network thread itself; ignored", m.name.c_str());
    return report;
  }
  std::lock_guard life(m.lifecycle);
  if (!m.running.load()) return report;
  m.stopping.store(true, std::memory_order_release);
  m.io.stop();
  if (m.thread.joinable()) m.thread.join();
  std::deque<std::function<void()>> dropped;
  {
    std::lock_guard lock(m.mutex);
    dropped.swap(m.tasks);
    m.drainScheduled = false;
  }
  report.tasksDropped = dropped.size();
  m.tasksDropped.fetch_add(report.tasksDropped, std::memory_order_relaxed);
  if (report.tasksDropped > 0)
    dm::log::warn("IoThread '%s' stopped with %zu queued tasks; they were discarded", m.name.c_str(),
                  report.tasksDropped);
  dropped.clear();  // destroy outside the lock: a task's captures may post
  m.running.store(false);
  return report;
}

bool IoThread::running() const noexcept { return impl_->running.load(); }

bool IoThread::stopRequested() const noexcept { return impl_->stopping.load(std::memory_order_acquire); }

bool IoThread::onThread() const noexcept { return impl_->threadId.load() == std::this_thread::get_id(); }

void IoThread::post(std::function<void()> task) {
  Impl& m = *impl_;
  std::lock_guard lock(m.mutex);
  m.tasks.push_back(std::move(task));
  if (!m.drainScheduled && !m.stopping.load(std::memory_order_acquire)) {
    m.drainScheduled = true;
    asio::post(m.io, [&m] { m.drain(); });
  }
}

void IoThread::runAndWait(const std::function<void()>& task) {
  Impl& m = *impl_;
  if (onThread() || !m.running.load()) {
    m.guard("a task", task);
    return;
  }
  // Whoever claims the task first runs it: the network thread, or this
  // thread if the loop stops before getting to it (a stopped loop keeps its
  // handlers until the next start, and the claim makes that run a no-op).
  auto claimed = std::make_shared<std::atomic<bool>>(false);
  auto done = std::make_shared<std::promise<void>>();
  std::future<void> future = done->get_future();
  asio::post(m.io, [&m, &task, claimed, done] {
    if (claimed->exchange(true)) return;
    m.guard("a task", task);
    done->set_value();
  });
  while (future.wait_for(std::chrono::milliseconds(2)) != std::future_status::ready) {
    if (m.stopping.load() || !m.running.load()) {
      if (!claimed->exchange(true)) {
        m.guard("a task", task);
        return;
      }
      future.wait();  // the network thread is running it; stop() lets it finish
      return;
    }
  }
}

IoThreadStats IoThread::stats() const {
  return {impl_->tasksRun.load(), impl_->tasksDropped.load(), impl_->tasksThrew.load()};
}

const std::string& IoThread::name() const noexcept { return impl_->name; }

std::string describe(const SocketAddress& a) {
  const bool v6 = a.address.find(':') != std::string::npos;
  return (v6 ? "[" + a.address + "]" : a.address) + ":" + std::to_string(a.port);
}

}  // namespace dm
