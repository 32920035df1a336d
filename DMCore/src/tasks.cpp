#include <dm/core/assert.hpp>
#include <dm/core/tasks.hpp>

#include <tbb/blocked_range.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <mutex>

namespace dm {

namespace detail {

void parallelForRef(std::size_t begin, std::size_t end, std::size_t grain, RangeFnRef fn) {
  if (begin >= end) return;
  DM_ASSERT(fn.call != nullptr, "parallelFor: empty function");
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(begin, end, std::max<std::size_t>(grain, 1)),
      [fn](const tbb::blocked_range<std::size_t>& r) { fn.call(fn.object, r.begin(), r.end()); });
}

}  // namespace detail

struct TaskPool::Impl {
  // One slot is kept for the thread that calls wait() (as TBB's default
  // arena does), except in a one-thread pool: there the single slot goes to
  // a worker, so submitted tasks run even if nobody calls wait().
  // oneTBB may still let an external thread that calls wait() join an arena
  // whose one slot a worker holds, so a one-thread pool also serialises its
  // tasks with a lock (recursive: a task that waits on its own pool may run
  // another of its tasks on the same thread, which is still one at a time).
  explicit Impl(int concurrency) : arena(concurrency, concurrency > 1 ? 1u : 0u), serial(concurrency == 1) {}

  tbb::task_arena arena;
  tbb::task_group group;
  bool serial;
  std::recursive_mutex oneAtATime;
};

namespace {
int resolveConcurrency(int requested) {
  if (requested > 0) return requested;
  return std::max(1, tbb::info::default_concurrency());
}
}  // namespace

TaskPool::TaskPool() : TaskPool(Options{}) {}

TaskPool::TaskPool(const Options& options)
    : impl_(std::make_unique<Impl>(resolveConcurrency(options.max_concurrency))) {}

TaskPool::~TaskPool() {
  // tbb::task_group must be waited for before it is destroyed.
  if (impl_) wait();
}

TaskPool::TaskPool(TaskPool&&) noexcept = default;

TaskPool& TaskPool::operator=(TaskPool&& other) noexcept {
  if (this != &other) {
    if (impl_) wait();
    impl_ = std::move(other.impl_);
  }
  return *this;
}

void TaskPool::enqueue(std::function<void()> task) {
  DM_DEMAND(impl_ != nullptr, "TaskPool: used after move");
  Impl& impl = *impl_;
  if (impl.serial)
    task = [&impl, inner = std::move(task)] {
      std::lock_guard lock(impl.oneAtATime);
      inner();
    };
  impl.arena.execute([&impl, &task] { impl.group.run(std::move(task)); });
}

void TaskPool::wait() {
  DM_DEMAND(impl_ != nullptr, "TaskPool: used after move");
  Impl& impl = *impl_;
  impl.arena.execute([&impl] { impl.group.wait(); });
}

void TaskPool::parallelForRef(std::size_t begin, std::size_t end, std::size_t grain, detail::RangeFnRef fn) {
  DM_DEMAND(impl_ != nullptr, "TaskPool: used after move");
  impl_->arena.execute([&] { detail::parallelForRef(begin, end, grain, fn); });
}

int TaskPool::maxConcurrency() const noexcept { return impl_ ? impl_->arena.max_concurrency() : 0; }

}  // namespace dm
