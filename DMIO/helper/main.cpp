// dm-isolate: the helper program DMIO's readers start to run Assimp and
// OpenVDB apart from the caller's process (dm/io/isolation.hpp,
// DMIO/src/isolate.hpp). It runs one job per start: the reader's own code
// (assimpImportJob, openVdbParseJob) on the request it reads from fd 0,
// writing the result to fd 3, under the caller's deadline and memory
// budget. The check-* jobs let the tests (Tests/DMIO/isolate_test.cpp) and a
// user see that a crash, a hang or an allocation beyond the budget in here
// comes back to the caller as an Error.
#include <dirent.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "../src/isolate.hpp"

namespace {

using dm::detail::ByteReader;
using dm::detail::FdWriter;

// Request: bytes per block, blocks. Allocates and touches them all, then
// answers the number of pages touched (so nothing is optimised away).
void checkAllocate(ByteReader& request, FdWriter& result) {
  const std::uint64_t bytes = request.u64(), blocks = request.u64();
  if (!request.ok()) return;
  std::vector<std::unique_ptr<unsigned char[]>> held;
  std::uint64_t pages = 0;
  for (std::uint64_t b = 0; b < blocks; ++b) {
    held.push_back(std::make_unique<unsigned char[]>(static_cast<std::size_t>(bytes)));
    std::memset(held.back().get(), 1, static_cast<std::size_t>(bytes));
    for (std::uint64_t i = 0; i < bytes; i += 4096) pages += held.back()[i];
  }
  result.u64(pages);
}

// Request: a string, answered as it came.
void checkEcho(ByteReader& request, FdWriter& result) {
  const std::string text = request.str();
  if (request.ok()) result.str(text);
}

void checkCrash(ByteReader&, FdWriter&) { std::raise(SIGSEGV); }

// What an uninstrumented library that writes past its blocks does to the
// heap: the header of a freed block overwritten (without instrumentation),
// then allocations until AddressSanitizer's quarantine recycles the block
// and its allocator's own check fails, with no report. Only meaningful
// under AddressSanitizer (the test that runs it skips otherwise).
__attribute__((no_sanitize("address"))) void overwriteHeader(std::uintptr_t block) {
  volatile unsigned char* header = reinterpret_cast<unsigned char*>(block) - 16;
  for (int i = 0; i < 16; ++i) header[i] = 0xcc;
}
void checkCorruptHeap(ByteReader&, FdWriter& result) {
  char* block = new char[32];
  const auto address = reinterpret_cast<std::uintptr_t>(block);
  delete[] block;
  overwriteHeader(address);
  for (int i = 0; i < 100000; ++i) {
    char* churn = new char[4096];
    churn[0] = 1;
    delete[] churn;
  }
  result.u64(0);
}

// Answers how many threads the helper (this job's parent, which forks every
// job) has: 1, or a fork there would be unsafe.
void checkHelperThreads(ByteReader&, FdWriter& result) {
  const std::string task = "/proc/" + std::to_string(::getppid()) + "/task";
  std::uint64_t n = 0;
  if (DIR* dir = ::opendir(task.c_str())) {
    while (const dirent* e = ::readdir(dir))
      if (e->d_name[0] != '.') ++n;
    ::closedir(dir);
  }
  result.u64(n);
}

void checkHang(ByteReader&, FdWriter&) {
  for (;;) std::this_thread::sleep_for(std::chrono::seconds(1));
}

constexpr dm::detail::HelperJobEntry kJobs[] = {
    {"assimp-import", dm::detail::assimpImportJob},
    {"openvdb-parse", dm::detail::openVdbParseJob, dm::detail::prepareOpenVdb},
    {"check-allocate", checkAllocate},
    {"check-echo", checkEcho},
    {"check-crash", checkCrash},
    {"check-corrupt-heap", checkCorruptHeap},
    {"check-helper-threads", checkHelperThreads},
    {"check-hang", checkHang},
};

}  // namespace

int main(int argc, char** argv) {
  return dm::detail::helperMain(argc, argv, kJobs, sizeof kJobs / sizeof kJobs[0]);
}
