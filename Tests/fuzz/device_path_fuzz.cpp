// libFuzzer target: device path CSV. Any input must give a path or a
// dm::Error naming where; a parsed path must survive formatting and parsing
// again with the same times and positions.
#include <dm/io/device_path.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  auto p = dm::parseDevicePathCsv(text, "<fuzz>", {.maxSamples = 100000});
  if (!p) {
    if (p.error().what.empty() || p.error().where.empty()) std::abort();
    return 0;
  }
  if (p->samples.empty()) std::abort();
  (void)p->at(0.5 * (p->startTime() + p->endTime()));
  auto back = dm::parseDevicePathCsv(dm::formatDevicePathCsv(*p), "<fuzz re-formatted>");
  if (!back || back->samples.size() != p->samples.size() || back->hasOrientation != p->hasOrientation)
    std::abort();
  for (std::size_t i = 0; i < p->samples.size(); ++i) {
    if (back->samples[i].t != p->samples[i].t || back->samples[i].position != p->samples[i].position)
      std::abort();
    if (std::abs(back->samples[i].orientation.norm() - 1.0) > 1e-12) std::abort();
  }
  return 0;
}
