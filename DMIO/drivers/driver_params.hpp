// Parameter parsing for device drivers: header-only, so that a driver built
// as a plugin needs no DMPlatform library. Every problem is written once into
// the caller's error buffer, naming the key, the value and what is expected.
#pragma once

#include <dm/io/device_abi.h>

#include <array>
#include <cerrno>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <initializer_list>
#include <string>

namespace dm::driver {

class ParamReader {
 public:
  ParamReader(const DmDeviceParam* params, std::size_t count, char* error, std::size_t errorSize) noexcept
      : params_(params), count_(count), error_(error), errorSize_(errorSize) {}

  bool ok() const noexcept { return ok_; }

  /// The value of `key`, or nullptr when absent.
  const char* find(const char* key) const noexcept {
    for (std::size_t i = 0; i < count_; ++i)
      if (params_[i].key && std::strcmp(params_[i].key, key) == 0)
        return params_[i].value ? params_[i].value : "";
    return nullptr;
  }

  /// A finite number in [min, max]; `fallback` when absent.
  double number(const char* key, double fallback, double min, double max) {
    const char* v = find(key);
    if (!v) return fallback;
    char* end = nullptr;
    errno = 0;
    const double x = std::strtod(v, &end);
    if (end == v || *end != '\0' || errno == ERANGE || !std::isfinite(x)) {
      failf("parameter '%s': '%s' is not a number", key, v);
      return fallback;
    }
    if (x < min || x > max) {
      failf("parameter '%s': %g is outside [%g, %g]", key, x, min, max);
      return fallback;
    }
    return x;
  }

  /// N comma-separated finite numbers ("x,y,z" for three). True when `key`
  /// is present and well formed (then `out` holds them); false when absent
  /// (`out` untouched) or malformed (`out` untouched, the failure recorded).
  template <std::size_t N>
  bool numbers(const char* key, std::array<double, N>& out) {
    static_assert(N >= 1 && N <= 9, "a handful of numbers");
    const char* v = find(key);
    if (!v) return false;
    std::array<double, N> parsed{};
    const char* p = v;
    for (std::size_t i = 0; i < N; ++i) {
      char* end = nullptr;
      errno = 0;
      parsed[i] = std::strtod(p, &end);
      const bool last = i + 1 == N;
      if (end == p || errno == ERANGE || !std::isfinite(parsed[i]) || (!last && *end != ',') ||
          (last && *end)) {
        static const char* const kCount[] = {"",
                                             "one number",
                                             "two numbers",
                                             "three numbers",
                                             "four numbers",
                                             "five numbers",
                                             "six numbers",
                                             "seven numbers",
                                             "eight numbers",
                                             "nine numbers"};
        std::string example;
        for (std::size_t k = 0; k < N; ++k) example += (k ? "," : "") + std::string(1, char('a' + k));
        if (N == 3) example = "x,y,z";
        failf("parameter '%s': '%s' is not %s \"%s\"", key, v, kCount[N], example.c_str());
        return false;
      }
      p = end + 1;
    }
    out = parsed;
    return true;
  }

  /// Three comma-separated numbers "x,y,z"; `fallback` when absent or malformed.
  std::array<double, 3> triple(const char* key, std::array<double, 3> fallback) {
    numbers(key, fallback);
    return fallback;
  }

  /// One of `choices`; returns its index, or `fallback` when absent.
  int choice(const char* key, std::initializer_list<const char*> choices, int fallback) {
    const char* v = find(key);
    if (!v) return fallback;
    int i = 0;
    std::string list;
    for (const char* c : choices) {
      if (std::strcmp(c, v) == 0) return i;
      list += (list.empty() ? "" : ", ") + std::string(c);
      ++i;
    }
    failf("parameter '%s': '%s' is not one of: %s", key, v, list.c_str());
    return fallback;
  }

  /// Fails on the first key not in `known`.
  void onlyKnown(std::initializer_list<const char*> known) {
    for (std::size_t i = 0; i < count_ && ok_; ++i) {
      bool found = false;
      for (const char* k : known) found = found || (params_[i].key && std::strcmp(params_[i].key, k) == 0);
      if (!found) {
        std::string list;
        for (const char* k : known) list += (list.empty() ? "" : ", ") + std::string(k);
        failf("unknown parameter '%s' (known: %s)", params_[i].key ? params_[i].key : "(null)", list.c_str());
      }
    }
  }

  /// Records the first failure, printf-style (the format is checked).
  __attribute__((format(printf, 2, 3))) void failf(const char* format, ...) noexcept {
    if (!ok_) return;  // keep the first message
    ok_ = false;
    if (!error_ || !errorSize_) return;
    std::va_list args;
    va_start(args, format);
    std::vsnprintf(error_, errorSize_, format, args);
    va_end(args);
  }

 private:
  const DmDeviceParam* params_;
  std::size_t count_;
  char* error_;
  std::size_t errorSize_;
  bool ok_ = true;
};

/// Copies `s` into a fixed char field, truncating and NUL-terminating.
template <std::size_t N>
void copyField(char (&field)[N], const char* s) noexcept {
  std::size_t i = 0;
  for (; s && i + 1 < N && s[i]; ++i) field[i] = s[i];
  field[i] = '\0';
}

/// Identity of a simulated driver: vendor "DMPlatform", serial "sim-<seed>".
inline void simIdentity(DmDeviceIdentity& id, const char* driver, const char* model,
                        unsigned long long seed) noexcept {
  copyField(id.driver, driver);
  copyField(id.vendor, "DMPlatform");
  copyField(id.model, model);
  std::snprintf(id.serial, sizeof id.serial, "sim-%llu", seed);
}

}  // namespace dm::driver
