// phantom.cpp — the calvarium phantom and the exact cube–plane partial volume.
#include <dm/math/phantom.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

namespace dm {

namespace {

// Volume of {u ∈ [0,1]³ : m·u < a} for 0 ≤ m0 ≤ m1 ≤ m2, m2 > 0, by
// inclusion–exclusion over the cube's corners (Scardovelli & Zaleski 2000)
// for a ≤ (m0+m1+m2)/2; the other half by symmetry keeps the cancellation
// small. A component below kFlat is taken at its midpoint — the volume
// changes by O(m²) there — and the formula of one dimension less is used,
// so planes parallel to an axis are exact rather than divided by ~0.
constexpr double kFlat = 1e-4;

double cornerVolume(const std::array<double, 3>& m, double a) noexcept {
  auto cube = [](double x) { return x > 0.0 ? x * x * x : 0.0; };
  auto square = [](double x) { return x > 0.0 ? x * x : 0.0; };
  if (m[1] < kFlat) return std::clamp((a - 0.5 * (m[0] + m[1])) / m[2], 0.0, 1.0);
  if (m[0] < kFlat) {
    const double b = a - 0.5 * m[0];
    return (square(b) - square(b - m[1]) - square(b - m[2]) + square(b - m[1] - m[2])) / (2.0 * m[1] * m[2]);
  }
  const double v = cube(a) - cube(a - m[0]) - cube(a - m[1]) - cube(a - m[2]) + cube(a - m[0] - m[1]) +
                   cube(a - m[0] - m[2]) + cube(a - m[1] - m[2]) - cube(a - m[0] - m[1] - m[2]);
  return v / (6.0 * m[0] * m[1] * m[2]);
}

// Smooth value noise in [−1, 1]: a hashed value at each lattice point,
// interpolated with smoothstep weights. Deterministic (integer hash only).
double valueNoise(const Vec3& p, std::uint32_t seed) noexcept {
  auto hash = [seed](std::int64_t i, std::int64_t j, std::int64_t k) {
    std::uint64_t x = static_cast<std::uint64_t>(i) * 0x9E3779B97F4A7C15ull ^
                      static_cast<std::uint64_t>(j) * 0xC2B2AE3D27D4EB4Full ^
                      static_cast<std::uint64_t>(k) * 0x165667B19E3779F9ull ^
                      (std::uint64_t{seed} << 32 | seed);
    x ^= x >> 33;
    x *= 0xFF51AFD7ED558CCDull;
    x ^= x >> 33;
    x *= 0xC4CEB9FE1A85EC53ull;
    x ^= x >> 33;
    return static_cast<double>(x >> 11) * (2.0 / 9007199254740992.0) - 1.0;  // 53 bits → [−1, 1)
  };
  const Vec3 f = p.array().floor();
  const Vec3 t = p - f;
  const Vec3 w = t.array() * t.array() * (3.0 - 2.0 * t.array());
  const auto i = static_cast<std::int64_t>(f.x()), j = static_cast<std::int64_t>(f.y()),
             k = static_cast<std::int64_t>(f.z());
  double sum = 0.0;
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const double weight =
        (dx ? w.x() : 1.0 - w.x()) * (dy ? w.y() : 1.0 - w.y()) * (dz ? w.z() : 1.0 - w.z());
    sum += weight * hash(i + dx, j + dy, k + dz);
  }
  return sum;
}

}  // namespace

double cubeFractionBelowPlane(const Vec3& centre, double h, const Vec3& n, double offset) noexcept {
  // In the cube's unit coordinates u ∈ [0,1]³ with every normal component
  // made non-negative by reflection: n·x < offset ⇔ m·u < a.
  std::array<double, 3> m{std::abs(n.x()), std::abs(n.y()), std::abs(n.z())};
  std::sort(m.begin(), m.end());
  if (!(m[2] > 0.0)) return 0.0;  // not a plane (zero or NaN normal)
  const double total = m[0] + m[1] + m[2];
  const double a = (offset - n.dot(centre)) / h + 0.5 * total;
  if (!(a > 0.0)) return 0.0;  // NaN too
  if (a >= total) return 1.0;
  return a <= 0.5 * total ? cornerVolume(m, a) : 1.0 - cornerVolume(m, total - a);
}

Status validate(const CalvariumPhantom& p) {
  auto bad = [](const char* field, const std::string& what) {
    return fail(ErrorCode::InvalidArgument, std::string(field) + " " + what, field);
  };
  const std::pair<const char*, double> lengths[] = {{"spacing", p.spacing},
                                                    {"halfWidth", p.halfWidth},
                                                    {"above", p.above},
                                                    {"below", p.below},
                                                    {"radius", p.radius},
                                                    {"scalp", p.scalp},
                                                    {"outerTable", p.outerTable},
                                                    {"diploe", p.diploe},
                                                    {"innerTable", p.innerTable},
                                                    {"dura", p.dura},
                                                    {"textureScale", p.textureScale},
                                                    {"textureHu", p.textureHu}};
  for (const auto& [field, v] : lengths)
    if (!std::isfinite(v) || v < 0.0) return bad(field, "must be finite and ≥ 0");
  const std::pair<const char*, double> positive[] = {
      {"spacing", p.spacing},       {"halfWidth", p.halfWidth},   {"below", p.below},
      {"outerTable", p.outerTable}, {"innerTable", p.innerTable}, {"textureScale", p.textureScale}};
  for (const auto& [field, v] : positive)
    if (!(v > 0.0)) return bad(field, "must be > 0");
  const std::pair<const char*, double> values[] = {
      {"airHu", p.airHu},           {"softTissueHu", p.softTissueHu},
      {"corticalHu", p.corticalHu}, {"diploeHu", p.diploeHu},
      {"duraHu", p.duraHu},         {"brainHu", p.brainHu}};
  for (const auto& [field, v] : values)
    if (!std::isfinite(v)) return bad(field, "must be finite");
  if (!(p.radius > p.halfWidth))
    return bad("radius", "must exceed the half width (the patch is a part of the vault)");
  if (!(p.radius > p.outerTable + p.diploe + p.innerTable + p.dura + p.spacing))
    return bad("radius", "must exceed the layers' total thickness plus a voxel");
  if (p.spacing > p.halfWidth) return bad("spacing", "must not exceed the half width");
  // The texture's lattice index of a point must stay far inside 64 bits.
  if (p.textureScale < 1e-6) return bad("textureScale", "must be at least 1e-6 m");
  return {};
}

Vec3i calvariumPhantomDims(const CalvariumPhantom& p) noexcept {
  auto count = [&](double length) {
    return static_cast<int>(std::clamp(std::round(length / p.spacing), 1.0, 2147483647.0));
  };
  const int across = count(2.0 * p.halfWidth);
  return {across, across, count(p.above + p.below)};
}

Result<Volume> makeCalvariumPhantom(const CalvariumPhantom& p, std::size_t maxBytes) {
  if (auto s = validate(p); !s) return s.error();
  const double h = p.spacing;
  const Vec3i dims = calvariumPhantomDims(p);
  const int nxy = dims.x(), nz = dims.z();
  Affine3 indexToWorld = Affine3::Identity();
  indexToWorld.linear() = Mat3::Identity() * h;
  indexToWorld.translation() = Vec3(-0.5 * (nxy - 1) * h, -0.5 * (nxy - 1) * h, -p.below + 0.5 * h);
  auto out = Volume::create(dims, VoxelType::I16, indexToWorld, maxBytes);
  if (!out) return out.error().within("phantom");

  // Layer boundaries (radii about c), outermost first, and the value of the
  // layer inside each one.
  const Vec3 c(0.0, 0.0, -p.radius);
  const double r1 = p.radius, r2 = r1 - p.outerTable, r3 = r2 - p.diploe, r4 = r3 - p.innerTable,
               r5 = r4 - p.dura;
  const double r0 = r1 + p.scalp;
  const double reach = 0.87 * h;  // a voxel's half diagonal: farther, it lies in one layer
  std::int16_t* data = out->data<std::int16_t>();
  std::size_t v = 0;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < nxy; ++j)
      for (int i = 0; i < nxy; ++i, ++v) {
        const Vec3 x = indexToWorld * Vec3(i, j, k);
        const Vec3 d = x - c;
        const double r = d.norm();
        const Vec3 n = d / r;
        // Fraction of the voxel inside the sphere of radius rho.
        auto inside = [&](double rho) {
          if (r + reach <= rho) return 1.0;
          if (r - reach >= rho) return 0.0;
          return cubeFractionBelowPlane(x, h, n, rho + n.dot(c));
        };
        const double f0 = inside(r0), f1 = inside(r1), f2 = inside(r2), f3 = inside(r3), f4 = inside(r4),
                     f5 = inside(r5);
        double diploeHu = p.diploeHu;
        if (f2 > f3 && p.textureHu > 0.0) diploeHu += p.textureHu * valueNoise(x / p.textureScale, p.seed);
        const double value = (1.0 - f0) * p.airHu + (f0 - f1) * p.softTissueHu + (f1 - f2) * p.corticalHu +
                             (f2 - f3) * diploeHu + (f3 - f4) * p.corticalHu + (f4 - f5) * p.duraHu +
                             f5 * p.brainHu;
        data[v] = static_cast<std::int16_t>(std::clamp(std::lround(value), -32768L, 32767L));
      }
  return out;
}

}  // namespace dm
