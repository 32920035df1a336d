// Real-time memory: the stack pre-faulted before the first tick, the
// process's pages locked (or the reason it cannot be), faults counted.
#include <dm/core/rt_memory.hpp>

#include <gtest/gtest.h>

#include <pthread.h>
#include <sys/mman.h>

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <memory>
#include <string>

namespace {

#if defined(__SANITIZE_ADDRESS__)
constexpr std::uint64_t kShadowPages = 32;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
constexpr std::uint64_t kShadowPages = 32;
#else
constexpr std::uint64_t kShadowPages = 0;
#endif
#else
constexpr std::uint64_t kShadowPages = 0;
#endif

// /proc/self/status's VmLck, the bytes locked in RAM.
std::size_t lockedBytes() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmLck:", 0) == 0) return std::strtoull(line.c_str() + 6, nullptr, 10) * 1024;
  return 0;
}

struct StackFaults {
  dm::PageFaults before, afterFirst, afterSecond;
};

void* touchTwice(void* arg) {
  auto* f = static_cast<StackFaults*>(arg);
  f->before = dm::readThreadPageFaults();
  dm::prefaultStack(512 * 1024);
  f->afterFirst = dm::readThreadPageFaults();
  dm::prefaultStack(512 * 1024);
  f->afterSecond = dm::readThreadPageFaults();
  return nullptr;
}

}  // namespace

// A thread on a stack no one has touched (a fresh mapping, no huge pages):
// pre-faulting 512 KiB maps its 128 pages, one minor fault each, and doing
// it again finds them mapped.
TEST(RtMemory, PrefaultStackMapsTheStackPagesOnce) {
  constexpr std::size_t kStack = 4 * 1024 * 1024;
  void* stack =
      mmap(nullptr, kStack, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
  ASSERT_NE(stack, MAP_FAILED);
  madvise(stack, kStack, MADV_NOHUGEPAGE);
  pthread_attr_t attr;
  pthread_attr_init(&attr);
  ASSERT_EQ(pthread_attr_setstack(&attr, stack, kStack), 0);
  StackFaults f;
  pthread_t thread;
  ASSERT_EQ(pthread_create(&thread, &attr, touchTwice, &f), 0);
  pthread_join(thread, nullptr);
  pthread_attr_destroy(&attr);
  munmap(stack, kStack);

  const std::uint64_t first = f.afterFirst.minor - f.before.minor;
  const std::uint64_t second = f.afterSecond.minor - f.afterFirst.minor;
  EXPECT_GE(first, 120u) << "512 KiB of untouched stack is 128 pages";
  // AddressSanitizer also maps the shadow of the stack frame it poisons:
  // at most an eighth of prefaultStack's 1 MiB frame, 32 pages (measured:
  // 144 = 128 + 16).
  EXPECT_LE(first, 128u + kShadowPages + 12u);
  EXPECT_LE(second, 2u) << "the pages were mapped by the first call";
  EXPECT_EQ(f.afterSecond.major, f.before.major);
}

// Locked: what the process has is counted in VmLck, and so is memory it maps
// and touches afterwards (MCL_FUTURE); unlocked by its last holder, nothing
// is. Where it may not lock, the error says which limit or capability is
// missing.
TEST(RtMemory, LockProcessMemoryLocksLaterPagesTooOrSaysWhy) {
  ASSERT_FALSE(dm::processMemoryLocked());
  const dm::Status s = dm::lockProcessMemory();
  if (!s) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__) || \
    (defined(__has_feature) && (__has_feature(address_sanitizer) || __has_feature(thread_sanitizer)))
    EXPECT_EQ(s.error().code, dm::ErrorCode::Unsupported) << s.error();  // GCC's macros, clang's features
#else
    EXPECT_EQ(s.error().code, dm::ErrorCode::Denied) << s.error();
    EXPECT_NE(s.error().message().find("RLIMIT_MEMLOCK"), std::string::npos) << s.error();
    EXPECT_FALSE(s.error().hint.empty());
#endif
    EXPECT_FALSE(dm::processMemoryLocked());
    EXPECT_EQ(lockedBytes(), 0u);
    return;
  }
  EXPECT_TRUE(dm::processMemoryLocked());
  const std::size_t locked = lockedBytes();
  EXPECT_GT(locked, 0u);

  constexpr std::size_t kLater = 8 * 1024 * 1024;
  void* later = mmap(nullptr, kLater, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  ASSERT_NE(later, MAP_FAILED);
  std::memset(later, 1, kLater);
  EXPECT_GE(lockedBytes(), locked + kLater) << "a mapping made after the lock is locked once touched";
  munmap(later, kLater);

  // Counted: a second holder keeps the lock when the first lets go.
  ASSERT_TRUE(dm::lockProcessMemory());
  dm::unlockProcessMemory();
  EXPECT_TRUE(dm::processMemoryLocked());
  EXPECT_GT(lockedBytes(), 0u);
  dm::unlockProcessMemory();
  EXPECT_FALSE(dm::processMemoryLocked());
  EXPECT_EQ(lockedBytes(), 0u);
  dm::unlockProcessMemory();  // none held: a no-op
  EXPECT_EQ(lockedBytes(), 0u);
}

// Touching 4 MiB just allocated (a fresh mapping) faults its pages in.
TEST(RtMemory, TouchingNewMemoryIsCountedAsMinorFaults) {
  const dm::PageFaults a = dm::readPageFaults();
  auto block = std::make_unique<char[]>(4 * 1024 * 1024);
  std::memset(block.get(), 1, 4 * 1024 * 1024);
  const dm::PageFaults b = dm::readPageFaults();
  EXPECT_GT(b.minor, a.minor);
  EXPECT_GE(b.major, a.major);
}
