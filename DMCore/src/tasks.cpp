#include <dm/core/assert.hpp>
#include <dm/core/tasks.hpp>

#include <tbb/blocked_range.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <atomic>
#include <mutex>
#include <thread>
#include <vector>

namespace dm {

namespace detail {

void parallelForRef(std::size_t begin, std::size_t end, std::size_t grain, RangeFnRef fn) {
  if (begin >= end) return;
  DM_ASSERT(fn.call != nullptr, "parallelFor: empty function");
#if defined(__SANITIZE_THREAD__)
  // oneTBB's scheduler is not built with ThreadSanitizer, which then cannot
  // see the synchronisation inside it and reports TBB's own bookkeeping
  // (task stealing in partitioner.h) as races. Under TSan the same chunks
  // run on std::threads, whose start and join TSan models, so races in the
  // caller's chunk code are still found.
  const std::size_t step = std::max<std::size_t>(grain, 1);
  const std::size_t chunks = (end - begin + step - 1) / step;
  const std::size_t threads = std::min<std::size_t>(chunks, std::max(2u, std::thread::hardware_concurrency()));
  std::atomic<std::size_t> next{0};
  auto work = [&] {
    for (std::size_t c = next.fetch_add(1); c < chunks; c = next.fetch_add(1))
      fn.call(fn.object, begin + c * step, std::min(end, begin + (c + 1) * step));
  };
  std::vector<std::thread> pool;
  for (std::size_t t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
#else
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(begin, end, std::max<std::size_t>(grain, 1)),
      [fn](const tbb::blocked_range<std::size_t>& r) { fn.call(fn.object, r.begin(), r.end()); });
#endif
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
