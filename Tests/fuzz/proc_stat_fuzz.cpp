// libFuzzer target: the parsers of dm/core/host_cpu.hpp. /proc/stat text
// (dm::parseProcStat): any input gives CPU times or a dm::Error naming
// /proc/stat, never a crash; parsed times are finite and non-negative. A
// DM_SIMD value (dm::parseSimdLevel): a level whose name is the input, or an
// error naming DM_SIMD.
#include <dm/core/host_cpu.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  if (auto level = dm::parseSimdLevel(text)) {
    if (text != dm::toString(*level)) std::abort();
  } else if (level.error().where != "DM_SIMD") {
    std::abort();
  }
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
