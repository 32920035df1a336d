// libFuzzer target: OpenVDB stream parsing from memory (dm::parseVdb).
// Any input must give a Volume or a dm::Error, never a crash, hang or large
// allocation in this process: OpenVDB itself runs in a forked child
// (Isolation::Fork here; applications get the dm-isolate helper, which runs
// the same parse), whose crash or out-of-memory death must come back as an
// Error. Such a child still runs libFuzzer's hooks, so it leaves crash-/oom-
// files in the artifact folder; only this process's exit status counts.
// (In CI's 30 s the children hit 4 GiB allocations from length fields and an
// allocation-size-too-big inside OpenVDB; every one came back as an Error.) A
// parsed volume must also survive writeVdb -> readVdb with identical dims and
// voxels (the writer's contract).
// A fork is safe only while no other thread can hold a lock, but OpenVDB
// runs oneTBB tasks in-process (writing a grid evaluates its bounding box in
// parallel), whose workers then outlive the call; a fork taken while one
// held the allocator's lock left the child stuck until its deadline, and CI
// once aborted on a read-back that timed out so. LLVMFuzzerInitialize caps
// oneTBB at this one thread. The written file is ours, so it is read back
// in-process, as trusted files are. maxBytes is small (2M float voxels) so a
// crafted dense box costs seconds, not a minute (a 10 kB file asking for 256³
// took 38 s under ASan).
#include <dm/io/vdb.hpp>

#include <oneapi/tbb/global_control.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <span>
#include <string>

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  static oneapi::tbb::global_control oneThread(oneapi::tbb::global_control::max_allowed_parallelism, 1);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  dm::VdbReadOptions options;
  options.maxBytes = std::size_t{8} << 20;
  // A forked child: about ten times the executions a second of the helper
  // program, and safe here: oneTBB runs no worker threads, and libFuzzer's
  // only other thread (its RSS monitor) wakes once a second to read /proc.
  options.isolation = dm::Isolation::Fork;
  options.timeoutSeconds = 10;
  auto v = dm::parseVdb(bytes, "<fuzz>", options);
  if (!v) {
    if (v.error().what.empty()) std::abort();  // every error says what failed
    return 0;
  }
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("dm_vdb_fuzz_" + std::to_string(::getpid()) + ".vdb");
  if (!dm::writeVdb(*v, file)) return 0;  // e.g. an unwritable temp dir
  dm::VdbReadOptions trusted = options;
  trusted.isolation = dm::Isolation::InProcess;
  auto back = dm::readVdb(file, trusted);
  std::error_code ec;
  std::filesystem::remove(file, ec);
  if (!back) {
    std::fprintf(stderr, "vdb_fuzz: the written volume did not read back: %s\n",
                 back.error().message().c_str());
    std::abort();
  }
  if (back->dims() != v->dims() || back->type() != v->type()) {
    std::fprintf(stderr, "vdb_fuzz: the written volume read back with other dims or type\n");
    std::abort();
  }
  for (std::size_t n = 0; n < v->voxelCount(); ++n) {
    const double a = v->valueAt(n), b = back->valueAt(n);
    if (a != b && !(a != a && b != b)) {  // equal, or both NaN
      std::fprintf(stderr, "vdb_fuzz: voxel %zu wrote %g and read back %g\n", n, a, b);
      std::abort();
    }
  }
  return 0;
}
