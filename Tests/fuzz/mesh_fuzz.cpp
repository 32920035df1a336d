// libFuzzer target: mesh import from memory (dm::parseMesh, through Assimp)
// and our writers. The first byte picks the format hint; the rest is the
// file. Any input must give a valid, non-empty Mesh or a dm::Error naming
// the "<memory>.<hint>" source; a parsed mesh must encode in every format we
// write, and the encoded bytes must parse again without crashing (their
// triangle count may differ: Assimp reads float32, which can collapse
// triangles that were distinct in double).
//
// Only our code is instrumented; Assimp is the system library. Assimp runs
// isolated in a forked child (Isolation::Fork: several times the executions
// a second of the default helper program, and safe here, where libFuzzer's
// only other thread, its RSS monitor, wakes once a second to read /proc), so
// its own hangs and crashes on broken input come back as Timeout/Parse
// errors rather than stopping the fuzzer; a sanitizer report from our code
// in the child makes it exit without a result, which parseMesh reports as
// ErrorCode::Internal — and that aborts here. The helper runs the same
// loadWithAssimp() (Tests/DMIO/isolate_test.cpp checks the way there).
#include <dm/core/log.hpp>
#include <dm/io/mesh_io.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <iterator>
#include <span>
#include <string>

namespace {

constexpr const char* kFormats[] = {"stl", "ply", "obj", "off", "gltf", "glb", "dae"};

}  // namespace

// Assimp 5.2 leaks on some malformed inputs (e.g. a glTF whose buffer file
// cannot be opened leaks with a plain Importer::ReadFileFromMemory too). It is
// not our code and not instrumented; LeakSanitizer still checks ours.
extern "C" const char* __lsan_default_suppressions() { return "leak:libassimp.so\n"; }

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  static const bool quiet = [] {
    dm::log::setLevel(dm::log::Level::Off);  // non-manifold warnings for every other input
    return true;
  }();
  (void)quiet;

  const std::string hint = kFormats[data[0] % std::size(kFormats)];
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data + 1), size - 1);
  dm::MeshImportOptions options;
  options.maxTriangles = std::size_t{1} << 20;
  options.maxFileBytes = std::size_t{1} << 20;
  options.weldTolerance = (data[0] & 0x80) != 0 ? 1e-3 : 0.0;  // both weld paths
  options.timeoutSeconds = 10;                                 // well under libFuzzer's -timeout
  options.isolation = dm::Isolation::Fork;

  auto mesh = dm::parseMesh(bytes, hint, options);
  if (!mesh) {
    const std::string msg = mesh.error().message();
    if (mesh.error().code == dm::ErrorCode::Internal || mesh.error().what.empty() ||
        msg.find("<memory>." + hint) == std::string::npos)
      std::abort();
    return 0;
  }
  if (mesh->empty() || !mesh->validate()) std::abort();

  for (const char* format : {"stl", "ply", "obj"}) {
    auto encoded = dm::encodeMesh(*mesh, format, {.binary = (size & 1) != 0});
    if (!encoded) std::abort();  // a valid non-empty mesh must always encode
    auto back = dm::parseMesh(*encoded, format, options);
    if (back && (back->empty() || !back->validate())) std::abort();
  }
  return 0;
}
