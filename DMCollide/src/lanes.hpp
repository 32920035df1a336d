// Small fixed-width lane types for DMCollide's hot loops (internal header).
//
//   F4: four floats (x, y, z, unused), lane-wise min/max/sub/mul: the BVH
//       builder's boxes and centroids (bvh.cpp).
//   D2: two doubles, lane-wise arithmetic, comparisons to masks, select: two
//       sibling nodes' box tests at once (mesh_query.cpp).
//
// SSE2 where the compiler targets it (every x86-64), plain arrays otherwise;
// both give the same IEEE results lane by lane.
#pragma once

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace dm::lanes {

struct F4 {
#if defined(__SSE2__)
  __m128 v;
  static F4 of(float x, float y, float z) noexcept { return {_mm_set_ps(0.0f, z, y, x)}; }
  static F4 all(float a) noexcept { return {_mm_set1_ps(a)}; }
  friend F4 min(F4 a, F4 b) noexcept { return {_mm_min_ps(a.v, b.v)}; }
  friend F4 max(F4 a, F4 b) noexcept { return {_mm_max_ps(a.v, b.v)}; }
  friend F4 operator-(F4 a, F4 b) noexcept { return {_mm_sub_ps(a.v, b.v)}; }
  friend F4 operator*(F4 a, F4 b) noexcept { return {_mm_mul_ps(a.v, b.v)}; }
  void store(float* out) const noexcept { _mm_storeu_ps(out, v); }
  /// Lanes truncated towards zero.
  void truncate(std::int32_t* out) const noexcept {
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out), _mm_cvttps_epi32(v));
  }
  float operator[](int i) const noexcept {
    float f[4];
    store(f);
    return f[i];
  }
#else
  float v[4];
  static F4 of(float x, float y, float z) noexcept { return {{x, y, z, 0.0f}}; }
  static F4 all(float a) noexcept { return {{a, a, a, a}}; }
  template <typename Op>
  static F4 zip(F4 a, F4 b, Op op) noexcept {
    return {{op(a.v[0], b.v[0]), op(a.v[1], b.v[1]), op(a.v[2], b.v[2]), op(a.v[3], b.v[3])}};
  }
  friend F4 min(F4 a, F4 b) noexcept { return zip(a, b, [](float x, float y) { return x < y ? x : y; }); }
  friend F4 max(F4 a, F4 b) noexcept { return zip(a, b, [](float x, float y) { return x > y ? x : y; }); }
  friend F4 operator-(F4 a, F4 b) noexcept { return zip(a, b, [](float x, float y) { return x - y; }); }
  friend F4 operator*(F4 a, F4 b) noexcept { return zip(a, b, [](float x, float y) { return x * y; }); }
  void store(float* out) const noexcept { std::copy(v, v + 4, out); }
  void truncate(std::int32_t* out) const noexcept {
    for (int i = 0; i < 4; ++i) out[i] = static_cast<std::int32_t>(v[i]);
  }
  float operator[](int i) const noexcept { return v[i]; }
#endif
};

/// Two doubles. Comparisons give a D2 mask (all bits set in true lanes).
struct D2 {
#if defined(__SSE2__)
  __m128d v;
  static D2 of(double a, double b) noexcept { return {_mm_set_pd(b, a)}; }
  static D2 all(double a) noexcept { return {_mm_set1_pd(a)}; }
  friend D2 operator+(D2 a, D2 b) noexcept { return {_mm_add_pd(a.v, b.v)}; }
  friend D2 operator-(D2 a, D2 b) noexcept { return {_mm_sub_pd(a.v, b.v)}; }
  friend D2 operator*(D2 a, D2 b) noexcept { return {_mm_mul_pd(a.v, b.v)}; }
  friend D2 operator/(D2 a, D2 b) noexcept { return {_mm_div_pd(a.v, b.v)}; }
  friend D2 min(D2 a, D2 b) noexcept { return {_mm_min_pd(a.v, b.v)}; }
  friend D2 max(D2 a, D2 b) noexcept { return {_mm_max_pd(a.v, b.v)}; }
  friend D2 abs(D2 a) noexcept { return {_mm_andnot_pd(_mm_set1_pd(-0.0), a.v)}; }
  friend D2 sqrt(D2 a) noexcept { return {_mm_sqrt_pd(a.v)}; }
  friend D2 operator>(D2 a, D2 b) noexcept { return {_mm_cmpgt_pd(a.v, b.v)}; }
  friend D2 operator&(D2 a, D2 b) noexcept { return {_mm_and_pd(a.v, b.v)}; }
  /// mask ? a : b, lane by lane.
  friend D2 select(D2 mask, D2 a, D2 b) noexcept {
    return {_mm_or_pd(_mm_and_pd(mask.v, a.v), _mm_andnot_pd(mask.v, b.v))};
  }
  /// Whether every lane of a mask is true.
  friend bool allOf(D2 mask) noexcept { return _mm_movemask_pd(mask.v) == 3; }
  double operator[](int i) const noexcept {
    double d[2];
    _mm_storeu_pd(d, v);
    return d[i];
  }
#else
  double v[2];
  static D2 of(double a, double b) noexcept { return {{a, b}}; }
  static D2 all(double a) noexcept { return {{a, a}}; }
  template <typename Op>
  static D2 zip(D2 a, D2 b, Op op) noexcept {
    return {{op(a.v[0], b.v[0]), op(a.v[1], b.v[1])}};
  }
  static double bits(bool b) noexcept { return std::bit_cast<double>(b ? ~std::uint64_t{0} : std::uint64_t{0}); }
  static bool isSet(double d) noexcept { return std::bit_cast<std::uint64_t>(d) != 0; }
  friend D2 operator+(D2 a, D2 b) noexcept { return zip(a, b, [](double x, double y) { return x + y; }); }
  friend D2 operator-(D2 a, D2 b) noexcept { return zip(a, b, [](double x, double y) { return x - y; }); }
  friend D2 operator*(D2 a, D2 b) noexcept { return zip(a, b, [](double x, double y) { return x * y; }); }
  friend D2 operator/(D2 a, D2 b) noexcept { return zip(a, b, [](double x, double y) { return x / y; }); }
  friend D2 min(D2 a, D2 b) noexcept { return zip(a, b, [](double x, double y) { return x < y ? x : y; }); }
  friend D2 max(D2 a, D2 b) noexcept { return zip(a, b, [](double x, double y) { return x > y ? x : y; }); }
  friend D2 abs(D2 a) noexcept { return {{std::abs(a.v[0]), std::abs(a.v[1])}}; }
  friend D2 sqrt(D2 a) noexcept { return {{std::sqrt(a.v[0]), std::sqrt(a.v[1])}}; }
  friend D2 operator>(D2 a, D2 b) noexcept { return {{bits(a.v[0] > b.v[0]), bits(a.v[1] > b.v[1])}}; }
  friend D2 operator&(D2 a, D2 b) noexcept {
    return {{bits(isSet(a.v[0]) && isSet(b.v[0])), bits(isSet(a.v[1]) && isSet(b.v[1]))}};
  }
  friend D2 select(D2 mask, D2 a, D2 b) noexcept {
    return {{isSet(mask.v[0]) ? a.v[0] : b.v[0], isSet(mask.v[1]) ? a.v[1] : b.v[1]}};
  }
  friend bool allOf(D2 mask) noexcept { return isSet(mask.v[0]) && isSet(mask.v[1]); }
  double operator[](int i) const noexcept { return v[i]; }
#endif
};

}  // namespace dm::lanes
