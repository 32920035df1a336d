// What importer isolation costs per import (dm/io/isolation.hpp): the same
// files read in-process, in a forked child and in the dm-isolate helper
// program, in one process, alternating. Meshes: icospheres of 80 to 327,680
// triangles written as binary STL; a 64³ fog volume written as .vdb. Prints
// the median milliseconds per import in each mode and the helper's and the
// fork's cost over in-process (extra ms, and the ratio).
//
//   io_isolation_bench [REPEATS=30]
#include <dm/core/volume.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/io/vdb.hpp>
#include <dm/math/primitives.hpp>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

double medianMs(int repeats, const std::function<bool()>& once) {
  std::vector<double> ms;
  for (int i = 0; i < repeats; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    if (!once()) {
      std::fprintf(stderr, "io_isolation_bench: an import failed\n");
      std::exit(1);
    }
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::nth_element(ms.begin(), ms.begin() + ms.size() / 2, ms.end());
  return ms[ms.size() / 2];
}

void row(const std::string& what, int repeats, const std::function<bool(dm::Isolation)>& import) {
  double ms[3];
  const dm::Isolation modes[3] = {dm::Isolation::InProcess, dm::Isolation::Fork, dm::Isolation::Helper};
  for (int m = 0; m < 3; ++m) import(modes[m]);  // warm the page cache and the loader
  for (int m = 0; m < 3; ++m) ms[m] = medianMs(repeats, [&] { return import(modes[m]); });
  std::printf("%-34s %9.2f %9.2f %9.2f   %+8.2f (%5.2fx) %+8.2f (%5.2fx)\n", what.c_str(), ms[0], ms[1],
              ms[2], ms[1] - ms[0], ms[1] / ms[0], ms[2] - ms[0], ms[2] / ms[0]);
}

}  // namespace

int main(int argc, char** argv) {
  const int repeats = argc > 1 ? std::max(3, std::atoi(argv[1])) : 30;
  const fs::path dir = fs::temp_directory_path() / ("dm_isolation_bench_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::printf("median ms per import over %d repeats\n", repeats);
  std::printf("%-34s %9s %9s %9s   %16s %16s\n", "file", "in-proc", "fork", "helper", "fork - in-proc",
              "helper - in-proc");
  for (const int levels : {1, 3, 5, 7}) {
    const dm::Mesh sphere = dm::makeIcosphere(0.05, levels);
    const fs::path file = dir / ("sphere" + std::to_string(levels) + ".stl");
    if (auto s = dm::writeMesh(sphere, file); !s) {
      std::fprintf(stderr, "%s\n", s.error().message().c_str());
      return 1;
    }
    row("STL, " + std::to_string(sphere.triangleCount()) + " triangles", repeats, [&](dm::Isolation i) {
      dm::MeshImportOptions o;
      o.isolation = i;
      return static_cast<bool>(dm::readMesh(file, o));
    });
  }
  auto fog = dm::Volume::create({64, 64, 64}, dm::VoxelType::F32, dm::Affine3::Identity());
  if (!fog) return 1;
  for (int i = 0; i < 64 * 64 * 64; ++i) fog->data<float>()[i] = static_cast<float>((i * 7919) % 101) / 100.f;
  const fs::path vdb = dir / "fog.vdb";
  if (auto s = dm::writeVdb(*fog, vdb); !s) {
    std::fprintf(stderr, "%s\n", s.error().message().c_str());
    return 1;
  }
  row("VDB, 64^3 fog", repeats, [&](dm::Isolation i) {
    dm::VdbReadOptions o;
    o.isolation = i;
    return static_cast<bool>(dm::readVdb(vdb, o));
  });
  std::error_code ec;
  fs::remove_all(dir, ec);
  return 0;
}
