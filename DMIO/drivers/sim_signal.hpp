// Pieces shared by the simulated drivers (sim-controller, sim-daq,
// sim-sensor): scripted periodic signals and a scripted loss window.
// Header-only like driver_params.hpp, so plugins link nothing of ours.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdlib>

#include "driver_params.hpp"

namespace dm::driver {

/// A periodic signal of time t (s):
///   sine      offset + amplitude·sin(2π·frequency·t)
///   square    offset ± amplitude (+ for the first half of each period)
///   ramp      offset + amplitude·(2·frac(frequency·t) − 1)   (sawtooth)
///   constant  offset
struct Signal {
  enum Shape { kSine, kSquare, kRamp, kConstant };
  Shape shape = kSine;
  double amplitude = 1.0;
  double frequency = 1.0;  // Hz
  double offset = 0.0;

  double at(double t) const noexcept {
    const double cycles = frequency * t;
    const double frac = cycles - std::floor(cycles);
    switch (shape) {
      case kSine:
        return offset + amplitude * std::sin(2.0 * 3.14159265358979323846 * cycles);
      case kSquare:
        return offset + (frac < 0.5 ? amplitude : -amplitude);
      case kRamp:
        return offset + amplitude * (2.0 * frac - 1.0);
      case kConstant:
        return offset;
    }
    return offset;
  }
};

/// Parses parameter `key` = "shape[,amplitude[,frequency[,offset]]]" (shape
/// sine | square | ramp | constant; frequency in [0, 1e6] Hz) over
/// `signal`; leaves it unchanged when absent. Fails naming the key.
inline void readSignal(ParamReader& r, const char* key, Signal& signal) {
  const char* v = r.find(key);
  if (!v) return;
  static const char* const kShapes[] = {"sine", "square", "ramp", "constant"};
  const char* comma = std::strchr(v, ',');
  const std::size_t len = comma ? static_cast<std::size_t>(comma - v) : std::strlen(v);
  int shape = -1;
  for (int i = 0; i < 4; ++i)
    if (std::strlen(kShapes[i]) == len && std::strncmp(kShapes[i], v, len) == 0) shape = i;
  if (shape < 0) {
    r.failf("parameter '%s': '%s' does not start with sine, square, ramp or constant", key, v);
    return;
  }
  double numbers[3] = {signal.amplitude, signal.frequency, signal.offset};
  const char* p = comma;
  for (int i = 0; i < 3 && p; ++i) {
    char* end = nullptr;
    errno = 0;
    numbers[i] = std::strtod(p + 1, &end);
    if (end == p + 1 || errno == ERANGE || !std::isfinite(numbers[i]) || (*end != ',' && *end != '\0') ||
        (i == 2 && *end)) {
      r.failf("parameter '%s': '%s' is not \"shape[,amplitude[,frequency[,offset]]]\"", key, v);
      return;
    }
    p = *end == ',' ? end : nullptr;
  }
  if (numbers[1] < 0.0 || numbers[1] > 1e6) {
    r.failf("parameter '%s': frequency %g is outside [0, 1e6] Hz", key, numbers[1]);
    return;
  }
  signal = Signal{static_cast<Signal::Shape>(shape), numbers[0], numbers[1], numbers[2]};
}

/// A whole number in [min, max] for `key`; `fallback` when absent. Fails
/// naming the key for a fraction.
inline unsigned wholeNumber(ParamReader& r, const char* key, unsigned fallback, unsigned min, unsigned max) {
  const double x = r.number(key, fallback, min, max);
  if (x != std::floor(x)) {
    r.failf("parameter '%s': %g is not a whole number", key, x);
    return fallback;
  }
  return static_cast<unsigned>(x);
}

/// A scripted connection loss: lost from `dropAt` (s, host time) until a
/// reconnect attempt at or after `reconnectAt`; negative: never.
struct LossWindow {
  double dropAt = -1.0;
  double reconnectAt = -1.0;
  bool lost = false;
  bool reconnected = false;

  /// Reads parameters drop_at and reconnect_at.
  void read(ParamReader& r) {
    dropAt = r.number("drop_at", -1.0, -1.0, 1e9);
    reconnectAt = r.number("reconnect_at", -1.0, -1.0, 1e9);
  }
  /// True while the device is away at host time nowNs.
  bool lostAt(std::int64_t nowNs) noexcept {
    if (!lost && !reconnected && dropAt >= 0.0 && 1e-9 * static_cast<double>(nowNs) >= dropAt) lost = true;
    return lost;
  }
  /// The driver's reconnect at nowNs: DM_DEVICE_OK once the window is over.
  int reconnect(std::int64_t nowNs) noexcept {
    if (!lost) return DM_DEVICE_OK;
    if (reconnectAt < 0.0 || 1e-9 * static_cast<double>(nowNs) < reconnectAt) return DM_DEVICE_ERROR_LOST;
    lost = false;
    reconnected = true;
    return DM_DEVICE_OK;
  }
};

}  // namespace dm::driver
