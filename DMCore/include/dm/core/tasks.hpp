// dm/core/tasks.hpp — task parallelism on oneTBB, without TBB in the API.
//
// dm::parallelFor splits an index range into chunks and runs them on the
// oneTBB worker threads; dm::TaskPool is an isolated pool (its own
// tbb::task_arena, optionally with fewer threads) to which independent jobs
// are submitted. Neither is for real-time threads: they allocate and block.
// Physics, collision pre-passes and asset loading use them; the haptic loop
// does not. Under ThreadSanitizer (whose view stops at oneTBB's
// uninstrumented scheduler) parallelFor runs its chunks on std::threads
// instead, so the concurrency tests still check the callers' chunk code.
//
// @code
//   dm::parallelFor(0, n, 1024, [&](std::size_t b, std::size_t e) {
//     for (std::size_t i = b; i < e; ++i) out[i] = f(in[i]);
//   });
// @endcode
#pragma once

#include <cstddef>
#include <functional>
#include <future>
#include <memory>
#include <type_traits>
#include <utility>

namespace dm {

namespace detail {
/// Non-owning, non-allocating reference to a callable void(size_t, size_t).
struct RangeFnRef {
  void* object = nullptr;
  void (*call)(void* object, std::size_t begin, std::size_t end) = nullptr;

  template <class F>
  static RangeFnRef to(F& fn) noexcept {
    return RangeFnRef{static_cast<void*>(std::addressof(fn)),
                      [](void* o, std::size_t b, std::size_t e) { (*static_cast<F*>(o))(b, e); }};
  }
};
/// parallelFor on the calling thread's current task arena.
void parallelForRef(std::size_t begin, std::size_t end, std::size_t grain, RangeFnRef fn);
}  // namespace detail

/// Calls fn(b, e) on disjoint chunks [b, e) that together cover
/// [begin, end), concurrently on the oneTBB worker threads, and returns when
/// all are done. Chunks hold about `grain` indices or more (grain 0 is
/// taken as 1); the split is not deterministic, so fn must write disjoint
/// outputs (then the result equals the serial loop's). Nothing happens when
/// begin >= end. The first exception thrown by fn is rethrown here after
/// the other chunks stop. Called from inside a TaskPool task, it runs in
/// that pool.
///
/// @code
///   std::vector<double> y(n);
///   dm::parallelFor(0, n, 256, [&](std::size_t b, std::size_t e) { for (auto i = b; i < e; ++i) y[i] = 2 *
///   x[i]; });
/// @endcode
template <class F>
void parallelFor(std::size_t begin, std::size_t end, std::size_t grain, F&& fn) {
  detail::parallelForRef(begin, end, grain, detail::RangeFnRef::to(fn));
}

/// A pool of worker threads with its own concurrency limit (pimpl over a
/// tbb::task_arena and tbb::task_group). submit() and parallelFor() may be
/// called from any thread; wait() from one thread at a time.
///
/// @code
///   dm::TaskPool pool({.max_concurrency = 2});
///   std::future<int> answer = pool.submit([] { return 6 * 7; });
///   pool.wait();  // answer.get() == 42
/// @endcode
class TaskPool {
 public:
  struct Options {
    /// Most threads running this pool's tasks at once; <= 0 means one per
    /// hardware thread. The workers come from oneTBB's global pool, whose
    /// size is the number of hardware threads.
    int max_concurrency = 0;
  };

  /// A pool with one thread per hardware thread.
  TaskPool();
  explicit TaskPool(const Options& options);
  /// Waits for every submitted task, then releases the arena.
  ~TaskPool();
  TaskPool(TaskPool&&) noexcept;
  TaskPool& operator=(TaskPool&&) noexcept;
  TaskPool(const TaskPool&) = delete;
  TaskPool& operator=(const TaskPool&) = delete;

  /// Runs fn() on a pool thread and returns a future for its result (an
  /// exception thrown by fn is stored in the future). Allocates. Do not
  /// block on the future from inside a task of this pool (it may need the
  /// very thread that is waiting); call wait() or future.get() from outside.
  template <class F>
  auto submit(F&& fn) -> std::future<std::invoke_result_t<std::decay_t<F>&>> {
    using R = std::invoke_result_t<std::decay_t<F>&>;
    auto task = std::make_shared<std::packaged_task<R()>>(std::forward<F>(fn));
    std::future<R> result = task->get_future();
    enqueue([task] { (*task)(); });
    return result;
  }

  /// Blocks until every task submitted so far (and every task they submit)
  /// has finished; the calling thread helps run them.
  void wait();

  /// dm::parallelFor, run on this pool's threads.
  template <class F>
  void parallelFor(std::size_t begin, std::size_t end, std::size_t grain, F&& fn) {
    parallelForRef(begin, end, grain, detail::RangeFnRef::to(fn));
  }

  /// The concurrency limit in effect (>= 1).
  int maxConcurrency() const noexcept;

 private:
  void enqueue(std::function<void()> task);
  void parallelForRef(std::size_t begin, std::size_t end, std::size_t grain, detail::RangeFnRef fn);

  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
