// libFuzzer target: the UCI letter-recognition reader. Any input must give a
// consistent data set (one label in 0..25 per row, rows × dims features) or
// an error that names where (never a crash, hang or huge allocation).
#include <dm/vision/classify.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  auto set = dm::parseLetterData(text, "<fuzz>");
  if (!set) {
    if (set.error().what.empty() || set.error().where.empty()) std::abort();
    return 0;
  }
  if (set->features.size() != set->size() * static_cast<std::size_t>(set->dims)) std::abort();
  for (int label : set->labels)
    if (label < 0 || label > 25) std::abort();
  return 0;
}
