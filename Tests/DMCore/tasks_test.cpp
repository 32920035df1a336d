#include <dm/core/tasks.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <future>
#include <numeric>
#include <stdexcept>
#include <vector>

namespace {

double f(std::size_t i) { return std::sin(0.001 * static_cast<double>(i)) * static_cast<double>(i % 97); }

TEST(ParallelFor, EqualsSerialLoopForEveryGrain) {
  const std::size_t n = 100'003;  // not a multiple of any grain
  std::vector<double> serial(n);
  for (std::size_t i = 0; i < n; ++i) serial[i] = f(i);
  for (std::size_t grain : {std::size_t{0}, std::size_t{1}, std::size_t{7}, std::size_t{1024}, n, 2 * n}) {
    std::vector<double> parallel(n, -1.0);
    dm::parallelFor(0, n, grain, [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) parallel[i] = f(i);
    });
    EXPECT_EQ(parallel, serial) << "grain " << grain;
  }
}

TEST(ParallelFor, ChunksCoverTheRangeExactlyOnce) {
  const std::size_t begin = 10, end = 50'010;
  std::vector<std::atomic<int>> hits(end);
  dm::parallelFor(begin, end, 100, [&](std::size_t b, std::size_t e) {
    ASSERT_LT(b, e);
    for (std::size_t i = b; i < e; ++i) hits[i].fetch_add(1);
  });
  for (std::size_t i = 0; i < end; ++i) ASSERT_EQ(hits[i].load(), i >= begin ? 1 : 0) << i;
}

TEST(ParallelFor, EmptyOrReversedRangeDoesNothing) {
  int calls = 0;
  dm::parallelFor(5, 5, 1, [&](std::size_t, std::size_t) { ++calls; });
  dm::parallelFor(9, 3, 1, [&](std::size_t, std::size_t) { ++calls; });
  EXPECT_EQ(calls, 0);
}

TEST(ParallelFor, ExceptionsReachTheCaller) {
  EXPECT_THROW(dm::parallelFor(0, 1000, 10,
                               [](std::size_t b, std::size_t e) {
                                 if (b <= 500 && 500 < e) throw std::runtime_error("chunk with 500");
                               }),
               std::runtime_error);
}

TEST(TaskPool, ManyTasksAllComplete) {
  dm::TaskPool pool;
  EXPECT_GE(pool.maxConcurrency(), 1);
  std::atomic<int> done{0};
  constexpr int kTasks = 5000;
  for (int i = 0; i < kTasks; ++i)
    (void)pool.submit([&done] { done.fetch_add(1, std::memory_order_relaxed); });
  pool.wait();
  EXPECT_EQ(done.load(), kTasks);
}

TEST(TaskPool, FuturesCarryResultsAndExceptions) {
  dm::TaskPool pool({.max_concurrency = 2});
  std::vector<std::future<std::int64_t>> squares;
  for (std::int64_t i = 0; i < 200; ++i) squares.push_back(pool.submit([i] { return i * i; }));
  auto boom = pool.submit([]() -> int { throw std::invalid_argument("bad"); });
  pool.wait();
  std::int64_t sum = 0;
  for (auto& s : squares) sum += s.get();
  EXPECT_EQ(sum, 199 * 200 * 399 / 6);  // sum of i^2 for i < 200
  EXPECT_THROW(boom.get(), std::invalid_argument);
}

TEST(TaskPool, FutureCompletesWithoutCallingWait) {
  dm::TaskPool pool({.max_concurrency = 1});
  auto answer = pool.submit([] { return 42; });
  EXPECT_EQ(answer.get(), 42);
}

TEST(TaskPool, RespectsMaxConcurrencyOfOne) {
  dm::TaskPool pool({.max_concurrency = 1});
  EXPECT_EQ(pool.maxConcurrency(), 1);
  std::atomic<int> inside{0}, peak{0};
  for (int i = 0; i < 200; ++i)
    (void)pool.submit([&] {
      const int now = inside.fetch_add(1) + 1;
      int p = peak.load();
      while (now > p && !peak.compare_exchange_weak(p, now)) {
      }
      volatile double x = 0;
      for (int k = 0; k < 1000; ++k) x = x + k;
      inside.fetch_sub(1);
    });
  pool.wait();
  EXPECT_EQ(peak.load(), 1);
}

TEST(TaskPool, ParallelForInsidePoolEqualsSerial) {
  dm::TaskPool pool({.max_concurrency = 2});
  constexpr std::size_t n = 20'000;
  std::vector<double> out(n);
  pool.parallelFor(0, n, 64, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) out[i] = f(i);
  });
  for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(out[i], f(i));
  // Nested: tasks that themselves run parallel loops.
  std::vector<std::future<double>> sums;
  for (int t = 0; t < 4; ++t)
    sums.push_back(pool.submit([] {
      std::vector<double> part(n);
      dm::parallelFor(0, n, 256, [&](std::size_t b, std::size_t e) {
        for (std::size_t i = b; i < e; ++i) part[i] = f(i);
      });
      return std::accumulate(part.begin(), part.end(), 0.0);
    }));
  pool.wait();
  double serial = 0.0;
  for (std::size_t i = 0; i < n; ++i) serial += f(i);
  for (auto& s : sums) EXPECT_EQ(s.get(), serial);
}

TEST(TaskPool, DestructorWaitsForTasks) {
  std::atomic<int> done{0};
  {
    dm::TaskPool pool({.max_concurrency = 2});
    for (int i = 0; i < 100; ++i) (void)pool.submit([&done] { done.fetch_add(1); });
  }
  EXPECT_EQ(done.load(), 100);
}

TEST(TaskPool, MovedPoolKeepsWorking) {
  dm::TaskPool a({.max_concurrency = 2});
  dm::TaskPool b(std::move(a));
  auto r = b.submit([] { return 7; });
  b.wait();
  EXPECT_EQ(r.get(), 7);
}

}  // namespace
