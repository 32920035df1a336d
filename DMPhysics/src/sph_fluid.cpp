// sph_fluid.cpp — DFSPH: the density and divergence solves, viscosity,
// surface tension and boundary particles (dm/physics/sph_fluid.hpp).
#include <dm/core/tasks.hpp>
#include <dm/physics/sph_fluid.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>
#include <string>
#include <tuple>

namespace dm {

namespace {

constexpr std::size_t kGrain = 256;
// A particle with fewer neighbours than this is at a free surface or alone:
// the divergence solve leaves it (Bender & Koschier 2017).
constexpr std::size_t kMinNeighboursForDivergence = 20;
// The share of the last solve's pressure a solve starts from (as
// SPlisHSPlasH's DFSPH): all of it overshoots when the flow changes.
constexpr double kWarmShare = 0.5;

// The coordinates of a vector of Vec3 as one flat array of doubles (a
// Vec3 is three packed doubles). The loops over particle pairs below work on
// plain doubles: the same machine code as Eigen's at -O2, while a sanitizer
// build at -O1 would call a function per Eigen expression (15 times the
// plain time, where ASan's usual cost is 2: docs/build-time.md).
static_assert(sizeof(Vec3) == 3 * sizeof(double));
double* coords(std::vector<Vec3>& v) noexcept { return reinterpret_cast<double*>(v.data()); }

// Monaghan's (2005) viscous acceleration of particle i from j (a fluid
// particle of volume V_j, or a wall particle of Ψ_j/ρ0 moving with its
// body) is this factor times ∇W_ij, with c = 10 ν V_j; eps2 = 0.01 h² keeps
// it finite for close pairs.
inline double viscousFactor(double c, const double* r, const double* vi, const double* vj, double eps2) {
  const double vr = (vi[0] - vj[0]) * r[0] + (vi[1] - vj[1]) * r[1] + (vi[2] - vj[2]) * r[2];
  return c * vr / (r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + eps2);
}

double serialMean(const std::vector<double>& values, std::size_t n) {
  double sum = 0.0;
  for (std::size_t i = 0; i < n; ++i) sum += values[i];
  return n == 0 ? 0.0 : sum / double(n);
}

}  // namespace

Result<SphFluid> SphFluid::create(const SphFluidOptions& o) {
  const auto bad = [](const char* what, double v, const char* hint) {
    return fail(ErrorCode::InvalidArgument, formatString("%s is %g", what, v),
                std::string("SphFluidOptions.") + what, hint);
  };
  if (!(o.particleSpacing > 0.0) || !std::isfinite(o.particleSpacing))
    return bad("particleSpacing", o.particleSpacing, "a spacing in metres, e.g. 0.005");
  if (!(o.restDensity > 0.0) || !std::isfinite(o.restDensity))
    return bad("restDensity", o.restDensity, "kg/m³, e.g. 1000 for water, 1060 for blood");
  if (!(o.viscosity >= 0.0) || !std::isfinite(o.viscosity))
    return bad("viscosity", o.viscosity, "a kinematic viscosity in m²/s, ≥ 0");
  if (!(o.surfaceTension >= 0.0) || !std::isfinite(o.surfaceTension))
    return bad("surfaceTension", o.surfaceTension, "≥ 0");
  if (!o.gravity.allFinite())
    return fail(ErrorCode::InvalidArgument, "gravity is not finite", "SphFluidOptions.gravity");
  if (!(o.maxDensityError > 0.0) || !std::isfinite(o.maxDensityError))
    return bad("maxDensityError", o.maxDensityError, "a relative error, e.g. 0.001");
  if (!(o.maxDivergenceError > 0.0) || !std::isfinite(o.maxDivergenceError))
    return bad("maxDivergenceError", o.maxDivergenceError, "a relative error, e.g. 0.001");
  if (o.minIterations < 1 || o.maxIterations < o.minIterations)
    return bad("maxIterations", o.maxIterations, "1 ≤ minIterations ≤ maxIterations");
  if (!(o.cfl > 0.0) || !(o.cfl <= 1.0)) return bad("cfl", o.cfl, "in (0, 1]");
  if (!(o.relaxation > 0.0) || !(o.relaxation <= 1.0)) return bad("relaxation", o.relaxation, "in (0, 1]");
  if (o.maxSubSteps < 1) return bad("maxSubSteps", o.maxSubSteps, "≥ 1");
  return SphFluid(o);
}

SphFluid::SphFluid(const SphFluidOptions& o) : o_(o) {
  const double d = o.particleSpacing;
  h_ = 2.0 * d;
  kernelScale_ = 8.0 / (std::numbers::pi * h_ * h_ * h_);
  // The mass that gives a full cubic lattice exactly the rest density.
  double sum = 0.0;
  for (int z = -2; z <= 2; ++z)
    for (int y = -2; y <= 2; ++y)
      for (int x = -2; x <= 2; ++x) sum += kernel(d * std::sqrt(double(x * x + y * y + z * z)));
  mass_ = o.restDensity / sum;
  // Akinci's boundary volume 1 / Σ_k W_bk makes a wall sampled at spacing d
  // weigh as its plane's kernel sum says, while the fluid it stands for (the
  // missing lattice layer one spacing away) weighs as the full lattice's:
  // scaled by their ratio, a flat wall at spacing d gives the fluid next to
  // it exactly the rest density (without it, 6 % too much at a wall, 13 %
  // at an edge and 19 % in a corner, which the first steps blow apart).
  double plane = 0.0;
  for (int y = -2; y <= 2; ++y)
    for (int x = -2; x <= 2; ++x) plane += kernel(d * std::sqrt(double(x * x + y * y)));
  boundaryScale_ = plane / sum;
}

double SphFluid::kernel(double r) const noexcept {
  const double q = r / h_;
  if (q >= 1.0) return 0.0;
  if (q <= 0.5) return kernelScale_ * (6.0 * (q * q * q - q * q) + 1.0);
  const double u = 1.0 - q;
  return kernelScale_ * 2.0 * u * u * u;
}

double SphFluid::gradientScale(double len) const noexcept {
  const double q = len / h_;
  if (q >= 1.0 || len <= 1e-12 * h_) return 0.0;
  const double dw = q <= 0.5 ? kernelScale_ / h_ * (18.0 * q * q - 12.0 * q)
                             : kernelScale_ / h_ * (-6.0 * (1.0 - q) * (1.0 - q));
  return dw / len;
}

std::size_t SphFluid::addBlock(const Vec3& lo, const Vec3& hi, const Vec3& velocity) {
  const double d = o_.particleSpacing;
  std::vector<Vec3> points;
  for (double z = lo.z() + 0.5 * d; z < hi.z() - 1e-9 * d; z += d)
    for (double y = lo.y() + 0.5 * d; y < hi.y() - 1e-9 * d; y += d)
      for (double x = lo.x() + 0.5 * d; x < hi.x() - 1e-9 * d; x += d) points.emplace_back(x, y, z);
  addParticles(points, velocity);
  return points.size();
}

void SphFluid::addParticles(std::span<const Vec3> positions, const Vec3& velocity) {
  x_.insert(x_.end(), positions.begin(), positions.end());
  v_.insert(v_.end(), positions.size(), velocity);
  rho_.clear();  // stale: refreshed at the next step
}

void SphFluid::addBoundaryParticles(std::span<const Vec3> positions) {
  bx_.insert(bx_.end(), positions.begin(), positions.end());
  boundaryDirty_ = true;
  rho_.clear();
  layOutBoundaryVelocities();  // the moving particles' velocities come after the static ones
}

std::size_t SphFluid::addBoxBoundary(const Vec3& inner, const Vec3& upper) {
  // The walls' particles lie half a spacing outside the fluid's space, as a
  // fluid particle's centre lies half a spacing inside it (addBlock): one
  // spacing apart, as in the fluid.
  const double d = o_.particleSpacing;
  const Vec3 lo = inner - Vec3::Constant(0.5 * d);
  const Vec3 hi(upper.x() + 0.5 * d, upper.y() + 0.5 * d, upper.z());
  const auto count = [&](int a) { return std::max(1, int(std::lround((hi[a] - lo[a]) / d))); };
  const int nx = count(0), ny = count(1), nz = count(2);
  std::set<std::tuple<int, int, int>> cells;  // lattice points on the five walls, once each
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i)
        if (k == 0 || i == 0 || i == nx || j == 0 || j == ny) cells.emplace(i, j, k);
  std::vector<Vec3> points;
  points.reserve(cells.size());
  for (const auto& [i, j, k] : cells)
    points.emplace_back(lo.x() + (hi.x() - lo.x()) * i / nx, lo.y() + (hi.y() - lo.y()) * j / ny,
                        lo.z() + (hi.z() - lo.z()) * k / nz);
  addBoundaryParticles(points);
  return points.size();
}

Result<std::size_t> SphFluid::addRigidBoundary(std::span<const Vec3> bodyPoints, const Isometry3& pose) {
  const std::string where = "SphFluid::addRigidBoundary";
  if (bodyPoints.empty())
    return fail(ErrorCode::InvalidArgument, "no boundary particles", where,
                "sample the body's surface, e.g. dm::sampleBoundary(mesh, d, d / 3)");
  for (std::size_t q = 0; q < bodyPoints.size(); ++q)
    if (!bodyPoints[q].allFinite())
      return fail(ErrorCode::InvalidArgument, formatString("point %zu is not finite", q), where);
  if (!pose.matrix().allFinite()) return fail(ErrorCode::InvalidArgument, "the pose is not finite", where);
  Rigid body;
  body.local.assign(bodyPoints.begin(), bodyPoints.end());
  body.first = rx_.size();
  body.pose = pose;
  rigid_.push_back(std::move(body));
  addMoving(bodyPoints.size());
  // Ψ from the body's own particles (it keeps its shape, so once).
  OwnPairs own;
  ownVolumes(rigid_.back().first, bodyPoints.size(), own);
  return rigid_.size() - 1;
}

Result<std::size_t> SphFluid::addSurfaceBoundary(BoundarySurface samples, std::span<const Vec3> vertices) {
  const std::string where = "SphFluid::addSurfaceBoundary";
  if (samples.size() == 0)
    return fail(ErrorCode::InvalidArgument, "the surface has no samples", where,
                "dm::BoundarySurface::create(mesh, d, d / 3) of a mesh with triangles");
  if (vertices.size() != samples.vertexCount())
    return fail(ErrorCode::InvalidArgument,
                formatString("%zu vertices for a surface of %zu", vertices.size(), samples.vertexCount()),
                where);
  for (std::size_t v = 0; v < vertices.size(); ++v)
    if (!vertices[v].allFinite())
      return fail(ErrorCode::InvalidArgument, formatString("vertex %zu is not finite", v), where);
  Surface surface{.samples = std::move(samples), .first = rx_.size()};
  const std::size_t n = surface.samples.vertexCount();
  surface.vertices.assign(vertices.begin(), vertices.end());
  surface.velocities.assign(n, Vec3::Zero());
  surface.impulse.assign(n, Vec3::Zero());
  surface.load.assign(n, Vec3::Zero());
  const std::size_t count = surface.samples.size();
  surfaces_.push_back(std::move(surface));
  addMoving(count);
  return surfaces_.size() - 1;
}

Status SphFluid::setSurfaceState(std::size_t surface, std::span<const Vec3> vertices,
                                 std::span<const Vec3> velocities) {
  const std::string where = "SphFluid::setSurfaceState";
  if (surface >= surfaces_.size())
    return fail(ErrorCode::InvalidArgument, formatString("surface %zu of %zu", surface, surfaces_.size()),
                where);
  Surface& sf = surfaces_[surface];
  const std::size_t n = sf.vertices.size();
  if (vertices.size() != n || velocities.size() != n)
    return fail(ErrorCode::InvalidArgument,
                formatString("surface %zu: %zu vertices and %zu velocities for its %zu vertices", surface,
                             vertices.size(), velocities.size(), n),
                where);
  for (std::size_t v = 0; v < n; ++v)
    if (!vertices[v].allFinite() || !velocities[v].allFinite())
      return fail(ErrorCode::InvalidArgument,
                  formatString("surface %zu: vertex %zu is not finite", surface, v), where);
  std::copy(vertices.begin(), vertices.end(), sf.vertices.begin());
  std::copy(velocities.begin(), velocities.end(), sf.velocities.begin());
  placeSurface(surface);
  boundaryMoved_ = true;  // neighbours and densities again at the next step
  return ok();
}

Status SphFluid::setRigidState(std::size_t body, const Isometry3& pose, const Vec3& linearVelocity,
                               const Vec3& angularVelocity) {
  const std::string where = "SphFluid::setRigidState";
  if (body >= rigid_.size())
    return fail(ErrorCode::InvalidArgument, formatString("body %zu of %zu", body, rigid_.size()), where);
  if (!pose.matrix().allFinite() || !linearVelocity.allFinite() || !angularVelocity.allFinite())
    return fail(ErrorCode::InvalidArgument, formatString("body %zu: a non-finite pose or velocity", body),
                where);
  Rigid& r = rigid_[body];
  r.pose = pose;
  r.v = linearVelocity;
  r.w = angularVelocity;
  placeRigid(body);
  boundaryMoved_ = true;  // neighbours and densities again at the next step
  return ok();
}

void SphFluid::addMoving(std::size_t count) {
  rx_.resize(rx_.size() + count);
  rpsi_.resize(rx_.size());
  rimp_.resize(rx_.size(), Vec3::Zero());
  boundaryDirty_ = true;
  rho_.clear();
  layOutBoundaryVelocities();  // places the new owner's particles too
}

void SphFluid::layOutBoundaryVelocities() {
  bv_.assign(bx_.size() + rx_.size(), Vec3::Zero());
  for (std::size_t k = 0; k < rigid_.size(); ++k) placeRigid(k);
  for (std::size_t k = 0; k < surfaces_.size(); ++k) placeSurface(k);
}

void SphFluid::ownVolumes(std::size_t first, std::size_t count, OwnPairs& own) {
  const std::span<const Vec3> x(rx_.data() + first, count);
  // The list holds every pair within h + skin. With c any common motion
  // (the mean), a pair at ≥ h + skin when listed is now at least
  // h + skin − |Δx_i − c| − |Δx_j − c| apart: beyond the kernel's support
  // while every particle's |Δx − c| < skin / 2. A surface that moves or
  // strains slowly is listed again every few dozen steps.
  const double skin = 0.25 * h_;
  bool fresh = own.listedAt.size() == count;
  if (fresh) {
    Vec3 c = Vec3::Zero();
    for (std::size_t q = 0; q < count; ++q) c += x[q] - own.listedAt[q];
    c /= double(count);
    double worst = 0.0;
    for (std::size_t q = 0; q < count; ++q)
      worst = std::max(worst, (x[q] - own.listedAt[q] - c).squaredNorm());
    fresh = 4.0 * worst < skin * skin;
  }
  if (!fresh) {
    ownGrid_.build(x, h_ + skin);
    own.pairs.clear();
    for (std::size_t i = 0; i < count; ++i)
      for (const std::uint32_t j : ownGrid_.neighbors(i))
        if (j > i) {
          own.pairs.push_back(static_cast<std::uint32_t>(i));
          own.pairs.push_back(j);
        }
    own.listedAt.assign(x.begin(), x.end());
  }
  // Σ_k W(x_b − x_k), b itself included, each pair's W once for both.
  // (Most of a step's time when a surface is densely sampled: a pair out of
  // reach costs a squared distance only.)
  ownSum_.assign(count, kernel(0.0));
  const double h2 = h_ * h_;
  for (std::size_t p = 0; p < own.pairs.size(); p += 2) {
    const std::uint32_t i = own.pairs[p], j = own.pairs[p + 1];
    const double r2 = (x[i] - x[j]).squaredNorm();
    if (r2 >= h2) continue;
    const double w = kernel(std::sqrt(r2));
    ownSum_[i] += w;
    ownSum_[j] += w;
  }
  for (std::size_t q = 0; q < count; ++q) rpsi_[first + q] = o_.restDensity * boundaryScale_ / ownSum_[q];
}

void SphFluid::placeSurface(std::size_t surface) {
  Surface& sf = surfaces_[surface];
  const std::size_t count = sf.samples.size();
  sf.samples.place(sf.vertices, std::span<Vec3>(rx_.data() + sf.first, count));
  sf.samples.interpolate(sf.velocities, std::span<Vec3>(bv_.data() + bx_.size() + sf.first, count));
  ownVolumes(sf.first, count, sf.own);
}

void SphFluid::placeRigid(std::size_t body) {
  const std::size_t nb = bx_.size();
  const Rigid& r = rigid_[body];
  const Vec3 origin = r.pose.translation();
  for (std::size_t q = 0; q < r.local.size(); ++q) {
    const Vec3 x = r.pose * r.local[q];
    rx_[r.first + q] = x;
    bv_[nb + r.first + q] = r.v + r.w.cross(x - origin);
  }
}

void SphFluid::moveBoundaries(double dt) {
  for (std::size_t k = 0; k < rigid_.size(); ++k) {
    Rigid& r = rigid_[k];
    if (r.v.squaredNorm() == 0.0 && r.w.squaredNorm() == 0.0) continue;
    const double angle = r.w.norm() * dt;
    if (angle > 0.0) r.pose.linear() = (AngleAxis(angle, r.w.normalized()) * r.pose.linear()).eval();
    r.pose.translation() += dt * r.v;
    placeRigid(k);
  }
  // A surface's samples on at their velocities (the next setSurfaceState
  // places them on the vertices again); their Ψ stay.
  const std::size_t nb = bx_.size();
  for (const Surface& sf : surfaces_)
    for (std::size_t q = sf.first; q < sf.first + sf.samples.size(); ++q) rx_[q] += dt * bv_[nb + q];
}

void SphFluid::neighbours() {
  const std::size_t nf = x_.size(), nb = bx_.size();
  all_.resize(nf + nb + rx_.size());
  std::copy(x_.begin(), x_.end(), all_.begin());
  std::copy(bx_.begin(), bx_.end(), all_.begin() + std::ptrdiff_t(nf));
  std::copy(rx_.begin(), rx_.end(), all_.begin() + std::ptrdiff_t(nf + nb));
  grid_.build(all_, h_, nf);  // lists for the fluid; boundary particles have none
}

void SphFluid::densitiesAndFactors() {
  const std::size_t nf = x_.size();
  rho_.resize(nf);
  alpha_.resize(nf);
  // ∇W of every listed pair of a fluid particle, in list order (the solves
  // iterate over them many times per sub-step).
  grad_.resize(nf == 0 ? 0 : 3 * grid_.listOffset(nf));
  const double* X = coords(all_);  // the fluid's positions first
  parallelFor(0, nf, kGrain, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      double rho = mass_ * kernel(0.0);
      double sx = 0.0, sy = 0.0, sz = 0.0, sumSq = 0.0;  // Σ m ∇W (ψ at the boundary), Σ |m ∇W|²
      double* grad = grad_.data() + 3 * grid_.listOffset(i);
      const double xi0 = X[3 * i], xi1 = X[3 * i + 1], xi2 = X[3 * i + 2];
      for (std::uint32_t j : grid_.neighbors(i)) {
        const double* xj = X + 3 * std::size_t(j);
        const double rx = xi0 - xj[0], ry = xi1 - xj[1], rz = xi2 - xj[2];
        const double len = std::sqrt(rx * rx + ry * ry + rz * rz);
        const double w = kernel(len), f = gradientScale(len);
        const double gx = f * rx, gy = f * ry, gz = f * rz;
        grad[0] = gx;
        grad[1] = gy;
        grad[2] = gz;
        grad += 3;
        const double m = j < nf ? mass_ : bpsi_[j - nf];
        rho += m * w;
        sx += m * gx;
        sy += m * gy;
        sz += m * gz;
        if (j < nf) sumSq += mass_ * mass_ * (gx * gx + gy * gy + gz * gz);
      }
      rho_[i] = rho;
      const double denom = sx * sx + sy * sy + sz * sz + sumSq;
      alpha_[i] = denom > 1e-6 * mass_ * mass_ / (h_ * h_ * h_ * h_ * h_ * h_ * h_ * h_) ? rho / denom : 0.0;
    }
  });
}

void SphFluid::refresh() {
  boundaryMoved_ = false;
  neighbours();
  const std::size_t nf = x_.size();
  const std::size_t nb = bx_.size();
  if (boundaryDirty_ || bpsi_.size() != nb + rx_.size()) {
    // Akinci's boundary volume: 1 / Σ_k W_bk over the static boundary
    // particles (a moving body's or surface's come from its own: ownVolumes).
    bpsi_.resize(nb + rx_.size());
    for (std::size_t b = 0; b < nb; ++b) {
      double sum = 0.0;  // (itself included: it is within the radius)
      grid_.forEachWithin(bx_[b], [&](std::uint32_t k) {
        if (k >= nf && k < nf + nb) sum += kernel((bx_[b] - all_[k]).norm());
      });
      bpsi_[b] = o_.restDensity * boundaryScale_ / sum;
    }
    if (bv_.size() != nb + rx_.size()) layOutBoundaryVelocities();
    boundaryDirty_ = false;
  }
  std::copy(rpsi_.begin(), rpsi_.end(),
            bpsi_.begin() + std::ptrdiff_t(nb));  // a surface's change as it moves
  densitiesAndFactors();
}

void SphFluid::nonPressure(double dt) {
  const std::size_t nf = x_.size();
  const double gamma = o_.surfaceTension, nu = o_.viscosity, rho0 = o_.restDensity;
  normal_.resize(gamma > 0.0 ? nf : 0);
  double* N = coords(normal_);
  if (gamma > 0.0)
    parallelFor(0, nf, kGrain, [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) {
        double nx = 0.0, ny = 0.0, nz = 0.0;
        const double* grad = grad_.data() + 3 * grid_.listOffset(i);
        for (std::uint32_t j : grid_.neighbors(i)) {
          if (j < nf) {
            const double k = mass_ / rho_[j];
            nx += k * grad[0];
            ny += k * grad[1];
            nz += k * grad[2];
          }
          grad += 3;
        }
        N[3 * i] = h_ * nx;
        N[3 * i + 1] = h_ * ny;
        N[3 * i + 2] = h_ * nz;
      }
    });
  // Akinci's cohesion spline, normalised for support h.
  const double h = h_, cScale = 32.0 / (std::numbers::pi * std::pow(h, 9.0)), h6 = std::pow(h, 6.0);
  const auto cohesion = [&](double r) {
    if (r >= h || r <= 0.0) return 0.0;
    const double a = (h - r) * (h - r) * (h - r) * r * r * r;
    return cScale * (2.0 * r > h ? a : 2.0 * a - h6 / 64.0);
  };
  a_.resize(nf);
  const double* X = coords(all_);
  const double* V = coords(v_);
  const double* BV = coords(bv_);
  double* A = coords(a_);
  parallelFor(0, nf, kGrain, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      double a[3] = {o_.gravity.x(), o_.gravity.y(), o_.gravity.z()};
      const double* grad = grad_.data() + 3 * grid_.listOffset(i);
      const double* xi = X + 3 * i;
      const double* vi = V + 3 * i;
      for (std::uint32_t j : grid_.neighbors(i)) {
        const double* xj = X + 3 * std::size_t(j);
        const double r[3] = {xi[0] - xj[0], xi[1] - xj[1], xi[2] - xj[2]};
        const double r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
        const double* g = grad;
        grad += 3;
        if (j < nf) {
          const double* vj = V + 3 * std::size_t(j);
          if (nu > 0.0) {
            const double k = viscousFactor(10.0 * nu * (mass_ / rho_[j]), r, vi, vj, 0.01 * h * h);
            for (int c = 0; c < 3; ++c) a[c] += k * g[c];
          }
          if (gamma > 0.0) {
            const double len = std::sqrt(r2);
            const double k = gamma * 2.0 * rho0 / (rho_[i] + rho_[j]);
            const double c = len > 1e-12 * h ? mass_ * cohesion(len) / len : 0.0;
            const double* ni = N + 3 * i;
            const double* nj = N + 3 * std::size_t(j);
            for (int d = 0; d < 3; ++d) a[d] -= k * (ni[d] - nj[d] + c * r[d]);
          }
        } else if (nu > 0.0) {  // no-slip walls, moving with their body
          const double* vb = BV + 3 * std::size_t(j - nf);
          const double k = viscousFactor(10.0 * nu * (bpsi_[j - nf] / rho0), r, vi, vb, 0.01 * h * h);
          for (int c = 0; c < 3; ++c) a[c] += k * g[c];
        }
      }
      for (int c = 0; c < 3; ++c) A[3 * i + c] = a[c];
    }
  });
  if (nu > 0.0 && !rx_.empty()) viscousReaction(dt);
  parallelFor(0, nf, kGrain, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) v_[i] += dt * a_[i];
  });
}

// Every pair of a fluid particle and a moving boundary particle, serially
// (a reproducible sum): rimp_[q] of moving particle q gets impulse(i, j, g),
// g the pair's ∇W_ij.
template <class PairImpulse>
void SphFluid::reactionWalk(PairImpulse&& impulse) {
  const std::size_t nf = x_.size(), first = nf + bx_.size();
  for (std::size_t i = 0; i < nf; ++i) {
    if (!touchesMoving(i)) continue;
    const double* g = grad_.data() + 3 * grid_.listOffset(i);
    for (std::uint32_t j : grid_.neighbors(i)) {
      if (j >= first) rimp_[j - first] += impulse(i, j, g);
      g += 3;
    }
  }
  collectReactions();
}

// The walk's impulses to their owners: a body's sum and moment about its
// frame's origin, a surface's spread onto its vertices.
void SphFluid::collectReactions() {
  for (Rigid& body : rigid_) {
    const Vec3 origin = body.pose.translation();
    for (std::size_t q = body.first; q < body.first + body.local.size(); ++q) {
      body.impulse += rimp_[q];
      body.angularImpulse += (rx_[q] - origin).cross(rimp_[q]);
    }
  }
  for (Surface& sf : surfaces_)
    sf.samples.spread(std::span<const Vec3>(rimp_.data() + sf.first, sf.samples.size()), sf.impulse);
  std::fill(rimp_.begin(), rimp_.end(), Vec3::Zero());
}

// The no-slip viscosity's pairs once more: the moving particle gets what
// the fluid particle got, opposite.
void SphFluid::viscousReaction(double dt) {
  const std::size_t nf = x_.size();
  const double c = 10.0 * o_.viscosity / o_.restDensity, eps2 = 0.01 * h_ * h_;
  const double* X = coords(all_);
  const double* V = coords(v_);
  const double* BV = coords(bv_);
  reactionWalk([&](std::size_t i, std::uint32_t j, const double* g) {
    const double* xi = X + 3 * i;
    const double* xj = X + 3 * std::size_t(j);
    const double r[3] = {xi[0] - xj[0], xi[1] - xj[1], xi[2] - xj[2]};
    const double k = viscousFactor(c * bpsi_[j - nf], r, V + 3 * i, BV + 3 * std::size_t(j - nf), eps2);
    return Vec3(-mass_ * dt * k * Vec3(g[0], g[1], g[2]));
  });
}

// What the solve that just ended gave the fluid through the moving
// particles (κ summed over its iterations: the gradients and densities were
// fixed within it), to them, opposite.
void SphFluid::pressureReaction(double dt) {
  const std::size_t nf = x_.size();
  reactionWalk([&](std::size_t i, std::uint32_t j, const double* g) {
    return Vec3(dt * mass_ * bpsi_[j - nf] * (kappaSum_[i] / rho_[i]) * Vec3(g[0], g[1], g[2]));
  });
}

// One pressure solve (see the file comment): the density solve drives the
// predicted compression to zero, the divergence solve its rate of change.
// Warm-started with the κ its last solve of the same kind ended with (kept
// as κ·dt² or κ·dt, which do not depend on the step): the hydrostatic
// pressure of a deep column would otherwise take Jacobi iterations in the
// square of its depth in particles to build up again every step.
int SphFluid::pressureSolve(double dt, bool density) {
  const std::size_t nf = x_.size();
  const double rho0 = o_.restDensity;
  std::vector<double>& warm = density ? warmDensity_ : warmDivergence_;
  const double keep = density ? dt * dt : dt;
  warm.resize(nf, 0.0);  // particles added since: none
  kappa_.resize(nf);
  kappaOverRho_.resize(nf);
  error_.resize(nf);
  kappaSum_.assign(nf, 0.0);
  // Δv_i = −dt Σ_j m (κ_i/ρ_i + κ_j/ρ_j) ∇W_ij (a boundary: κ_i/ρ_i alone).
  // The passes read κ/ρ of the neighbours (set with κ, one array) and write
  // only their own particle's entries, so each runs in one parallel loop.
  double* V = coords(v_);
  const double* BV = coords(bv_);
  const auto apply = [&] {
    parallelFor(0, nf, kGrain, [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) {
        const double ki = kappaOverRho_[i];
        double dx = 0.0, dy = 0.0, dz = 0.0;
        const double* g = grad_.data() + 3 * grid_.listOffset(i);
        for (std::uint32_t j : grid_.neighbors(i)) {
          const double k = j < nf ? mass_ * (ki + kappaOverRho_[j]) : bpsi_[j - nf] * ki;
          dx += k * g[0];
          dy += k * g[1];
          dz += k * g[2];
          g += 3;
        }
        V[3 * i] += -dt * dx;
        V[3 * i + 1] += -dt * dy;
        V[3 * i + 2] += -dt * dz;
        kappaSum_[i] += kappa_[i];
      }
    });
  };
  parallelFor(0, nf, kGrain, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      kappa_[i] = kWarmShare * warm[i] / keep;
      kappaOverRho_[i] = kappa_[i] / rho_[i];
    }
  });
  apply();
  int it = 0;
  double err = 0.0;
  for (;;) {
    parallelFor(0, nf, kGrain, [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) {
        double drho = 0.0;  // Dρ/Dt from the velocities now
        const auto nb = grid_.neighbors(i);
        const double* g = grad_.data() + 3 * grid_.listOffset(i);
        const double vi0 = V[3 * i], vi1 = V[3 * i + 1], vi2 = V[3 * i + 2];
        for (std::uint32_t j : nb) {
          if (j < nf) {
            const double* vj = V + 3 * std::size_t(j);
            drho += mass_ * ((vi0 - vj[0]) * g[0] + (vi1 - vj[1]) * g[1] + (vi2 - vj[2]) * g[2]);
          } else {
            const double* vb = BV + 3 * std::size_t(j - nf);
            drho += bpsi_[j - nf] * ((vi0 - vb[0]) * g[0] + (vi1 - vb[1]) * g[1] + (vi2 - vb[2]) * g[2]);
          }
          g += 3;
        }
        if (density) {
          const double compression = std::max(rho_[i] + dt * drho - rho0, 0.0);
          error_[i] = compression / rho0;
          kappa_[i] = o_.relaxation * compression * alpha_[i] / (dt * dt);
        } else {
          drho = nb.size() < kMinNeighboursForDivergence ? 0.0 : std::max(drho, 0.0);
          error_[i] = dt * drho / rho0;
          kappa_[i] = o_.relaxation * drho * alpha_[i] / dt;
        }
        kappaOverRho_[i] = kappa_[i] / rho_[i];
      }
    });
    err = serialMean(error_, nf);
    const double bound = density ? o_.maxDensityError : o_.maxDivergenceError;
    if (it >= o_.maxIterations || (it >= o_.minIterations && err <= bound)) {
      stats_.converged = stats_.converged && err <= bound;
      break;
    }
    apply();
    ++it;
  }
  (density ? stats_.densityError : stats_.divergenceError) = err;
  if (!rx_.empty()) pressureReaction(dt);
  for (std::size_t i = 0; i < nf; ++i) {
    warm[i] = kappaSum_[i] * keep;
    p_[i] += kappaSum_[i];
  }
  return it;
}

double SphFluid::subStep(double dt) {
  const std::size_t nf = x_.size();
  p_.assign(nf, 0.0);
  nonPressure(dt);
  stats_.densityIterations += pressureSolve(dt, true);
  parallelFor(0, nf, kGrain, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) x_[i] += dt * v_[i];
  });
  moveBoundaries(dt);
  neighbours();
  densitiesAndFactors();
  stats_.divergenceIterations += pressureSolve(dt, false);
  // p = ρ Σκ (κ/ρ = p/ρ²): the two solves' pressure impulses of this step.
  for (std::size_t i = 0; i < nf; ++i) p_[i] *= rho_[i];
  time_ += dt;
  return dt;
}

Status SphFluid::step(double dt) {
  if (!(dt > 0.0) || !std::isfinite(dt))
    return fail(ErrorCode::InvalidArgument, formatString("dt %g s", dt), "SphFluid::step",
                "a positive time step");
  stats_ = {};
  for (Rigid& r : rigid_) r.impulse = r.angularImpulse = Vec3::Zero();
  for (Surface& sf : surfaces_) std::fill(sf.impulse.begin(), sf.impulse.end(), Vec3::Zero());
  const auto loads = [&] {
    for (Rigid& r : rigid_) r.load = {.force = r.impulse / dt, .torque = r.angularImpulse / dt};
    for (Surface& sf : surfaces_)
      for (std::size_t v = 0; v < sf.impulse.size(); ++v) sf.load[v] = sf.impulse[v] / dt;
  };
  if (x_.empty()) {
    moveBoundaries(dt);
    time_ += dt;
    loads();
    return ok();
  }
  if (rho_.size() != x_.size() || boundaryDirty_ || boundaryMoved_) refresh();
  double left = dt;
  const double d = o_.particleSpacing;
  while (left > 1e-12 * dt) {
    double vmax = 0.0;
    for (const Vec3& v : v_) vmax = std::max(vmax, v.squaredNorm());
    for (std::size_t b = bx_.size(); b < bv_.size(); ++b)
      vmax = std::max(vmax, bv_[b].squaredNorm());  // bodies and surfaces
    // The speed bound adds 4 sqrt(|g| d) (8 times what a particle falling
    // from rest reaches over half a spacing): a column at rest still takes
    // sub-steps of at most 0.1 sqrt(d / |g|), past which the hydrostatic
    // column was found to slosh (10 ms for d = 1 cm).
    vmax = std::sqrt(vmax) + 4.0 * std::sqrt(o_.gravity.norm() * d);
    double hmax = o_.cfl * d / vmax;
    if (o_.viscosity > 0.0) hmax = std::min(hmax, 0.1 * d * d / o_.viscosity);  // explicit viscosity's bound
    // Equal sub-steps for what is left (a short remainder would turn small
    // density errors into large velocities), within the step's budget.
    const int remaining = o_.maxSubSteps - stats_.subSteps;
    const double n = std::min(double(std::max(remaining, 1)), std::ceil(left / hmax - 1e-9));
    const double h = n <= 1.0 ? left : left / n;
    left -= subStep(h);
    ++stats_.subSteps;
    for (std::size_t i = 0; i < x_.size(); ++i)
      if (!x_[i].allFinite() || !v_[i].allFinite())
        return fail(ErrorCode::InvalidArgument, formatString("fluid particle %zu is no longer finite", i),
                    "SphFluid::step", "a smaller step, more iterations or less viscosity");
  }
  double worst = 0.0;
  for (double r : rho_) worst = std::max(worst, (r - o_.restDensity) / o_.restDensity);
  stats_.maxDensityError = worst;
  loads();
  return ok();
}

}  // namespace dm
