// dm/physics/fluid_sources.hpp — where a particle fluid (dm::SphFluid) comes
// from and goes: a bleeding vessel or an irrigation nozzle (FluidInlet),
// a suction tip (FluidSuction) and the region of interest whose leavers are
// recycled (FluidRegion). Each keeps the account of the volume it moved, so
// the fluid's mass is always its start plus what the inlets emitted minus
// what suction and the region took, to the particle.
//
// Inlet. Fluid enters through a disc (centre c, outward normal n, radius R)
// sampled on the square lattice of the fluid's spacing d: its k points make
// the outlet's area A = k d², so a flow rate Q leaves it at v = Q/A along n
// and the layers it emits are d apart, as the fluid at rest. Each emit(dt)
// adds Q dt to the volume in flight and emits a layer for every k d³ of it;
// a layer is placed d/2 + V/A out along n, V the volume that has flowed
// after it (d/2: as a block's first layer lies half a spacing inside its
// face, clear of the boundary particles of a wall the disc lies in; V/A: so
// layers emitted within one call do not coincide). Where fluid already
// lies over the mouth (a pool over a cut), the inflow first pushes the
// column over the disc (within R + d/2 of its axis, from the disc up) one
// spacing along n, as an incompressible plug the pressure solve then
// spreads; a point still closer than 3/4 d to a particle after that is left
// out of its layer (particles started on top of each other blow apart
// under their pressure) and its volume waits, a layer at most: the vessel
// does not store what it could not deliver. (Found: inserting into the
// covered mouth blew the pool apart; driving the emitted particles through
// the mouth as a piston made it unstable where released layers met them.)
// The rate:
//   - a pump (drivingPressure 0: irrigation, a syringe) delivers its
//     flowRate whatever the pressure against it;
//   - a vessel (drivingPressure p_v > 0: a cut artery or vein) delivers
//     Q = flowRate · max(0, 1 − p_b / p_v), the linear (Poiseuille) law of a
//     vessel whose resistance sets flowRate at zero back pressure. The back
//     pressure p_b is the pressure a tool applies on the source
//     (setAppliedPressure: pressing it with p_v or more stops it) plus the
//     fluid's own: the mean pressure of the fluid particles within d of
//     c + 1.5 d n, so the fluid pressing on a cut (a pool over it) slows its
//     bleeding and stops it where its pressure reaches p_v. (1.5 d: past the
//     layer touching the wall, whose pressure the boundary particles
//     overstate — measured in a 7 cm pool: 1187 Pa at the wall's layer
//     against 623 hydrostatic, 485 against 525 one layer up.)
//
// Suction. A sphere (the tip of a suction cannula, movable) removes up to
// maxFlowRate·dt of fluid per call, the particles nearest its centre first.
// Suction that finds no fluid does not bank its capacity: at most one
// particle's volume carries over to the next call.
//
// Region. Particles outside a box (the region of interest: the operative
// field, not the floor below the table) are removed at each apply(): a run
// with a source can go on for any time without the particles growing.
//
// All three are plain objects the caller ticks beside SphFluid::step on the
// physics thread (the scene's fluid component, a script, a test); none
// allocates beyond the fluid's own growth.
//
// @code
//   auto fluid = *dm::SphFluid::create({.particleSpacing = 0.004, .restDensity = 1060});
//   auto cut = *dm::FluidInlet::create({.center = c, .normal = n, .radius = 0.002,
//                                       .flowRate = 2e-6, .drivingPressure = 2000}, fluid);
//   auto tip = *dm::FluidSuction::create({.center = t, .radius = 0.006, .maxFlowRate = 5e-6});
//   for (;;) { cut.emit(fluid, dt); tip.apply(fluid, dt); (void)fluid.step(dt); }
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/physics/sph_fluid.hpp>

#include <cstddef>
#include <vector>

namespace dm {

/// Options of FluidInlet::create().
struct FluidInletOptions {
  Vec3 center = Vec3::Zero();    ///< m: the middle of the outlet disc
  Vec3 normal = Vec3(0, 0, 1);   ///< the direction the fluid leaves in (normalised; nonzero)
  double radius = 0.0;           ///< m, ≥ 0: the disc's radius (one lattice point at least)
  double flowRate = 0.0;         ///< m³/s, ≥ 0: the rate at zero back pressure
  double drivingPressure = 0.0;  ///< Pa, ≥ 0: 0 a pump; > 0 a vessel (see the file comment)
};

/// A source of fluid; see the file comment. Copyable.
class FluidInlet {
 public:
  /// Fails with InvalidArgument naming the option out of range; `fluid` gives
  /// the spacing and particle volume (emit() into a fluid like it).
  static Result<FluidInlet> create(const FluidInletOptions& options, const SphFluid& fluid);

  /// Adds the fluid that flowed over dt (> 0) at the rate of the current back
  /// pressure; returns how many particles it added.
  std::size_t emit(SphFluid& fluid, double dt);

  void setFlowRate(double m3PerSecond) noexcept;  ///< ≥ 0 (a negative or NaN rate is taken as 0)
  /// The pressure a tool applies on the source, Pa (≥ 0; NaN taken as 0).
  void setAppliedPressure(double pascal) noexcept;
  /// The applied pressure plus the mean pressure of the fluid within d of
  /// samplePoint(), Pa.
  double backPressure(const SphFluid& fluid) const;
  /// Where the fluid's pressure on the source is sampled: c + 1.5 d n.
  Vec3 samplePoint() const noexcept { return o_.center + 1.5 * spacing_ * o_.normal; }
  /// m³/s at the given back pressure (the pump's or the vessel's law).
  double flowRateAt(double backPressure) const noexcept;

  double lastFlowRate() const noexcept { return lastRate_; }  ///< m³/s of the last emit()
  double emittedVolume() const noexcept { return double(emitted_) * particleVolume_; }  ///< m³ in all
  std::size_t emittedParticles() const noexcept { return emitted_; }
  double outletArea() const noexcept { return area_; }  ///< A = k d², m²
  std::size_t pointsPerLayer() const noexcept { return points_.size(); }
  const FluidInletOptions& options() const noexcept { return o_; }

 private:
  FluidInletOptions o_;
  std::vector<Vec3> points_;  // the disc's lattice points, relative to its centre
  std::vector<Vec3> layer_;   // scratch for one layer's positions
  double spacing_ = 0.0, area_ = 0.0, particleVolume_ = 0.0;
  double applied_ = 0.0, inFlight_ = 0.0, lastRate_ = 0.0;
  std::size_t emitted_ = 0;
};

/// Options of FluidSuction::create().
struct FluidSuctionOptions {
  Vec3 center = Vec3::Zero();  ///< m: the tip's centre
  double radius = 0.0;         ///< m, > 0
  double maxFlowRate = 0.0;    ///< m³/s, ≥ 0
};

/// A suction tip; see the file comment. Copyable.
class FluidSuction {
 public:
  static Result<FluidSuction> create(const FluidSuctionOptions& options);

  /// Removes up to maxFlowRate·dt (dt > 0) of the fluid inside the sphere,
  /// nearest the centre first; returns how many particles.
  std::size_t apply(SphFluid& fluid, double dt);

  void setCenter(const Vec3& center) noexcept { o_.center = center; }  ///< the tip moves with its tool
  void setMaxFlowRate(double m3PerSecond) noexcept;                    ///< ≥ 0 (negative or NaN: 0)
  double removedVolume() const noexcept { return double(removed_) * particleVolume_; }  ///< m³ in all
  std::size_t removedParticles() const noexcept { return removed_; }
  const FluidSuctionOptions& options() const noexcept { return o_; }

 private:
  FluidSuctionOptions o_;
  double credit_ = 0.0;          // m³ of capacity not yet used
  double particleVolume_ = 0.0;  // of the fluid it last applied to
  std::size_t removed_ = 0;
  std::vector<double> candidates_;  // scratch: squared distances of the particles inside
};

/// The region of interest: an axis-aligned box; see the file comment.
class FluidRegion {
 public:
  /// Fails with InvalidArgument unless lo < hi on every axis (finite).
  static Result<FluidRegion> create(const Vec3& lo, const Vec3& hi);

  /// Removes the fluid particles outside the box; returns how many.
  std::size_t apply(SphFluid& fluid);
  bool contains(const Vec3& x) const noexcept;
  std::size_t removedParticles() const noexcept { return removed_; }
  const Vec3& lo() const noexcept { return lo_; }
  const Vec3& hi() const noexcept { return hi_; }

 private:
  FluidRegion(const Vec3& lo, const Vec3& hi) : lo_(lo), hi_(hi) {}
  Vec3 lo_, hi_;
  std::size_t removed_ = 0;
};

}  // namespace dm
