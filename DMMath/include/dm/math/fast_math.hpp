// dm/math/fast_math.hpp — fast approximations of sqrt, 1/sqrt, sin, cos and
// exp with documented error bounds, for hot loops (haptic rendering,
// per-particle or per-voxel kernels).
//
// Why they can be faster than <cmath>: they are inline, never set errno, and
// have no slow paths on the common inputs (one well-predicted branch sends
// zeros, subnormals, infinities and NaN to a separate path; sin/cos are
// branch-free, with no Payne–Hanek reduction for huge arguments; exp uses a
// 2 KiB table). Whether they are faster on a given machine is measured by
// Bench/fast_math_bench.cpp, which prints std/fast time ratios; std::sqrt is
// a single instruction on x86-64 and is hard to beat. (GCC 12 at -O2 does not
// vectorise loops over these; -O3 vectorises fastSin/fastCos.)
//
// Accuracy: every function states its maximum error over its domain as a
// constant below; Tests/DMMath/fast_math_test.cpp sweeps each domain
// (dense sampling, every binary exponent for sqrt/invsqrt, special values)
// against long-double references and fails if a bound is exceeded. The sin,
// cos and exp bounds are within a few units in the last place; the
// sqrt/invsqrt bounds are 5e-11 relative in double (three Newton steps) and
// 6e-6 in float (two) — use std::sqrt where the last digits matter.
//
// The range reductions round with the 1.5·2^52 trick, which needs IEEE
// semantics: do not compile code that includes this header with
// -ffast-math / -fassociative-math.
//
// @code
//   double inv = dm::fastInvSqrt(v.squaredNorm());   // normalise without a division
//   double c = dm::fastCos(omega * t), e = dm::fastExp(-t / tau);
// @endcode
#pragma once

#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

namespace dm {

// ----- documented bounds -----------------------------------------------------

/// fastInvSqrt(double): max relative error over all positive finite doubles
/// (normal and subnormal). Seed error e₀ ≤ 3.42 %, each Newton step maps
/// e → 1.5e² + 0.5e³: 1.8e-3, 4.7e-6, 3.3e-11; measured 3.17e-11.
inline constexpr double kFastInvSqrtMaxRelError = 5e-11;
/// fastSqrt(double): max relative error over all positive finite doubles.
inline constexpr double kFastSqrtMaxRelError = 5e-11;
/// fastInvSqrt(float) / fastSqrt(float): max relative error over all
/// positive finite floats (two Newton steps; measured ≈ 4.7e-6).
inline constexpr float kFastInvSqrtMaxRelErrorF = 6e-6f;
inline constexpr float kFastSqrtMaxRelErrorF = 6e-6f;

/// fastSin / fastCos: max absolute error for |x| ≤ kFastSinCosDomain.
/// Error budget: reduction ≤ ½ ulp(π/4), polynomials < 2e-18, four roundings
/// of at most ½ ulp(1) in the kernel: ≲ 2e-16; measured 1.74e-16.
inline constexpr double kFastSinMaxAbsError = 2.5e-16;
inline constexpr double kFastCosMaxAbsError = 2.5e-16;
/// Domain of the sin/cos bounds, radians. The reduction stays exact up to
/// |x| ≈ 1.6e6; beyond 2^50 the result is meaningless.
inline constexpr double kFastSinCosDomain = 1e5;

/// fastExp: max relative error for x in [kFastExpMin, kFastExpMax], where
/// the result is a normal double. Budget: one final rounding (2^-53 =
/// 1.11e-16) plus < 5e-18 from the polynomial, table and reduction;
/// measured 1.11e-16.
inline constexpr double kFastExpMaxRelError = 1.5e-16;
inline constexpr double kFastExpMin = -708.0;
inline constexpr double kFastExpMax = 709.7;

namespace detail {

inline constexpr double kDblMin = std::numeric_limits<double>::min();  // smallest normal
inline constexpr double kDblMax = std::numeric_limits<double>::max();
/// 1.5·2^52: adding it rounds a double of magnitude < 2^51 to an integer,
/// which then sits in the low mantissa bits (two's complement).
inline constexpr double kRoundMagic = 6755399441055744.0;

/// 2^(j/128), j = 0..127, correctly rounded (hi), and the relative rounding
/// error (2^(j/128) − hi)/hi (lo), for fastExp. Generated with mpmath at 50
/// digits.
// clang-format off
inline constexpr double kExp2TableHi[128] = {
    0x1.0000000000000p+0, 0x1.0163da9fb3335p+0, 0x1.02c9a3e778061p+0, 0x1.04315e86e7f85p+0,
    0x1.059b0d3158574p+0, 0x1.0706b29ddf6dep+0, 0x1.0874518759bc8p+0, 0x1.09e3ecac6f383p+0,
    0x1.0b5586cf9890fp+0, 0x1.0cc922b7247f7p+0, 0x1.0e3ec32d3d1a2p+0, 0x1.0fb66affed31bp+0,
    0x1.11301d0125b51p+0, 0x1.12abdc06c31ccp+0, 0x1.1429aaea92de0p+0, 0x1.15a98c8a58e51p+0,
    0x1.172b83c7d517bp+0, 0x1.18af9388c8deap+0, 0x1.1a35beb6fcb75p+0, 0x1.1bbe084045cd4p+0,
    0x1.1d4873168b9aap+0, 0x1.1ed5022fcd91dp+0, 0x1.2063b88628cd6p+0, 0x1.21f49917ddc96p+0,
    0x1.2387a6e756238p+0, 0x1.251ce4fb2a63fp+0, 0x1.26b4565e27cddp+0, 0x1.284dfe1f56381p+0,
    0x1.29e9df51fdee1p+0, 0x1.2b87fd0dad990p+0, 0x1.2d285a6e4030bp+0, 0x1.2ecafa93e2f56p+0,
    0x1.306fe0a31b715p+0, 0x1.32170fc4cd831p+0, 0x1.33c08b26416ffp+0, 0x1.356c55f929ff1p+0,
    0x1.371a7373aa9cbp+0, 0x1.38cae6d05d866p+0, 0x1.3a7db34e59ff7p+0, 0x1.3c32dc313a8e5p+0,
    0x1.3dea64c123422p+0, 0x1.3fa4504ac801cp+0, 0x1.4160a21f72e2ap+0, 0x1.431f5d950a897p+0,
    0x1.44e086061892dp+0, 0x1.46a41ed1d0057p+0, 0x1.486a2b5c13cd0p+0, 0x1.4a32af0d7d3dep+0,
    0x1.4bfdad5362a27p+0, 0x1.4dcb299fddd0dp+0, 0x1.4f9b2769d2ca7p+0, 0x1.516daa2cf6642p+0,
    0x1.5342b569d4f82p+0, 0x1.551a4ca5d920fp+0, 0x1.56f4736b527dap+0, 0x1.58d12d497c7fdp+0,
    0x1.5ab07dd485429p+0, 0x1.5c9268a5946b7p+0, 0x1.5e76f15ad2148p+0, 0x1.605e1b976dc09p+0,
    0x1.6247eb03a5585p+0, 0x1.6434634ccc320p+0, 0x1.6623882552225p+0, 0x1.68155d44ca973p+0,
    0x1.6a09e667f3bcdp+0, 0x1.6c012750bdabfp+0, 0x1.6dfb23c651a2fp+0, 0x1.6ff7df9519484p+0,
    0x1.71f75e8ec5f74p+0, 0x1.73f9a48a58174p+0, 0x1.75feb564267c9p+0, 0x1.780694fde5d3fp+0,
    0x1.7a11473eb0187p+0, 0x1.7c1ed0130c132p+0, 0x1.7e2f336cf4e62p+0, 0x1.80427543e1a12p+0,
    0x1.82589994cce13p+0, 0x1.8471a4623c7adp+0, 0x1.868d99b4492edp+0, 0x1.88ac7d98a6699p+0,
    0x1.8ace5422aa0dbp+0, 0x1.8cf3216b5448cp+0, 0x1.8f1ae99157736p+0, 0x1.9145b0b91ffc6p+0,
    0x1.93737b0cdc5e5p+0, 0x1.95a44cbc8520fp+0, 0x1.97d829fde4e50p+0, 0x1.9a0f170ca07bap+0,
    0x1.9c49182a3f090p+0, 0x1.9e86319e32323p+0, 0x1.a0c667b5de565p+0, 0x1.a309bec4a2d33p+0,
    0x1.a5503b23e255dp+0, 0x1.a799e1330b358p+0, 0x1.a9e6b5579fdbfp+0, 0x1.ac36bbfd3f37ap+0,
    0x1.ae89f995ad3adp+0, 0x1.b0e07298db666p+0, 0x1.b33a2b84f15fbp+0, 0x1.b59728de5593ap+0,
    0x1.b7f76f2fb5e47p+0, 0x1.ba5b030a1064ap+0, 0x1.bcc1e904bc1d2p+0, 0x1.bf2c25bd71e09p+0,
    0x1.c199bdd85529cp+0, 0x1.c40ab5fffd07ap+0, 0x1.c67f12e57d14bp+0, 0x1.c8f6d9406e7b5p+0,
    0x1.cb720dcef9069p+0, 0x1.cdf0b555dc3fap+0, 0x1.d072d4a07897cp+0, 0x1.d2f87080d89f2p+0,
    0x1.d5818dcfba487p+0, 0x1.d80e316c98398p+0, 0x1.da9e603db3285p+0, 0x1.dd321f301b460p+0,
    0x1.dfc97337b9b5fp+0, 0x1.e264614f5a129p+0, 0x1.e502ee78b3ff6p+0, 0x1.e7a51fbc74c83p+0,
    0x1.ea4afa2a490dap+0, 0x1.ecf482d8e67f1p+0, 0x1.efa1bee615a27p+0, 0x1.f252b376bba97p+0,
    0x1.f50765b6e4540p+0, 0x1.f7bfdad9cbe14p+0, 0x1.fa7c1819e90d8p+0, 0x1.fd3c22b8f71f1p+0,
};
inline constexpr double kExp2TableLo[128] = {
    0x0p+0, 0x1.b3b4f1a88bf6ep-54, -0x1.160139cd8dc5dp-56, -0x1.05e7a108766d1p-54,
    0x1.cd2523567f613p-55, -0x1.bce8023f98efap-55, 0x1.0f74e61e6c861p-57, 0x1.0a3e45b33d399p-54,
    0x1.79aa65d837b6dp-54, 0x1.eb51a92fdeffcp-55, 0x1.ebe3d702f9cd1p-60, -0x1.a033489906e0bp-57,
    -0x1.556522a2fbd0ep-54, -0x1.080ef8c4eea55p-58, -0x1.1c923b9d5f416p-54, 0x1.0d3e3e95c55afp-55,
    -0x1.01b15eaa59348p-55, -0x1.f1ff055de323dp-55, 0x1.b898c3f1353bfp-55, -0x1.6d99c7611eb26p-54,
    0x1.aecf73e3a2f60p-54, -0x1.fe782cb86389dp-55, 0x1.a6f4144a6c38dp-55, 0x1.07a05b0e4047dp-55,
    0x1.68efde3a8a894p-54, 0x1.75e18f274487dp-55, 0x1.0472b981fe7f2p-55, -0x1.6b87b3f71085ep-54,
    0x1.2f7e16d09ab31p-55, -0x1.d219b1a6fbffap-60, 0x1.b3782720c0ab4p-55, 0x1.e149289cecb8fp-57,
    0x1.34d754db0abb6p-55, 0x1.64201e2ac744cp-55, 0x1.fdd395dd3f84ap-55, -0x1.6a3803b8e5b04p-55,
    -0x1.24aedcc4b5068p-54, -0x1.907f81b512d8ep-54, -0x1.1d1e83e9436d2p-56, -0x1.91919b3ce1b15p-54,
    0x1.59f48a72a4c6dp-55, -0x1.312607a28698ap-54, -0x1.8a78f4817895bp-58, -0x1.c2c9b67499a1bp-56,
    0x1.363ed60c2ac11p-59, 0x1.666093b0664efp-54, 0x1.ecce1daa10379p-57, 0x1.3ff8e3f0f1230p-54,
    0x1.690cebb7aafb0p-56, 0x1.31dbdeb54e077p-54, -0x1.f94340071a38ep-55, -0x1.7deccdc93a349p-55,
    -0x1.8dec6bd0f385fp-56, -0x1.61246ec7b5cf6p-55, 0x1.3350518fdd78ep-54, 0x1.b98b72f8a9b05p-56,
    0x1.063e1e21c5409p-54, 0x1.4c7855019c6eap-60, 0x1.432e62b64c035p-54, -0x1.ce44a6199769fp-55,
    -0x1.c33c53bef4da8p-55, -0x1.45378892be9aep-55, -0x1.3cedd78565858p-54, 0x1.710aa807e1964p-58,
    -0x1.3b3efbf5e2228p-54, -0x1.a12ad8734b982p-57, -0x1.367efb86da9eep-57, -0x1.0dc3d54e08851p-55,
    -0x1.81f647e5a3ecfp-56, -0x1.6ee4ac08b7db0p-55, -0x1.619321e55e68ap-55, 0x1.09ccb5e09d4d3p-54,
    -0x1.b32dcb94da51dp-56, 0x1.4ecfd5467c06bp-54, 0x1.5ebe1abd66c55p-57, -0x1.8a1c52fb3cf42p-55,
    -0x1.369b6f13b3734p-54, -0x1.05e843a19ff1ep-55, -0x1.4d450d872576ep-54, 0x1.0ad675b0e8a00p-54,
    0x1.db72fc1f0eab4p-55, -0x1.5b6609cc5e7ffp-57, 0x1.bf68359f35f44p-56, -0x1.3091fa71e3d83p-54,
    -0x1.da9b88b6c1e29p-58, -0x1.c23f97c90b959p-57, -0x1.2434322f4f9aap-54, -0x1.5ca6cd7668e4bp-55,
    0x1.1affc2b91ce27p-56, 0x1.dd235e10a73bbp-57, -0x1.7c50422622263p-55, 0x1.b1c86e3e231d5p-55,
    -0x1.1bbd1d3bcbb15p-54, 0x1.0cc319cee31d2p-54, 0x1.469846e735ab3p-55, -0x1.2dfcd978e9db4p-55,
    0x1.c1a7792cb3387p-55, -0x1.07b8f4ad1d9fap-54, -0x1.5c3d956dcaebap-58, -0x1.0a40e3da6f640p-54,
    -0x1.8d6f438ad9334p-57, -0x1.1eee26b588a35p-54, 0x1.4ffd70a5fddcdp-56, -0x1.1bdfbfa9298acp-54,
    0x1.36eae30af0cb3p-56, 0x1.ee3325c9ffd94p-55, 0x1.4e08fd10959acp-55, 0x1.3cdaf384e1a67p-57,
    0x1.76b2c6c921968p-57, -0x1.08a1883ccb5d2p-55, -0x1.fad5d3ffffa6fp-55, -0x1.00dae3875a949p-54,
    0x1.4a385a63d07a7p-56, -0x1.2919e2040220fp-55, 0x1.e5a50d5c192acp-55, 0x1.43a59ac016b4bp-55,
    -0x1.2d52107b43e1fp-55, -0x1.92ab93b470dc9p-55, 0x1.4b604603a88d3p-56, 0x1.3c5ec519d7271p-55,
    -0x1.ff7128fd391f0p-55, -0x1.dae98e223747dp-55, 0x1.ec3bc41aa2008p-55, 0x1.42b94c3a9eb32p-55,
    0x1.a64a931d185eep-55, -0x1.e37bae43be3edp-55, 0x1.7893b4d91cd9dp-56, 0x1.305c14160cc89p-58,
};
// clang-format on

/// 1/√x for positive normal x: bit-hack seed (3.4 % worst case) and three
/// Newton steps y ← y(1.5 − ½x y²), each squaring the relative error.
inline double invSqrtNormal(double x) noexcept {
  double y = std::bit_cast<double>(0x5FE6EB50C7B537A9ull - (std::bit_cast<std::uint64_t>(x) >> 1));
  const double h = 0.5 * x;
  y = y * (1.5 - h * y * y);
  y = y * (1.5 - h * y * y);
  y = y * (1.5 - h * y * y);
  return y;
}

inline float invSqrtNormal(float x) noexcept {
  float y = std::bit_cast<float>(0x5F375A86u - (std::bit_cast<std::uint32_t>(x) >> 1));
  const float h = 0.5f * x;
  y = y * (1.5f - h * y * y);
  y = y * (1.5f - h * y * y);
  return y;
}

// Off the fast path: subnormals (rescaled by an even power of two so the
// seed sees a normal number), zeros, infinities, negatives and NaN.
template <class T>
T invSqrtSpecial(T x) noexcept {
  constexpr bool dbl = sizeof(T) == 8;
  constexpr T up = dbl ? T(0x1p108) : T(0x1p48), down = dbl ? T(0x1p54) : T(0x1p24);
  if (x > T(0) && x < std::numeric_limits<T>::min()) return invSqrtNormal(x * up) * down;
  if (x == T(0))
    return std::signbit(x) ? -std::numeric_limits<T>::infinity() : std::numeric_limits<T>::infinity();
  if (x == std::numeric_limits<T>::infinity()) return T(0);
  return std::numeric_limits<T>::quiet_NaN();
}

template <class T>
T sqrtSpecial(T x) noexcept {
  constexpr bool dbl = sizeof(T) == 8;
  constexpr T up = dbl ? T(0x1p108) : T(0x1p48), down = dbl ? T(0x1p-54) : T(0x1p-24);
  if (x > T(0) && x < std::numeric_limits<T>::min()) return (x * up) * invSqrtNormal(x * up) * down;
  if (x == T(0) || x == std::numeric_limits<T>::infinity()) return x;
  return std::numeric_limits<T>::quiet_NaN();
}

/// sin(x + q·π/2) for q = 0 (sin) or 1 (cos): Cody–Waite reduction to
/// r ∈ [−π/4, π/4] with k = round(2x/π), then minimax polynomials (Remez,
/// degree 13 for sin, 14 for cos; both below 2e-18) and a quadrant select by bit masks.
inline double sinQuadrant(double x, std::uint64_t q) noexcept {
  constexpr double kTwoOverPi = 0.63661977236758134308;
  constexpr double kPio2Hi = 1.57079632673412561417e+00;  // π/2 to 33 bits: k·kPio2Hi is exact for |k| < 2^20
  constexpr double kPio2Lo = 6.07710050650619224932e-11;  // π/2 − kPio2Hi
  constexpr double S0 = -1.66666666666666003715e-01, S1 = 8.33333333331648169375e-03,
                   S2 = -1.98412698259341189070e-04, S3 = 2.75573125447745832613e-06,
                   S4 = -2.50506002386490946234e-08, S5 = 1.58885859399412648792e-10;
  constexpr double C0 = 4.16666666666665995562e-02, C1 = -1.38888888888741386498e-03,
                   C2 = 2.48015872894918359848e-05, C3 = -2.75573143552443346466e-07,
                   C4 = 2.08757236847744876686e-09, C5 = -1.13596698855731443139e-11;
  const double t = x * kTwoOverPi + kRoundMagic;
  const double k = t - kRoundMagic;
  const std::uint64_t quadrant = std::bit_cast<std::uint64_t>(t) + q;  // low two bits: (k + q) mod 4
  const double r = (x - k * kPio2Hi) - k * kPio2Lo;
  const double r2 = r * r;
  const double s = r + r * r2 * (S0 + r2 * (S1 + r2 * (S2 + r2 * (S3 + r2 * (S4 + r2 * S5)))));
  const double c =
      (1.0 - 0.5 * r2) + r2 * r2 * (C0 + r2 * (C1 + r2 * (C2 + r2 * (C3 + r2 * (C4 + r2 * C5)))));
  // Odd quadrants take the cosine branch; quadrants 2 and 3 flip the sign.
  const std::uint64_t useCos = 0 - (quadrant & 1u);
  const std::uint64_t bits =
      (std::bit_cast<std::uint64_t>(s) & ~useCos) | (std::bit_cast<std::uint64_t>(c) & useCos);
  return std::bit_cast<double>(bits ^ ((quadrant & 2u) << 62));
}

/// eˣ without the 2^k factor: returns 2^(j/128)·eʳ ∈ [0.99, 2) and n = 128k + j,
/// for |x| ≤ 746.
inline double expMantissa(double x, std::int64_t& n) noexcept {
  constexpr double kScale = 184.6649652337873;       // 128 / ln 2
  constexpr double kLn2Hi = 0x1.62e42feep-8;         // ln2/128 to 32 bits: n·kLn2Hi exact for |n| < 2^21
  constexpr double kLn2Lo = 1.4907929134926466e-12;  // ln2/128 − kLn2Hi
  constexpr double c3 = 1.0 / 6.0, c4 = 1.0 / 24.0, c5 = 1.0 / 120.0;
  const double t = x * kScale + kRoundMagic;
  const double nd = t - kRoundMagic;
  n = static_cast<std::int64_t>(std::bit_cast<std::uint64_t>(t) - std::bit_cast<std::uint64_t>(kRoundMagic));
  const double r = (x - nd * kLn2Hi) - nd * kLn2Lo;
  const double r2 = r * r;
  const auto j = static_cast<std::size_t>(n & 127);
  const double q = r + (r2 * (0.5 + r * c3) + r2 * r2 * (c4 + r * c5)) + kExp2TableLo[j];
  const double hi = kExp2TableHi[j];
  return hi + hi * q;
}

/// eˣ for any x (the edges of fastExp): 2^k = 2^k1 · 2^k2 with k1 = ⌊k/2⌋,
/// each factor a normal double for k ∈ [−1077, 1025], so overflow and
/// underflow (with one rounding into the subnormals) happen in the product.
inline double expWide(double x) noexcept {
  // Clamp so that the exponent stays inside its field; NaN passes through.
  double xc = x < -746.0 ? -746.0 : x;
  xc = xc > 710.0 ? 710.0 : xc;
  std::int64_t n = 0;
  const double m = expMantissa(xc, n);
  const std::int64_t k = n >> 7, k1 = k >> 1, k2 = k - k1;
  const double s1 = std::bit_cast<double>(static_cast<std::uint64_t>(k1 + 1023) << 52);
  const double s2 = std::bit_cast<double>(static_cast<std::uint64_t>(k2 + 1023) << 52);
  return m * s1 * s2;
}

}  // namespace detail

/// Approximate 1/√x. Domain: all positive finite doubles (subnormals are
/// rescaled); max relative error kFastInvSqrtMaxRelError. Edges, as
/// 1/std::sqrt: +0 → +Inf, −0 → −Inf, x < 0 → NaN, NaN → NaN, +Inf → +0.
inline double fastInvSqrt(double x) noexcept {
  if (x >= detail::kDblMin && x <= detail::kDblMax) [[likely]]
    return detail::invSqrtNormal(x);
  return detail::invSqrtSpecial(x);
}

/// Approximate √x as x · fastInvSqrt(x). Domain: all positive finite
/// doubles; max relative error kFastSqrtMaxRelError. Edges, as std::sqrt:
/// ±0 → ±0, +Inf → +Inf, x < 0 → NaN, NaN → NaN (errno is never set).
inline double fastSqrt(double x) noexcept {
  if (x >= detail::kDblMin && x <= detail::kDblMax) [[likely]]
    return x * detail::invSqrtNormal(x);
  return detail::sqrtSpecial(x);
}

/// Float 1/√x (the classic 0x5F375A86 seed, two Newton steps). Domain: all
/// positive finite floats; max relative error kFastInvSqrtMaxRelErrorF.
/// Edges as the double version.
inline float fastInvSqrt(float x) noexcept {
  if (x >= std::numeric_limits<float>::min() && x <= std::numeric_limits<float>::max()) [[likely]]
    return detail::invSqrtNormal(x);
  return detail::invSqrtSpecial(x);
}

/// Float √x; max relative error kFastSqrtMaxRelErrorF. Edges as std::sqrt.
inline float fastSqrt(float x) noexcept {
  if (x >= std::numeric_limits<float>::min() && x <= std::numeric_limits<float>::max()) [[likely]]
    return x * detail::invSqrtNormal(x);
  return detail::sqrtSpecial(x);
}

/// Approximate sin(x), x in radians. Max absolute error kFastSinMaxAbsError
/// for |x| ≤ kFastSinCosDomain (error grows slowly beyond, see the domain
/// note). ±0 → +0 (the sign of a zero is not kept); ±Inf and NaN → NaN.
/// Branch-free.
inline double fastSin(double x) noexcept { return detail::sinQuadrant(x, 0); }

/// Approximate cos(x), x in radians. Max absolute error kFastCosMaxAbsError
/// for |x| ≤ kFastSinCosDomain. cos(0) = 1 exactly; ±Inf and NaN → NaN.
inline double fastCos(double x) noexcept { return detail::sinQuadrant(x, 1); }

/// Approximate eˣ. Max relative error kFastExpMaxRelError for x in
/// [kFastExpMin, kFastExpMax]. Reduction x = (128k + j)·ln2/128 + r with
/// |r| ≤ ln2/256, eˣ = 2^k · 2^(j/128) · eʳ: a 128-entry table (with its
/// rounding error kept as a correction), a degree-5 polynomial for eʳ − 1
/// (Estrin form; truncation 5.5e-19) and 2^k added to the exponent bits
/// (|x| < 708; beyond, as two factors, so results down into the subnormal
/// range and up to DBL_MAX are reached). Edges: x > 709.79 → +Inf (overflow), x < −745.2 → +0, subnormal
/// results (x < −708.4) are within 2 subnormal ulps, exp(0) = 1 exactly,
/// +Inf → +Inf, −Inf → +0, NaN → NaN. errno is never set.
inline double fastExp(double x) noexcept {
  if (std::abs(x) < 708.0) [[likely]] {
    // Result normal and k ∈ [−1022, 1021]: scale by adding k to the exponent.
    std::int64_t n = 0;
    const double m = detail::expMantissa(x, n);
    return std::bit_cast<double>(std::bit_cast<std::uint64_t>(m) +
                                 (static_cast<std::uint64_t>(n >> 7) << 52));
  }
  return detail::expWide(x);
}

}  // namespace dm
