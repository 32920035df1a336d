// libFuzzer target: one DICOM slice parsed from memory (Part 10 or a bare
// data set, any uncompressed transfer syntax). Any input must give a Volume
// or a dm::Error with a message, never a crash, hang or large allocation —
// also inside DCMTK, which only ever sees bytes the reader has bounds-checked.
// A parsed slice must be an nx×ny×1 volume whose byte size matches its dims.
#include <dm/io/dicom.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  dm::DicomReadOptions options;
  options.maxBytes = std::size_t{64} << 20;
  auto v = dm::parseDicomSlice(bytes, "<fuzz>", options);
  if (!v) {
    if (v.error().what.empty()) std::abort();  // every error says what failed
    return 0;
  }
  const auto& d = v->dims();
  if (d.z() != 1 || d.x() < 1 || d.y() < 1 || v->byteSize() > options.maxBytes ||
      v->byteSize() != v->voxelCount() * dm::voxelBytes(v->type()))
    std::abort();
  (void)v->range();  // touches every voxel
  return 0;
}
