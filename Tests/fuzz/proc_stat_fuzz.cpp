// libFuzzer target: /proc/stat text (dm::parseProcStat). Any input gives
// CPU times or a dm::Error naming /proc/stat, never a crash; parsed times are
// finite and non-negative.
#include <dm/core/host_cpu.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  auto t = dm::parseProcStat(text, 100.0);
  if (!t) {
    if (t.error().what.empty() || t.error().where.find("/proc/stat") == std::string_view::npos) std::abort();
    return 0;
  }
  for (double v : {t->busy_s, t->idle_s, t->steal_s})
    if (!std::isfinite(v) || v < 0) std::abort();
  if (t->cpus < 0) std::abort();
  return 0;
}
