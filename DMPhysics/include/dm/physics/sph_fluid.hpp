// dm/physics/sph_fluid.hpp — a particle fluid (blood, irrigation saline):
// SPH with the divergence-free solver DFSPH (Bender & Koschier 2015, 2017),
// which keeps the average density error under a set bound (0.1 % by
// default) with two implicit pressure solves per step instead of a stiff
// equation of state.
//
// Why DFSPH: a weakly compressible SPH needs a speed of sound ten times the
// flow's and steps a hundred times smaller to stay within 1 % density
// error; position-based fluids (Macklin & Müller 2013) hold the density but
// have no physical pressure (the hydrostatic test and the force on a body
// need one); IISPH holds it too but solves only the density, and its
// divergence drifts at rest. DFSPH solves both — constant density after the
// advection, zero velocity divergence after the positions move — so a
// column at rest stays at rest with ρ0 g depth as its pressure, at CFL
// steps.
//
// Model. Particles of rest spacing d (volume d³, mass calibrated so that a
// full cubic lattice has exactly the rest density ρ0), the cubic spline
// kernel of support h = 2d, fixed-radius neighbours from dm::NeighborGrid.
// One step of dt (split into CFL sub-steps, |v| dt ≤ cfl · d, and viscous
// sub-steps, ν dt ≤ d²/10):
//   1. non-pressure accelerations: gravity, viscosity (the SPH Laplacian of
//      Monaghan 2005 with the kinematic viscosity ν; against boundaries too,
//      no-slip), surface tension (cohesion and curvature of Akinci et al.
//      2013, coefficient γ); v* = v + dt a;
//   2. density solve: relaxed Jacobi iterations of κ_i = ω (ρ*_i − ρ0) α_i / dt²,
//      warm-started with the last solve's κ
//      (compression only: free surfaces do not pull) until the average
//      relative error is under maxDensityError;
//   3. x += dt v; neighbours, densities ρ_i and factors α_i at the new x;
//   4. divergence solve: κ_i = (Dρ/Dt)_i α_i / dt until the average
//      divergence error (dt Dρ/Dt / ρ0) is under maxDivergenceError.
// The pressure of a particle is p_i = ρ_i Σκ_i over both solves of the step
// (Δv = −dt Σ m_j (κ_i/ρ_i + κ_j/ρ_j)∇W is −dt ∇p/ρ).
// Boundaries are particles (Akinci et al. 2012): each contributes
// Ψ_b = ρ0 V_b with V_b = s / Σ_k W_bk over its boundary neighbours, s the
// ratio of a lattice plane's kernel sum to the full lattice's, so a wall
// sampled at spacing d completes the fluid's neighbourhood exactly; walls of a
// box container come from addBoxBoundary(), any surface from
// addBoundaryParticles() (dm::sampleBoundary() samples a mesh).
//
// Rigid bodies (two-way coupling, Akinci et al. 2012): addRigidBoundary()
// gives a body's surface as boundary particles in its own frame, with their
// Ψ from the body's own particles. The caller integrates the body (a
// PhysicsWorld body, a test's own integrator) and hands its pose and
// velocities in with setRigidState(); within step() the body moves on at
// them, its surface velocity enters the density and divergence solves
// (Dρ/Dt sees v_i − v_b) and the no-slip viscosity, and the fluid's
// reaction — every boundary pair's pressure impulse dt m_i Ψ_b κ_i/ρ_i ∇W_ib
// and viscous one, opposite to what the fluid particle got — is summed per
// body into rigidLoad(): force and torque, averaged over the step. The
// exchange is explicit (the caller's state holds for a step): a sphere of
// half the fluid's density, whose mass equals its added mass, floats
// steadily at 2 ms steps; much lighter bodies need shorter steps.
//
// Deforming surfaces (tissue; one-way, and loads for two-way):
// addSurfaceBoundary() takes a dm::BoundarySurface (samples that follow a
// mesh's triangles), setSurfaceState() the mesh's vertices and velocities
// as its owner (an FEM body) has them each step. The samples are placed on
// the deformed triangles, move on at the interpolated velocities within the
// step, and get their Ψ again from their own neighbours (a stretched
// surface's samples stand for more area; their pairs within h + h/4 are
// kept as a Verlet list, listed again only once the samples have moved
// apart by h/8 relative to their mean motion); surfaceLoads() spreads the
// fluid's reactions on them onto the vertices. Sample a surface that
// stretches by s at d / s or finer: samples more than a spacing apart let
// the fluid through (Tests/DMPhysics/sph_surface_test.cpp).
//
// Every per-particle sum runs over its neighbour list in index order and
// reductions are serial, so a run is bit-reproducible on any thread count.
// The step runs on oneTBB (dm::parallelFor): a physics thread's work, not
// the haptic loop's.
//
// References: J. Bender, D. Koschier, "Divergence-free SPH for incompressible
// and viscous fluids", IEEE TVCG 2017. N. Akinci et al., "Versatile rigid-
// fluid coupling for incompressible SPH", SIGGRAPH 2012; "Versatile surface
// tension and adhesion for SPH fluids", SIGGRAPH Asia 2013. J. J. Monaghan,
// "Smoothed particle hydrodynamics", Rep. Prog. Phys. 2005.
//
// @code
//   dm::SphFluid fluid(*dm::SphFluid::create({.particleSpacing = 0.005}));
//   fluid.addBoxBoundary({-0.1, -0.1, 0}, {0.1, 0.1, 0.2});
//   fluid.addBlock({-0.1, -0.1, 0}, {0.1, 0.1, 0.1});
//   for (int k = 0; k < 1000; ++k) (void)fluid.step(1e-3);
// @endcode
#pragma once

#include <dm/collide/neighbor_grid.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/physics/sph_boundary.hpp>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace dm {

/// Options of SphFluid::create().
struct SphFluidOptions {
  double particleSpacing = 0.005;  ///< m, > 0: the rest spacing d (kernel support 2d)
  double restDensity = 1000.0;     ///< kg/m³, > 0 (blood: 1060)
  double viscosity = 1e-6;         ///< m²/s, ≥ 0: kinematic (water 1e-6, blood about 3.5e-6)
  double surfaceTension = 0.0;     ///< ≥ 0: Akinci's γ (0.05..1 for water-like droplets)
  Vec3 gravity = Vec3(0.0, 0.0, -9.81);
  double maxDensityError = 1e-3;     ///< average relative compression the density solve leaves, > 0
  double maxDivergenceError = 1e-3;  ///< average dt·Dρ/Dt/ρ0 the divergence solve leaves, > 0
  int minIterations = 2;             ///< per solve, ≥ 1
  int maxIterations = 100;           ///< per solve, ≥ minIterations
  double cfl = 0.4;                  ///< (0, 1]: sub-steps keep |v| dt ≤ cfl · d
  /// (0, 1]: the share of each Jacobi update of κ applied (ω). A full update
  /// counts every neighbour's response to a particle's own pressure but not
  /// to the neighbours' own, and overshoots where all are compressed; 0.5
  /// (as IISPH's ω) converges on the hydrostatic column at any step size.
  double relaxation = 0.5;
  int maxSubSteps = 64;  ///< per step(), ≥ 1
};

/// What the last step() did.
struct SphStepStats {
  int subSteps = 0;
  int densityIterations = 0;  ///< summed over the sub-steps
  int divergenceIterations = 0;
  double densityError = 0.0;     ///< average relative compression after the last density solve
  double divergenceError = 0.0;  ///< after the last divergence solve
  double maxDensityError = 0.0;  ///< the largest particle's relative compression after the step
  bool converged = true;         ///< every solve met its bound within maxIterations
};

/// What the fluid did to a rigid body over the last step (SphFluid::rigidLoad).
struct SphRigidLoad {
  Vec3 force = Vec3::Zero();   ///< N, pressure and viscosity, averaged over the step
  Vec3 torque = Vec3::Zero();  ///< N·m, about the body frame's origin
};

/// See the file comment. Not thread-safe; copyable (a snapshot).
class SphFluid {
 public:
  /// Fails with InvalidArgument naming the option that is out of range.
  static Result<SphFluid> create(const SphFluidOptions& options = {});

  // --- particles -----------------------------------------------------------
  /// Fills the box [lo, hi] with fluid on the lattice of spacing d (the
  /// first layer d/2 inside each face); returns how many were added.
  std::size_t addBlock(const Vec3& lo, const Vec3& hi, const Vec3& velocity = Vec3::Zero());
  /// Adds fluid particles (a source: bleeding, irrigation).
  void addParticles(std::span<const Vec3> positions, const Vec3& velocity = Vec3::Zero());
  /// Removes the fluid particles for which inside(position) is true (suction,
  /// leaving the region of interest); returns how many.
  template <class Inside>
  std::size_t removeIf(Inside&& inside);
  /// Moves the fluid particles for which select(position) is true by
  /// `offset`, their velocities kept (an inflow lifting the fluid over its
  /// mouth); returns how many.
  template <class Select>
  std::size_t displaceIf(Select&& select, const Vec3& offset);
  /// Static boundary particles (a wall, an organ's surface sampled at about
  /// d); their volumes are computed from their neighbours at the next step.
  void addBoundaryParticles(std::span<const Vec3> positions);
  /// The five walls (no lid) of a container whose inside is the box [lo,
  /// hi], as boundary particles at spacing about d half a spacing outside
  /// each face (a fluid particle's centre lies half a spacing inside it, see
  /// addBlock); the fluid stays inside.
  std::size_t addBoxBoundary(const Vec3& lo, const Vec3& hi);

  // --- rigid bodies (two-way) ----------------------------------------------
  /// A rigid body the fluid flows around and pushes: its surface as boundary
  /// particles in the body's frame, about d apart and a third of a spacing
  /// inside its surface (dm::sampleBoundary(mesh, d, d / 3)), placed by
  /// `pose`.
  /// Returns the body's index (0, 1, ...); fails (InvalidArgument) on no
  /// points, a non-finite point or a non-finite pose.
  Result<std::size_t> addRigidBoundary(std::span<const Vec3> bodyPoints,
                                       const Isometry3& pose = Isometry3::Identity());
  /// The body's pose and its frame origin's linear and angular velocity (the
  /// caller integrates the body); within the next step() it moves on at
  /// them. Fails (InvalidArgument) on an unknown body or a non-finite state.
  Status setRigidState(std::size_t body, const Isometry3& pose, const Vec3& linearVelocity,
                       const Vec3& angularVelocity);
  std::size_t rigidBodyCount() const noexcept { return rigid_.size(); }
  /// Where the last step() left the body (its pose moved on at its velocities).
  Isometry3 rigidPose(std::size_t body) const { return rigid_.at(body).pose; }
  /// What the fluid exerted on the body over the last step (see SphRigidLoad).
  SphRigidLoad rigidLoad(std::size_t body) const { return rigid_.at(body).load; }

  // --- deforming surfaces (tissue) -------------------------------------------
  /// A deforming surface the fluid flows around and is pushed by (tissue
  /// under a tool): `surface`'s samples (dm::BoundarySurface::create(mesh,
  /// d, d / 3)) placed on its mesh's vertices at `vertices`, at rest.
  /// Their Ψ come from the surface's own samples, again at every placement
  /// (a stretched surface's samples stand for more area each). Returns the
  /// surface's index (0, 1, ...); fails (InvalidArgument) on a surface
  /// without samples, a vertex count other than the surface's, or a
  /// non-finite vertex.
  Result<std::size_t> addSurfaceBoundary(BoundarySurface surface, std::span<const Vec3> vertices);
  /// The surface's vertices where its owner (an FEM body) has them now and
  /// their velocities; within the next step() the samples move on at the
  /// velocities interpolated. Allocation-free. Fails (InvalidArgument) on
  /// an unknown surface, counts other than its vertices' or a non-finite
  /// value.
  Status setSurfaceState(std::size_t surface, std::span<const Vec3> vertices,
                         std::span<const Vec3> velocities);
  std::size_t surfaceCount() const noexcept { return surfaces_.size(); }
  /// Per vertex of the surface, the force the fluid exerted on it over the
  /// last step (N, averaged over the step): every boundary pair's pressure
  /// and viscous reaction on a sample, spread onto its triangle's vertices
  /// by its barycentric weights. The fluid does not move the surface: its
  /// owner may apply these (two-way) or not (one-way).
  std::span<const Vec3> surfaceLoads(std::size_t surface) const { return surfaces_.at(surface).load; }

  /// Every moving boundary particle in the world (rigid bodies' and
  /// surfaces', in the order they were added).
  std::span<const Vec3> movingBoundaryPositions() const noexcept { return rx_; }

  // --- stepping ------------------------------------------------------------
  /// Advances dt (> 0, finite) in CFL sub-steps. Fails (InvalidArgument) on a
  /// bad dt, or naming the particle when a state stops being finite.
  Status step(double dt);

  /// Neighbours, boundary volumes and densities at the current positions,
  /// as the next step starts from (step() does it itself when particles were
  /// added or removed); for reading densities() before any step.
  void refresh();

  // --- state ---------------------------------------------------------------
  std::size_t size() const noexcept { return x_.size(); }
  std::span<const Vec3> positions() const noexcept { return x_; }
  std::span<const Vec3> velocities() const noexcept { return v_; }
  std::span<const double> densities() const noexcept { return rho_; }  ///< kg/m³, at the last step
  std::span<const double> pressures() const noexcept { return p_; }    ///< Pa, of the last sub-step
  std::span<const Vec3> boundaryPositions() const noexcept { return bx_; }
  double particleMass() const noexcept { return mass_; }
  double time() const noexcept { return time_; }
  const SphFluidOptions& options() const noexcept { return o_; }
  const SphStepStats& lastStep() const noexcept { return stats_; }
  /// Kg of fluid; changes only by addBlock/addParticles/removeIf.
  double mass() const noexcept { return mass_ * double(x_.size()); }
  /// Kernel W(r) and its support radius h = 2d (for samplers and tests).
  double kernel(double r) const noexcept;
  double supportRadius() const noexcept { return h_; }

 private:
  explicit SphFluid(const SphFluidOptions& o);
  void neighbours();
  void densitiesAndFactors();
  double gradientScale(double len) const noexcept;  // ∇W(r) = gradientScale(|r|) r
  void nonPressure(double dt);
  int pressureSolve(double dt, bool density);
  double subStep(double dt);  // returns the dt it took
  void addMoving(std::size_t count);       // room for the last added body's or surface's particles
  void layOutBoundaryVelocities();         // bv_ for the boundary as it is now
  void placeRigid(std::size_t body);       // its particles' positions and velocities from its state
  void placeSurface(std::size_t surface);  // its samples' positions, velocities and Ψ from its vertices
  // A moving owner's pairs of its own particles within h + skin (a Verlet
  // list): listed again only when the particles have moved, relative to
  // their mean motion, far enough that an unlisted pair could come within h.
  struct OwnPairs {
    std::vector<std::uint32_t> pairs;  // (i, j), i < j, flat
    std::vector<Vec3> listedAt;        // the particles where they were when listed
  };
  void ownVolumes(std::size_t first, std::size_t count, OwnPairs& own);  // rpsi_ of its particles
  void moveBoundaries(double dt);                         // every body and surface on at its velocities
  template <class PairImpulse>
  void reactionWalk(PairImpulse&& impulse);  // rimp_ += impulse(i, j, ∇W) over fluid–moving pairs
  void collectReactions();                   // rimp_ into the bodies' and surfaces' impulses
  void viscousReaction(double dt);           // what the no-slip viscosity of this sub-step did to them
  void pressureReaction(double dt);          // what the solve that just ended did to them
  bool touchesMoving(std::size_t i) const noexcept {  // fluid particle i has a moving particle in its list
    const auto nb = grid_.neighbors(i);
    return !nb.empty() && nb.back() >= x_.size() + bx_.size();  // lists are in index order
  }

  struct Rigid {
    std::vector<Vec3> local;  // its boundary particles in its frame
    std::size_t first = 0;    // its first particle in rx_
    Isometry3 pose = Isometry3::Identity();
    Vec3 v = Vec3::Zero(), w = Vec3::Zero();
    Vec3 impulse = Vec3::Zero(), angularImpulse = Vec3::Zero();  // summed over this step's sub-steps
    SphRigidLoad load;
  };
  struct Surface {
    BoundarySurface samples;
    std::size_t first = 0;  // its first particle in rx_
    std::vector<Vec3> vertices, velocities;
    std::vector<Vec3> impulse, load;  // per vertex: summed over this step's sub-steps; averaged
    OwnPairs own;                     // its samples' pairs, for their Ψ (ownVolumes)
  };

  SphFluidOptions o_;
  double h_ = 0.0, mass_ = 0.0, kernelScale_ = 0.0, time_ = 0.0;
  double boundaryScale_ = 1.0;  // Σ_plane W / Σ_lattice W: see the constructor
  std::vector<Vec3> x_, v_, a_, normal_;
  std::vector<double> grad_;  // ∇W (x, y, z) of every listed pair of a fluid particle, in list order
  std::vector<double> rho_, alpha_, p_, kappa_, kappaOverRho_, kappaSum_, error_;
  std::vector<double> warmDensity_, warmDivergence_;  // κ·dt², κ·dt of the last solves, per particle  // rho_
                                                      // empty: stale (refreshed at the next step)
  std::vector<Vec3> bx_;
  std::vector<Vec3> rx_;      // moving boundary particles (bodies', surfaces'), in the world
  std::vector<double> rpsi_;  // their Ψ, from their own body's or surface's particles
  std::vector<Vec3> rimp_;    // their reaction impulses (scratch of the reaction walks)
  std::vector<Rigid> rigid_;
  std::vector<Surface> surfaces_;
  std::vector<Vec3> bv_;      // every boundary particle's velocity (static, then moving)
  std::vector<double> bpsi_;  // ρ0 V_b: static, then moving
  bool boundaryDirty_ = false;
  bool boundaryMoved_ = false;  // setRigidState or setSurfaceState since the last refresh
  std::vector<Vec3> all_;       // fluid, static boundary, moving boundary positions, for the grid
  NeighborGrid grid_;
  NeighborGrid ownGrid_;        // a moving body's or surface's own particles (ownVolumes)
  std::vector<double> ownSum_;  // their kernel sums (ownVolumes' scratch)
  SphStepStats stats_;
};

template <class Inside>
std::size_t SphFluid::removeIf(Inside&& inside) {
  std::size_t kept = 0;
  for (std::size_t i = 0; i < x_.size(); ++i) {
    if (inside(x_[i])) continue;
    x_[kept] = x_[i];
    v_[kept] = v_[i];
    if (warmDensity_.size() == x_.size()) warmDensity_[kept] = warmDensity_[i];
    if (warmDivergence_.size() == x_.size()) warmDivergence_[kept] = warmDivergence_[i];
    ++kept;
  }
  const std::size_t removed = x_.size() - kept;
  if (warmDensity_.size() == x_.size()) warmDensity_.resize(kept);
  if (warmDivergence_.size() == x_.size()) warmDivergence_.resize(kept);
  x_.resize(kept);
  v_.resize(kept);
  if (removed > 0) rho_.clear();
  return removed;
}

template <class Select>
std::size_t SphFluid::displaceIf(Select&& select, const Vec3& offset) {
  std::size_t moved = 0;
  for (Vec3& x : x_)
    if (select(x)) {
      x += offset;
      ++moved;
    }
  if (moved > 0) rho_.clear();  // stale: refreshed at the next step
  return moved;
}

}  // namespace dm
