// host_cpu.cpp — /proc/stat's CPU time accounts; the SIMD level of the
// run-time picked kernels.
#include <dm/core/host_cpu.hpp>
#include <dm/core/log.hpp>

#include <algorithm>
#include <charconv>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include <unistd.h>

namespace dm {

namespace {

constexpr const char* kSource = "/proc/stat";

std::string_view nextField(std::string_view& line) {
  const auto begin = line.find_first_not_of(" \t");
  if (begin == std::string_view::npos) {
    line = {};
    return {};
  }
  line.remove_prefix(begin);
  const auto end = line.find_first_of(" \t");
  const std::string_view field = line.substr(0, end);
  line.remove_prefix(end == std::string_view::npos ? line.size() : end);
  return field;
}

bool isCpuN(std::string_view name) {
  if (name.size() < 4 || name.substr(0, 3) != "cpu") return false;
  for (char c : name.substr(3))
    if (c < '0' || c > '9') return false;
  return true;
}

}  // namespace

Result<HostCpuTimes> parseProcStat(std::string_view text, double ticksPerSecond) {
  if (!(ticksPerSecond > 0))
    return fail(ErrorCode::InvalidArgument, formatString("ticks per second is %g", ticksPerSecond),
                "parseProcStat", "pass sysconf(_SC_CLK_TCK)");
  HostCpuTimes t;
  bool aggregate = false;
  std::size_t lineNo = 0;
  while (!text.empty()) {
    const auto eol = text.find('\n');
    std::string_view line = text.substr(0, eol);
    text.remove_prefix(eol == std::string_view::npos ? text.size() : eol + 1);
    ++lineNo;
    const std::string_view name = nextField(line);
    if (isCpuN(name)) ++t.cpus;
    if (name != "cpu" || aggregate) continue;
    aggregate = true;
    // user nice system idle iowait irq softirq steal [guest guest_nice]
    unsigned long long v[8] = {};
    int n = 0;
    for (std::string_view f = nextField(line); !f.empty() && n < 8; f = nextField(line), ++n) {
      const auto [end, ec] = std::from_chars(f.data(), f.data() + f.size(), v[n]);
      if (ec != std::errc() || end != f.data() + f.size())
        return fail(ErrorCode::Parse, "field " + std::to_string(n + 1) + " is \"" + std::string(f) + "\"",
                    formatString("%s: line %zu", kSource, lineNo), "expected a non-negative integer");
    }
    if (n < 4)
      return fail(ErrorCode::Parse, "the cpu line has " + std::to_string(n) + " fields",
                  formatString("%s: line %zu", kSource, lineNo), "expected at least user nice system idle");
    const double s = 1.0 / ticksPerSecond;
    t.busy_s = static_cast<double>(v[0] + v[1] + v[2] + v[5] + v[6]) * s;
    t.idle_s = static_cast<double>(v[3] + v[4]) * s;
    t.steal_s = static_cast<double>(v[7]) * s;
  }
  if (!aggregate)
    return fail(ErrorCode::Parse, "no aggregate \"cpu\" line", kSource, "is this Linux's /proc/stat?");
  return t;
}

Result<HostCpuTimes> readHostCpuTimes() {
#ifdef __linux__
  std::ifstream in(kSource);
  if (!in) return fail(ErrorCode::NotFound, "cannot open", kSource, "is /proc mounted?");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return fail(ErrorCode::Io, "cannot read", kSource);
  return parseProcStat(text.str(), static_cast<double>(sysconf(_SC_CLK_TCK)));
#else
  return fail(ErrorCode::Unsupported, "no /proc/stat on this system", "readHostCpuTimes");
#endif
}

const char* toString(SimdLevel level) noexcept {
  switch (level) {
    case SimdLevel::Sse2:
      return "sse2";
    case SimdLevel::Avx2:
      return "avx2";
    case SimdLevel::Avx512:
      return "avx512";
  }
  return "?";
}

Result<SimdLevel> parseSimdLevel(std::string_view text) {
  for (SimdLevel level : {SimdLevel::Sse2, SimdLevel::Avx2, SimdLevel::Avx512})
    if (text == toString(level)) return level;
  return fail(ErrorCode::InvalidArgument, "unknown SIMD level \"" + std::string(text) + "\"", "DM_SIMD",
              "use sse2, avx2 or avx512");
}

namespace {

SimdLevel detectSimdLevel() noexcept {
  SimdLevel level = SimdLevel::Sse2;
#if defined(__GNUC__) && defined(__x86_64__)
  // GCC and clang: x86-64-v4's features spelled out, since clang 14 knows no
  // level names (the ASan+UBSan tree is built with clang and must run the
  // same SIMD paths as the product).
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
      __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx512dq") &&
      __builtin_cpu_supports("avx512vl"))
    level = SimdLevel::Avx512;
  else if (__builtin_cpu_supports("avx2"))
    level = SimdLevel::Avx2;
#endif
  if (const char* cap = std::getenv("DM_SIMD")) {
    if (auto parsed = parseSimdLevel(cap))
      level = std::min(level, *parsed);
    else
      log::warn("%s; ignored", parsed.error().message().c_str());
  }
  return level;
}

}  // namespace

SimdLevel simdLevel() noexcept {
  static const SimdLevel level = detectSimdLevel();
  return level;
}

}  // namespace dm
