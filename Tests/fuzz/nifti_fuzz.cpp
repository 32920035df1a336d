// libFuzzer target: NIfTI-1/2 parsing from memory (plain and gzip).
// Any input must give a Volume or a dm::Error, never a crash, hang or large
// allocation. A parsed volume must also survive encodeNifti -> parseNifti
// with identical voxels (the writer's contract).
#include <dm/io/nifti.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <span>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  (void)dm::parseNiftiHeader(bytes, "<fuzz>");
  dm::NiftiReadOptions options;
  options.maxBytes = std::size_t{64} << 20;
  auto v = dm::parseNifti(bytes, "<fuzz>", options);
  if (!v) {
    if (v.error().what.empty()) std::abort();  // every error says what failed
    return 0;
  }
  auto encoded = dm::encodeNifti(*v);
  if (!encoded) return 0;  // e.g. a dimension beyond NIfTI-1's 32767
  auto back = dm::parseNifti(*encoded, "<fuzz re-encoded>", options);
  if (!back || back->type() != v->type() || back->dims() != v->dims() ||
      std::memcmp(back->bytes(), v->bytes(), v->byteSize()) != 0)
    std::abort();
  return 0;
}
