// libFuzzer target: what a reader makes of the bytes an isolated import sends
// back (DMIO/src/isolate.hpp: meshesFromResult, volumeFromResult). The other
// process runs Assimp or OpenVDB on a hostile file; a parser that corrupted
// its heap may still let it end cleanly with garbage, so its result is
// untrusted input to the caller too. The first byte picks the reader (bit 7:
// volume, else meshes; bit 0: merged, as readMesh asks; bit 1: welding
// within a tolerance), the rest is the result. Any input must give meshes
// that validate() or a volume of the dims it claims, or a dm::Error that
// says what failed — never a crash, and never an allocation the bytes
// cannot justify.
#include <dm/core/mesh.hpp>
#include <dm/core/volume.hpp>
#include <dm/io/mesh_io.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "isolate.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::vector<char> bytes(reinterpret_cast<const char*>(data + 1),
                                reinterpret_cast<const char*>(data + size));
  if ((data[0] & 0x80) != 0) {
    auto v = dm::detail::volumeFromResult(bytes, std::size_t{8} << 20, "<fuzz>");
    if (!v) {
      if (v.error().what.empty()) std::abort();
      return 0;
    }
    if (v->empty() || v->byteSize() > (std::size_t{8} << 20) || !v->indexToWorld().matrix().allFinite())
      std::abort();
    return 0;
  }
  dm::MeshImportOptions options;
  options.maxTriangles = std::size_t{1} << 20;
  options.weldTolerance = (data[0] & 2) != 0 ? 1e-3 : 0.0;
  const bool merge = (data[0] & 1) != 0;
  auto meshes = dm::detail::meshesFromResult(bytes, options, merge, "<fuzz>");
  if (!meshes) {
    if (meshes.error().what.empty()) std::abort();
    return 0;
  }
  if (meshes->empty() || (merge && meshes->size() != 1)) std::abort();
  for (const dm::Mesh& m : *meshes)
    if (m.empty() || !m.validate()) std::abort();
  return 0;
}
