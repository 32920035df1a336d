// libFuzzer target: PNG decoding from memory through libpng.
// Any input must give an Image or a dm::Error, never a crash, hang, longjmp
// gone wrong or large allocation. A decoded image must also survive
// encodePng -> parsePng with identical pixels (the writer's contract).
#include <dm/io/image_io.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <span>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  dm::ImageReadOptions options;
  options.maxBytes = std::size_t{64} << 20;
  options.maxPixels = std::size_t{16} << 20;
  auto img = dm::parsePng(bytes, "<fuzz>", options);
  if (!img) {
    if (img.error().what.empty() || img.error().where.find("<fuzz>") == std::string::npos) std::abort();
    return 0;
  }
  auto encoded = dm::encodePng(*img);
  if (!encoded) std::abort();  // every decoded layout is writable
  auto back = dm::parsePng(*encoded, "<fuzz re-encoded>", options);
  if (!back || back->width() != img->width() || back->height() != img->height() ||
      back->channels() != img->channels() || back->type() != img->type())
    std::abort();
  for (int y = 0; y < img->height(); ++y)
    if (std::memcmp(back->row(y), img->row(y), img->rowBytes()) != 0) std::abort();
  return 0;
}
