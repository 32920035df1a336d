// libFuzzer target: NRRD (attached data; raw, gzip, ascii, hex) parsing from
// memory. Any input must give a Volume or a dm::Error; a parsed volume must
// survive encodeNrrd -> parseNrrd with identical voxels.
#include <dm/io/nrrd.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <span>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  dm::NrrdReadOptions options;
  options.maxBytes = std::size_t{64} << 20;
  auto v = dm::parseNrrd(bytes, "<fuzz>", options);
  if (!v) {
    if (v.error().what.empty()) std::abort();
    return 0;
  }
  auto encoded = dm::encodeNrrd(*v, {.gzip = (size & 1) != 0});
  if (!encoded) return 0;  // the writer may refuse (e.g. an affine overflowing in mm)
  auto back = dm::parseNrrd(*encoded, "<fuzz re-encoded>", options);
  if (!back || back->type() != v->type() || back->dims() != v->dims() ||
      std::memcmp(back->bytes(), v->bytes(), v->byteSize()) != 0)
    std::abort();
  return 0;
}
