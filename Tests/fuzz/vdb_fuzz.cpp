// libFuzzer target: OpenVDB stream parsing from memory (dm::parseVdb).
// Any input must give a Volume or a dm::Error, never a crash, hang or large
// allocation in this process: OpenVDB itself runs in the isolated child that
// parseVdb() forks with VdbReadOptions::isolate, whose crash or out-of-memory death must come back as an
// Error. Such a child still runs libFuzzer's hooks, so it leaves crash-/oom-
// files in the artifact folder; only this process's exit status counts.
// (In CI's 30 s the children hit 4 GiB allocations from length fields and an
// allocation-size-too-big inside OpenVDB; every one came back as an Error.) A parsed volume must also survive
// writeVdb -> readVdb with identical dims and voxels (the writer's contract).
#include <dm/io/vdb.hpp>

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <span>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  dm::VdbReadOptions options;
  options.maxBytes = std::size_t{64} << 20;
  options.isolate = true;  // the fuzzer runs no worker threads, so forking is safe
  options.timeoutSeconds = 10;
  auto v = dm::parseVdb(bytes, "<fuzz>", options);
  if (!v) {
    if (v.error().what.empty()) std::abort();  // every error says what failed
    return 0;
  }
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("dm_vdb_fuzz_" + std::to_string(::getpid()) + ".vdb");
  if (!dm::writeVdb(*v, file)) return 0;  // e.g. an unwritable temp dir
  auto back = dm::readVdb(file, options);
  std::error_code ec;
  std::filesystem::remove(file, ec);
  if (!back || back->dims() != v->dims() || back->type() != v->type()) std::abort();
  for (std::size_t n = 0; n < v->voxelCount(); ++n) {
    const double a = v->valueAt(n), b = back->valueAt(n);
    if (a != b && !(a != a && b != b)) std::abort();  // equal, or both NaN
  }
  return 0;
}
