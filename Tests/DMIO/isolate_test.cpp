// The forked-child isolation behind the Assimp and OpenVDB readers
// (DMIO/src/isolate.hpp, private to DMIO): results come back through the
// pipe, and a crash, a timeout or an allocation beyond the memory budget in
// the child becomes an Error in the parent — in plain builds (RLIMIT_AS) and
// under the sanitizers (allocator hooks) alike.
#include "../../DMIO/src/isolate.hpp"

#include <gtest/gtest.h>

#include <csignal>
#include <cstring>
#include <memory>
#include <thread>
#include <vector>

namespace {

using dm::detail::FdWriter;
using dm::detail::IsolateOptions;
using dm::detail::runIsolated;

IsolateOptions options(std::size_t budget, double timeout = 20.0) {
  IsolateOptions o;
  o.library = "TestLib";
  o.timeoutSeconds = timeout;
  o.memoryBudget = budget;
  o.budgetHint = "budget hint";
  o.crashHint = "crash hint";
  o.timeoutHint = "timeout hint";
  return o;
}

// Allocates and touches `bytes` in the child, then reports the sum of what it
// wrote so the allocation cannot be optimised away.
void allocateAndReport(FdWriter& w, std::size_t bytes) {
  auto block = std::make_unique<unsigned char[]>(bytes);
  std::memset(block.get(), 1, bytes);
  std::uint64_t sum = 0;
  for (std::size_t i = 0; i < bytes; i += 4096) sum += block[i];
  w.u64(sum);
}

TEST(Isolate, ResultComesBackWithinBudget) {
  constexpr std::size_t kBytes = std::size_t{8} << 20;
  auto run = runIsolated([](FdWriter& w) { allocateAndReport(w, kBytes); }, options(std::size_t{256} << 20),
                         "test.bin");
  ASSERT_TRUE(run) << run.error();
  dm::detail::ByteReader r(run->bytes);
  EXPECT_EQ(r.u64(), kBytes / 4096);
  EXPECT_TRUE(r.ok());
  EXPECT_EQ(run->exitInfo, "exit status 0");
}

TEST(Isolate, AllocationBeyondBudgetIsAnError) {
  auto run = runIsolated([](FdWriter& w) { allocateAndReport(w, std::size_t{512} << 20); },
                         options(std::size_t{64} << 20), "test.bin");
  ASSERT_FALSE(run);
  EXPECT_EQ(run.error().code, dm::ErrorCode::Unsupported);
  const std::string msg = run.error().message();
  EXPECT_NE(msg.find("test.bin"), std::string::npos) << msg;
  EXPECT_NE(msg.find("TestLib needed more than its memory budget of 64 MiB"), std::string::npos) << msg;
  EXPECT_NE(msg.find("budget hint"), std::string::npos) << msg;
}

// A request far beyond any machine (a file header's element count times the
// element size): the allocator refuses it before anything is allocated — in
// plain builds through RLIMIT_AS and the new-handler, under AddressSanitizer
// through its own report — and either way it is "over budget", not a crash.
TEST(Isolate, AllocationNoMachineCanServeIsOverBudget) {
  for (const std::size_t bytes : {std::size_t{1} << 37, std::size_t{1} << 46}) {
    auto run = runIsolated([bytes](FdWriter& w) { allocateAndReport(w, bytes); },
                           options(std::size_t{64} << 20), "test.bin");
    ASSERT_FALSE(run) << bytes;
    EXPECT_EQ(run.error().code, dm::ErrorCode::Unsupported) << bytes << ": " << run.error();
    EXPECT_NE(run.error().message().find("needed more than its memory budget"), std::string::npos)
        << run.error();
  }
}

TEST(Isolate, ManySmallAllocationsCountAgainstTheBudget) {
  auto run = runIsolated(
      [](FdWriter& w) {
        std::vector<std::unique_ptr<char[]>> blocks;
        for (int i = 0; i < 4096; ++i) {  // 4096 × 64 KiB = 256 MiB in all
          blocks.push_back(std::make_unique<char[]>(64 << 10));
          std::memset(blocks.back().get(), 1, 64 << 10);
        }
        w.u64(blocks.size());
      },
      options(std::size_t{64} << 20), "test.bin");
  ASSERT_FALSE(run);
  EXPECT_EQ(run.error().code, dm::ErrorCode::Unsupported) << run.error();
}

TEST(Isolate, CrashIsAParseError) {
  auto run = runIsolated([](FdWriter&) { std::raise(SIGSEGV); }, options(0), "test.bin");
  ASSERT_FALSE(run);
  EXPECT_EQ(run.error().code, dm::ErrorCode::Parse);
  EXPECT_NE(run.error().message().find("TestLib crashed while reading the file"), std::string::npos)
      << run.error();
}

TEST(Isolate, DeadlineEndsTheChild) {
  auto run = runIsolated([](FdWriter&) { std::this_thread::sleep_for(std::chrono::seconds(30)); },
                         options(0, 0.3), "test.bin");
  ASSERT_FALSE(run);
  EXPECT_EQ(run.error().code, dm::ErrorCode::Timeout);
  EXPECT_NE(run.error().message().find("timeout hint"), std::string::npos) << run.error();
}

}  // namespace
