#include <dm/core/host_cpu.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <string>
#include <thread>

namespace {

// A /proc/stat of a 2-CPU machine, 100 ticks per second.
constexpr const char* kStat =
    "cpu  3815415 563 513004 755784 7186 0 2709 18968 0 0\n"
    "cpu0 1906646 259 246456 423846 2704 0 712 9832 0 0\n"
    "cpu1 1908769 304 266548 331938 4482 0 1997 9136 0 0\n"
    "intr 123 4 5\n"
    "ctxt 99\n";

TEST(HostCpu, ParsesTheAggregateLineInSeconds) {
  auto t = dm::parseProcStat(kStat, 100.0);
  ASSERT_TRUE(t) << t.error().message();
  EXPECT_EQ(t->cpus, 2);
  EXPECT_DOUBLE_EQ(t->busy_s, (3815415 + 563 + 513004 + 0 + 2709) / 100.0);
  EXPECT_DOUBLE_EQ(t->idle_s, (755784 + 7186) / 100.0);
  EXPECT_DOUBLE_EQ(t->steal_s, 189.68);
}

TEST(HostCpu, OldKernelsWithoutStealReadZero) {
  auto t = dm::parseProcStat("cpu 10 0 5 100\ncpu0 10 0 5 100\n", 100.0);
  ASSERT_TRUE(t) << t.error().message();
  EXPECT_EQ(t->steal_s, 0.0);
  EXPECT_DOUBLE_EQ(t->busy_s, 0.15);
  EXPECT_EQ(t->cpus, 1);
}

TEST(HostCpu, BadTextNamesTheLineAndField) {
  auto noCpu = dm::parseProcStat("intr 1 2\n", 100.0);
  ASSERT_FALSE(noCpu);
  EXPECT_NE(noCpu.error().what.find("aggregate"), std::string::npos);

  auto bad = dm::parseProcStat("intr 1\ncpu 1 2 x3 4\n", 100.0);
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().code, dm::ErrorCode::Parse);
  EXPECT_NE(bad.error().where.find("line 2"), std::string::npos) << bad.error().message();
  EXPECT_NE(bad.error().what.find("field 3"), std::string::npos) << bad.error().message();

  auto negative = dm::parseProcStat("cpu 1 -2 3 4\n", 100.0);
  ASSERT_FALSE(negative);
  EXPECT_NE(negative.error().what.find("field 2"), std::string::npos);

  auto shortLine = dm::parseProcStat("cpu 1 2 3\n", 100.0);
  ASSERT_FALSE(shortLine);
  EXPECT_NE(shortLine.error().what.find("3 fields"), std::string::npos);

  EXPECT_FALSE(dm::parseProcStat(kStat, 0.0));
}

#ifdef __linux__
// The live accounts only grow, and a busy thread shows up as busy time.
TEST(HostCpu, LiveAccountsGrowWithWork) {
  auto a = dm::readHostCpuTimes();
  ASSERT_TRUE(a) << a.error().message();
  EXPECT_GE(a->cpus, 1);
  const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(300);
  volatile unsigned long spin = 0;
  while (std::chrono::steady_clock::now() < end) spin = spin + 1;
  auto b = dm::readHostCpuTimes();
  ASSERT_TRUE(b) << b.error().message();
  EXPECT_GE(b->steal_s, a->steal_s);
  EXPECT_GE(b->idle_s, a->idle_s);
  EXPECT_GE(b->busy_s - a->busy_s, 0.1);  // 0.3 s of spinning, USER_HZ granularity
}
#endif

TEST(HostCpu, SimdLevelsParseByNameAndNothingElse) {
  for (dm::SimdLevel level : {dm::SimdLevel::Sse2, dm::SimdLevel::Avx2, dm::SimdLevel::Avx512}) {
    auto parsed = dm::parseSimdLevel(dm::toString(level));
    ASSERT_TRUE(parsed) << parsed.error().message();
    EXPECT_EQ(*parsed, level);
  }
  for (const char* bad : {"", "AVX2", "avx", "avx512f", "sse2 "}) {
    auto parsed = dm::parseSimdLevel(bad);
    ASSERT_FALSE(parsed) << bad;
    EXPECT_EQ(parsed.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(parsed.error().message().find('"' + std::string(bad) + '"'), std::string::npos)
        << parsed.error().message();
    EXPECT_NE(parsed.error().message().find("DM_SIMD"), std::string::npos) << parsed.error().message();
  }
}

// The level never exceeds what the CPU runs (or, where DM_SIMD caps it, the cap).
TEST(HostCpu, SimdLevelIsWhatTheCpuRunsUnderTheCap) {
  const dm::SimdLevel level = dm::simdLevel();
  EXPECT_EQ(dm::simdLevel(), level);  // decided once
#if defined(__GNUC__) && defined(__x86_64__)
  __builtin_cpu_init();
  if (level == dm::SimdLevel::Avx512) {
    // x86-64-v4, spelled out: clang 14 knows no level names here.
    EXPECT_TRUE(__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
                __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx512dq") &&
                __builtin_cpu_supports("avx512vl"));
  }
  if (level == dm::SimdLevel::Avx2) {
    EXPECT_TRUE(__builtin_cpu_supports("avx2"));
  }
#endif
  if (const char* cap = std::getenv("DM_SIMD")) {
    if (auto parsed = dm::parseSimdLevel(cap)) {
      EXPECT_LE(int(level), int(*parsed));
    }
  }
}

}  // namespace
