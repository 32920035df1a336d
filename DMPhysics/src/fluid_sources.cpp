// fluid_sources.cpp — inlets, suction and the region of interest of a
// particle fluid (dm/physics/fluid_sources.hpp).
#include <dm/physics/fluid_sources.hpp>

#include <algorithm>
#include <cmath>

namespace dm {

namespace {

Error badOption(const char* type, const char* what, const std::string& value, const char* hint) {
  return fail(ErrorCode::InvalidArgument, std::string(what) + " is " + value, std::string(type) + "." + what,
              hint);
}

double nonNegative(double v) noexcept { return v > 0.0 && std::isfinite(v) ? v : 0.0; }

// The particle volume d³ = m / ρ0 of a fluid.
double particleVolume(const SphFluid& fluid) { return fluid.particleMass() / fluid.options().restDensity; }

}  // namespace

// --- FluidInlet ---------------------------------------------------------------

Result<FluidInlet> FluidInlet::create(const FluidInletOptions& o, const SphFluid& fluid) {
  const char* type = "FluidInletOptions";
  if (!o.center.allFinite()) return badOption(type, "center", "not finite", "the outlet's centre in metres");
  if (!o.normal.allFinite() || o.normal.norm() < 1e-12)
    return badOption(type, "normal", "zero or not finite", "the direction the fluid leaves in");
  if (!(o.radius >= 0.0) || !std::isfinite(o.radius))
    return badOption(type, "radius", formatString("%g", o.radius), "metres, ≥ 0");
  if (!(o.flowRate >= 0.0) || !std::isfinite(o.flowRate))
    return badOption(type, "flowRate", formatString("%g", o.flowRate), "m³/s, ≥ 0 (1 ml/s is 1e-6)");
  if (!(o.drivingPressure >= 0.0) || !std::isfinite(o.drivingPressure))
    return badOption(type, "drivingPressure", formatString("%g", o.drivingPressure),
                     "Pa, ≥ 0: 0 for a pump, a vessel's pressure otherwise (10 mmHg is 1333 Pa)");
  FluidInlet inlet;
  inlet.o_ = o;
  inlet.o_.normal = o.normal.normalized();
  const double d = fluid.options().particleSpacing;
  inlet.spacing_ = d;
  inlet.particleVolume_ = particleVolume(fluid);
  // The disc's points on the lattice of spacing d in its plane.
  const Vec3 n = inlet.o_.normal;
  const Vec3 t1 = (std::abs(n.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY()).cross(n).normalized();
  const Vec3 t2 = n.cross(t1);
  const int reach = int(std::floor(o.radius / d + 1e-9));
  for (int j = -reach; j <= reach; ++j)
    for (int i = -reach; i <= reach; ++i)
      if (double(i * i + j * j) * d * d <= o.radius * o.radius * (1.0 + 1e-9))
        inlet.points_.push_back(d * (double(i) * t1 + double(j) * t2));
  inlet.area_ = double(inlet.points_.size()) * d * d;
  inlet.layer_.reserve(inlet.points_.size());
  return inlet;
}

void FluidInlet::setFlowRate(double m3PerSecond) noexcept { o_.flowRate = nonNegative(m3PerSecond); }

void FluidInlet::setAppliedPressure(double pascal) noexcept { applied_ = nonNegative(pascal); }

double FluidInlet::backPressure(const SphFluid& fluid) const {
  const Vec3 at = samplePoint();
  const double reach2 = spacing_ * spacing_;
  const auto x = fluid.positions();
  const auto p = fluid.pressures();  // of the last step: shorter when particles came since
  double sum = 0.0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < p.size() && i < x.size(); ++i)
    if ((x[i] - at).squaredNorm() <= reach2) {
      sum += p[i];
      ++n;
    }
  return applied_ + (n == 0 ? 0.0 : sum / double(n));
}

double FluidInlet::flowRateAt(double back) const noexcept {
  if (o_.drivingPressure <= 0.0) return o_.flowRate;  // a pump
  return o_.flowRate * std::clamp(1.0 - back / o_.drivingPressure, 0.0, 1.0);
}

std::size_t FluidInlet::emit(SphFluid& fluid, double dt) {
  if (!(dt > 0.0) || !std::isfinite(dt)) return 0;
  lastRate_ = o_.drivingPressure > 0.0 ? flowRateAt(backPressure(fluid)) : o_.flowRate;
  inFlight_ += lastRate_ * dt;
  const double layerVolume = double(points_.size()) * particleVolume_;
  const Vec3 velocity = (lastRate_ / area_) * o_.normal;
  // Closer than this to a fluid particle, a point is occupied: two particles
  // started on top of each other would blow apart under their pressure.
  const double near2 = 0.5625 * spacing_ * spacing_;
  std::size_t added = 0;
  while (inFlight_ >= layerVolume) {
    // A layer starts half a spacing out of the disc (as a block's first
    // layer lies half a spacing inside its face, clear of the boundary
    // particles of a wall the disc lies in), and what flowed after it has
    // pushed it further.
    const Vec3 base = o_.center + (0.5 * spacing_ + (inFlight_ - layerVolume) / area_) * o_.normal;
    const auto occupied = [&](const Vec3& p) {
      const auto x = fluid.positions();
      return std::any_of(x.begin(), x.end(), [&](const Vec3& q) { return (q - p).squaredNorm() < near2; });
    };
    if (std::any_of(points_.begin(), points_.end(), [&](const Vec3& o) { return occupied(base + o); })) {
      // Fluid lies over the mouth: the inflow pushes the column over it up
      // by the layer it adds, as an incompressible plug (the pressure
      // solve then spreads it).
      const double reach = o_.radius + 0.5 * spacing_;
      fluid.displaceIf(
          [&](const Vec3& x) {
            const Vec3 r = x - o_.center;
            const double s = r.dot(o_.normal);
            return s >= 0.0 && (r - s * o_.normal).squaredNorm() <= reach * reach;
          },
          spacing_ * o_.normal);
    }
    layer_.clear();
    for (const Vec3& offset : points_)
      if (!occupied(base + offset)) layer_.push_back(base + offset);
    if (layer_.empty()) {
      // Fluid covers the mouth: the vessel does not store what it could not
      // deliver (a layer at most stays in flight).
      inFlight_ = std::min(inFlight_, layerVolume);
      break;
    }
    fluid.addParticles(layer_, velocity);
    inFlight_ -= double(layer_.size()) * particleVolume_;
    added += layer_.size();
  }
  emitted_ += added;
  return added;
}

// --- FluidSuction -------------------------------------------------------------

Result<FluidSuction> FluidSuction::create(const FluidSuctionOptions& o) {
  const char* type = "FluidSuctionOptions";
  if (!o.center.allFinite()) return badOption(type, "center", "not finite", "the tip's centre in metres");
  if (!(o.radius > 0.0) || !std::isfinite(o.radius))
    return badOption(type, "radius", formatString("%g", o.radius), "metres, > 0");
  if (!(o.maxFlowRate >= 0.0) || !std::isfinite(o.maxFlowRate))
    return badOption(type, "maxFlowRate", formatString("%g", o.maxFlowRate), "m³/s, ≥ 0 (1 ml/s is 1e-6)");
  FluidSuction s;
  s.o_ = o;
  return s;
}

void FluidSuction::setMaxFlowRate(double m3PerSecond) noexcept { o_.maxFlowRate = nonNegative(m3PerSecond); }

std::size_t FluidSuction::apply(SphFluid& fluid, double dt) {
  if (!(dt > 0.0) || !std::isfinite(dt)) return 0;
  particleVolume_ = particleVolume(fluid);
  credit_ += o_.maxFlowRate * dt;
  const auto budget = static_cast<std::size_t>(std::floor(credit_ / particleVolume_ + 1e-9));
  const double r2 = o_.radius * o_.radius;
  candidates_.clear();
  for (const Vec3& x : fluid.positions())
    if (const double q = (x - o_.center).squaredNorm(); q <= r2) candidates_.push_back(q);
  const std::size_t take = std::min(budget, candidates_.size());
  std::size_t removed = 0;
  if (take > 0) {
    // The take-th nearest distance: all nearer go, and of those at it (ties)
    // as many as the count leaves.
    std::nth_element(candidates_.begin(), candidates_.begin() + std::ptrdiff_t(take - 1), candidates_.end());
    const double limit = candidates_[take - 1];
    std::size_t ties = take - std::size_t(std::count_if(candidates_.begin(), candidates_.end(),
                                                        [limit](double q) { return q < limit; }));
    removed = fluid.removeIf([&](const Vec3& x) {
      const double q = (x - o_.center).squaredNorm();
      if (q < limit) return true;
      if (q > limit || ties == 0) return false;
      --ties;
      return true;
    });
  }
  removed_ += removed;
  credit_ -= double(removed) * particleVolume_;
  // Suction of air banks nothing: one particle's credit at most carries over.
  credit_ = std::min(credit_, particleVolume_);
  return removed;
}

// --- FluidRegion --------------------------------------------------------------

Result<FluidRegion> FluidRegion::create(const Vec3& lo, const Vec3& hi) {
  if (!lo.allFinite() || !hi.allFinite() || !(lo.array() < hi.array()).all())
    return fail(ErrorCode::InvalidArgument,
                formatString("the box [%g %g %g] .. [%g %g %g] is empty or not finite", lo.x(), lo.y(),
                             lo.z(), hi.x(), hi.y(), hi.z()),
                "FluidRegion", "lo below hi on every axis, in metres");
  return FluidRegion(lo, hi);
}

bool FluidRegion::contains(const Vec3& x) const noexcept {
  return (x.array() >= lo_.array()).all() && (x.array() <= hi_.array()).all();
}

std::size_t FluidRegion::apply(SphFluid& fluid) {
  const std::size_t removed = fluid.removeIf([this](const Vec3& x) { return !contains(x); });
  removed_ += removed;
  return removed;
}

}  // namespace dm
