// dm/physics/mass_spring.hpp — viscoelastic mass–spring meshes: membranes,
// cloth-like tissue, sheets of fascia and skin.
//
// Model. Point masses (particles) joined by one-dimensional viscoelastic
// elements along the segment between them. With L = |x_j − x_i|, the unit
// direction n = (x_j − x_i)/L, the extension e = L − L0 and its rate
// ė = n·(v_j − v_i), an element pulls i towards j with the tension F (N):
//
//  * Kelvin–Voigt (spring ∥ damper): F = k e + c ė. A held stretch keeps its
//    force; a constant load creeps to e = F/k with time constant c/k.
//  * Maxwell (spring in series with a damper): the element keeps the damper's
//    extension e_d as internal state; F = k (e − e_d) and ė_d = F / c. A held
//    stretch relaxes as F(t) = k e exp(−t k/c) (stress relaxation); a constant
//    load makes the damper flow at ė_d = F/c (unbounded linear creep).
//
// Layouts (Provot 1995): "structural" elements join grid or mesh neighbours
// (in-plane stretch), "shear" elements the diagonals of grid cells, "bend"
// elements nodes two apart (grid) or the two opposite vertices of adjacent
// triangles (mesh) and resist folding. Each layout has its own material.
//
// Particles may also feel gravity, a constant external force each and a
// drag f = −rate·m·v from the surrounding medium (setDrag).
//
// Integration. stepSymplectic(): semi-implicit (symplectic) Euler, v ← v + h
// M⁻¹ f(x, v), x ← x + h v; one force evaluation per step, conditionally stable
// (h < 2/ω_max, ω_max² ≈ 4 k_max / m_min for the stiffest element), no
// energy drift without damping. stepImplicit(): linearly implicit backward
// Euler (Baraff & Witkin 1998): one Newton step on the springs linearised at
// the start of the step, (M + h C + h² K) Δv = h (f₀ − h K v₀), solved
// matrix-free by CG with a block-Jacobi preconditioner, warm-started from the
// previous step's Δv, with dm::PcgSolver's iteration and stopping rule; stable
// at any step for stiff tissue, with numerical damping that grows with h.
// The geometric stiffness of compressed elements is dropped (Choi & Ko 2002)
// so the system stays positive definite. Maxwell damper states advance
// exactly (exponential) in the explicit path and by backward Euler in the
// implicit path, where a Maxwell element acts over one step as a spring of
// stiffness k c / (c + h k).
//
// Units SI: m, kg, s, N; stiffness k in N/m, damping c in N·s/m.
//
// Data layout. Structure of arrays: one flat array per particle field
// (positions and velocities as 3n doubles, masses, pin flags) and per element
// field (end nodes, rest length, k, c, damper state). Stepping allocates
// nothing once the workspace is sized, which the first step after a topology
// change does (serial path; the parallel path runs oneTBB tasks, see
// dm/core/tasks.hpp, and is meant for physics threads, not the haptic loop).
// The implicit step keeps each element's block of h C + h² K in the form
// a·I + b·n nᵀ (5 floats: rounding perturbs the matrix by about 1e-7
// relative, far below any useful CG tolerance; sums are in double), with the
// elements sorted by their lower end. One CG iteration is then one sweep in
// that order that forms the search direction just ahead of itself and
// applies every block once (adding to one end, subtracting from the other;
// two owners at a time, a SIMD lane each, so that each owner's sums stay in
// its lane), and one pass over the particles; both run serially.
//
// References: X. Provot, "Deformation constraints in a mass-spring model to
// describe rigid cloth behavior", Graphics Interface 1995. D. Baraff and
// A. Witkin, "Large steps in cloth simulation", SIGGRAPH 1998. K.-J. Choi and
// H.-S. Ko, "Stable but responsive cloth", SIGGRAPH 2002. Maxwell and
// Kelvin–Voigt models: Y. C. Fung, "Biomechanics: Mechanical Properties of
// Living Tissues", 2nd ed., Springer 1993, ch. 2.
//
// @code
//   auto sheet = dm::MassSpringBody::makeSheet({.nx = 32, .ny = 32, .mass = 0.1,
//                                               .structural = {.stiffness = 500, .damping = 0.5}});
//   sheet->setPinned(0, true);
//   for (int i = 0; i < 1000; ++i) (void)sheet->stepImplicit(1e-2);
// @endcode
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace dm {

/// Constitutive model of one element.
enum class SpringModel : std::uint8_t {
  KelvinVoigt,  ///< spring parallel to a damper: F = k e + c ė
  Maxwell,      ///< spring in series with a damper: F = k (e − e_d), ė_d = F / c
};

/// Where an element comes from; counts per layout are reported by elementCount().
enum class SpringLayout : std::uint8_t {
  Structural,  ///< grid or mesh-edge neighbours
  Shear,       ///< diagonals of a grid cell
  Bend,        ///< nodes two apart, or opposite vertices of two adjacent triangles
  Custom,      ///< added by addElement() with no layout given
};

/// Number of SpringLayout values.
inline constexpr std::size_t kSpringLayoutCount = 4;

/// "KelvinVoigt" / "Maxwell".
const char* toString(SpringModel model) noexcept;
/// "structural" / "shear" / "bend" / "custom".
const char* toString(SpringLayout layout) noexcept;

/// Material of the elements of one layout.
struct SpringMaterial {
  bool enabled = true;   ///< false: the builders create no element of this layout
  double stiffness = 0;  ///< k, N/m, finite, ≥ 0
  double damping = 0;    ///< c, N·s/m, finite, ≥ 0 (> 0 for Maxwell)
  SpringModel model = SpringModel::KelvinVoigt;
};

/// Checks a material: finite k ≥ 0, c ≥ 0, and c > 0 for Maxwell (a Maxwell
/// damper without resistance carries no force). `where` names the field in
/// the message (e.g. "SpringSheetOptions.shear").
Status validateSpringMaterial(const SpringMaterial& material, const char* where);

/// A rectangular sheet of nx × ny nodes for MassSpringBody::makeSheet().
/// Node (a, b), a in [0, nx), b in [0, ny), has index a + nx·b and sits at
/// origin + a/(nx−1)·width·û + b/(ny−1)·height·v̂ (û, v̂: the normalised axes).
/// Element counts: structural (nx−1)·ny + nx·(ny−1) (2·n·(n−1) for n × n),
/// shear 2·(nx−1)·(ny−1), bend (nx−2)·ny + nx·(ny−2).
struct SpringSheetOptions {
  int nx = 2;                  ///< nodes along u, 2 … 4096
  int ny = 2;                  ///< nodes along v, 2 … 4096; nx·ny ≤ 4,194,304
  double width = 1;            ///< m along u, > 0
  double height = 1;           ///< m along v, > 0
  Vec3 origin = Vec3::Zero();  ///< m, node (0, 0)
  Vec3 uAxis = Vec3::UnitX();  ///< direction of u (normalised here), not parallel to vAxis
  Vec3 vAxis = Vec3::UnitY();  ///< direction of v (normalised here)
  double mass = 1;             ///< kg, total, split equally among the nodes
  SpringMaterial structural{true, 100, 0.1, SpringModel::KelvinVoigt};
  SpringMaterial shear{true, 50, 0.05, SpringModel::KelvinVoigt};
  SpringMaterial bend{true, 10, 0.01, SpringModel::KelvinVoigt};
};

/// Options of MassSpringBody::fromMesh().
struct MassSpringMeshOptions {
  /// kg, total; each vertex gets the share of its lumped area (a third of
  /// each adjacent triangle's area).
  double mass = 1;
  SpringMaterial structural{true, 100, 0.1, SpringModel::KelvinVoigt};  ///< one element per edge
  /// One element per interior edge (exactly two triangles) joining the two
  /// opposite vertices; pairs already joined by an edge or by an earlier bend
  /// element are skipped.
  SpringMaterial bend{true, 10, 0.01, SpringModel::KelvinVoigt};
};

/// Solver settings of a MassSpringBody.
struct MassSpringSolverOptions {
  /// Implicit path: CG stops at ‖r‖ ≤ tolerance·‖b‖ …
  double cgTolerance = 1e-6;
  /// … or after this many iterations (the last iterate is used and the step
  /// reports converged = false).
  int cgMaxIterations = 200;
  /// Run the element and node loops with dm::parallelFor when the body has at
  /// least `parallelMinParticles` particles; stepImplicit's assembly and CG
  /// sweeps scatter and stay serial. Results are bitwise identical to the
  /// serial loops (every write is to a distinct element or node). Off by
  /// default: it did not pay on the 2-core build machine (see
  /// Bench/physics_cloth_bench.cpp); measure before turning it on, and never
  /// on a real-time thread (oneTBB tasks allocate and block).
  bool parallel = false;
  /// Smallest particle count for which the loops run in parallel.
  std::size_t parallelMinParticles = 16384;
};

/// What one implicit step did.
struct ImplicitStepReport {
  int cgIterations = 0;           ///< CG iterations of the Newton step
  /// ‖r‖ / ‖b‖ at exit, r the residual CG updates by recurrence. When it
  /// converged, the true residual b − A Δv is within the tolerance too:
  /// confirmed by one more sweep, or by a bound on the rounding errors when
  /// that leaves no doubt (MassSpringBody::stepImplicit).
  double relativeResidual = 0.0;
  bool converged = true;          ///< false when CG stopped at cgMaxIterations
};

/// Read-only view of one element.
struct SpringElement {
  std::uint32_t i = 0, j = 0;  ///< end particles
  double restLength = 0;       ///< L0, m
  double stiffness = 0;        ///< k, N/m
  double damping = 0;          ///< c, N·s/m
  double damperExtension = 0;  ///< e_d, m (Maxwell state; 0 for Kelvin–Voigt)
  SpringModel model = SpringModel::KelvinVoigt;
  SpringLayout layout = SpringLayout::Custom;
};

/// A viscoelastic mass–spring mesh: its particles, elements, state and the
/// two integrators. Copyable (a copy is an independent simulation, e.g. for
/// a parallel rollout); not thread-safe.
class MassSpringBody {
 public:
  /// Largest particle count the builders accept (2048²).
  static constexpr std::size_t kMaxParticles = 4194304;

  /// An empty body; fill it with addParticle() and addElement().
  MassSpringBody() = default;

  /// A rectangular sheet; see SpringSheetOptions for indices and counts.
  /// Fails with InvalidArgument naming the field (nx, ny, width, height,
  /// mass, uAxis, vAxis, origin, structural/shear/bend) on bad input. O(nx·ny).
  /// @code
  ///   auto cloth = dm::MassSpringBody::makeSheet({.nx = 64, .ny = 64, .width = 0.2, .height = 0.2});
  ///   if (!cloth) return cloth.error();
  ///   cloth->setPinned(0, true);
  /// @endcode
  static Result<MassSpringBody> makeSheet(const SpringSheetOptions& options);

  /// A body with one particle per vertex of `mesh` (positions in metres),
  /// structural elements along its edges and bend elements across its
  /// interior edges (see MassSpringMeshOptions). Fails with InvalidArgument
  /// when the mesh is invalid (Mesh::validate()), has no non-degenerate
  /// triangle, has a vertex no non-degenerate triangle uses (remove it) or
  /// more than kMaxParticles vertices, or on a bad mass or material.
  /// O(V + F log F).
  /// @code
  ///   auto membrane = dm::MassSpringBody::fromMesh(mesh, {.mass = 0.02});
  ///   if (!membrane) return membrane.error();
  ///   membrane->setGravity({0, 0, -9.81});
  /// @endcode
  static Result<MassSpringBody> fromMesh(const Mesh& mesh, const MassSpringMeshOptions& options = {});

  // --- building -----------------------------------------------------------

  /// Appends a particle at `position` (m) with `mass` (kg, finite, > 0) and
  /// zero velocity; returns its index. Fails on a non-finite position, a bad
  /// mass or more than kMaxParticles particles.
  Result<std::uint32_t> addParticle(const Vec3& position, double mass, bool pinned = false);

  /// Appends an element between particles i ≠ j with `material` (its
  /// `enabled` flag is ignored) and rest length `restLength` (m, finite, ≥ 0;
  /// negative: the current distance). Returns its index. Fails on an index
  /// out of range, i == j or a bad material.
  /// @code
  ///   auto a = body.addParticle({0, 0, 0}, 1.0, true), b = body.addParticle({1, 0, 0}, 1.0);
  ///   auto e = body.addElement(*a, *b, {.stiffness = 100, .damping = 5, .model = dm::SpringModel::Maxwell});
  /// @endcode
  Result<std::uint32_t> addElement(std::uint32_t i, std::uint32_t j, const SpringMaterial& material,
                                   double restLength = -1.0, SpringLayout layout = SpringLayout::Custom);

  // --- particles ------------------------------------------------------------

  /// Number of particles n. O(1).
  std::size_t particleCount() const noexcept { return mass_.size(); }
  /// Position of particle i, m. i < particleCount() (DM_ASSERT).
  Vec3 position(std::size_t i) const { return x_.segment<3>(3 * Eigen::Index(i)); }
  /// Velocity of particle i, m/s.
  Vec3 velocity(std::size_t i) const { return v_.segment<3>(3 * Eigen::Index(i)); }
  /// Mass of particle i, kg.
  double mass(std::size_t i) const { return mass_[i]; }
  /// True while particle i is pinned (held in place by setPinned()).
  bool pinned(std::size_t i) const { return pinned_[i] != 0; }
  /// All positions as a flat array [x0 y0 z0 x1 …] (3n), m.
  const VecX& positions() const noexcept { return x_; }
  /// All velocities as a flat array (3n), m/s.
  const VecX& velocities() const noexcept { return v_; }
  /// Sum of the particle masses, kg. O(n).
  double totalMass() const noexcept;

  /// Moves particle i (e.g. a pinned node driven by a tool). O(1).
  void setPosition(std::size_t i, const Vec3& x);
  /// Sets the velocity of particle i (ignored while pinned). O(1).
  void setVelocity(std::size_t i, const Vec3& v);
  /// Pins (fixes in place, zero velocity) or releases particle i. O(1).
  void setPinned(std::size_t i, bool pinned);
  /// Constant external force on particle i (N) until changed; 0 initially.
  void setExternalForce(std::size_t i, const Vec3& f);
  /// Particle i's external force, N.
  Vec3 externalForce(std::size_t i) const { return fext_.segment<3>(3 * Eigen::Index(i)); }
  /// Sets particle i's mass (kg) from the next step on, e.g. a rigid body's
  /// mass lent for one step to the particles touching it
  /// (dm::ParticleObstacles::beforeStep). Fails (InvalidArgument, nothing
  /// changed) on a mass that is not finite and > 0. O(1), allocation-free.
  Status setMass(std::size_t i, double mass);
  /// Sets every external force to zero. O(n).
  void clearExternalForces();

  /// Drag on every particle, f = −rate·m·v (rate in 1/s, finite, ≥ 0; 0
  /// initially): the viscous resistance of the surrounding medium (air,
  /// interstitial fluid), which also damps rigid motions that the elements'
  /// dampers cannot. Fails on a negative or non-finite rate (nothing changes).
  Status setDrag(double rate);
  /// The drag rate, 1/s.
  double drag() const noexcept { return drag_; }

  /// Uniform gravitational acceleration, m/s²; (0, 0, 0) initially.
  void setGravity(const Vec3& g) noexcept { gravity_ = g; }
  /// The gravitational acceleration, m/s².
  const Vec3& gravity() const noexcept { return gravity_; }

  // --- elements -------------------------------------------------------------

  /// Number of elements, all layouts together. O(1).
  std::size_t elementCount() const noexcept { return ei_.size(); }
  /// Number of elements of one layout. O(1).
  std::size_t elementCount(SpringLayout layout) const noexcept {
    return layoutCount_[static_cast<std::size_t>(layout)];
  }
  /// Element e, e < elementCount() (DM_ASSERT).
  SpringElement element(std::size_t e) const;
  /// Current tension of element e, N (positive when it pulls its ends
  /// together), with the damper state as it is now. O(1).
  double elementTension(std::size_t e) const;
  /// Sum of the element forces acting on particle i, N (for a pinned node:
  /// the load it carries). O(elements).
  Vec3 elementForceOn(std::size_t i) const;

  // --- energy ----------------------------------------------------------------

  /// ½ Σ m |v|², J. O(n).
  double kineticEnergy() const;
  /// Σ ½ k (e − e_d)² over the elements (e_d = 0 for Kelvin–Voigt), J. O(elements).
  double elasticEnergy() const;
  /// −Σ m g·x, J (zero at the origin). O(n).
  double gravitationalEnergy() const;

  // --- stepping ----------------------------------------------------------------

  /// Replaces the solver options; they take effect at the next step.
  void setSolverOptions(const MassSpringSolverOptions& options) noexcept { options_ = options; }
  /// The solver options in effect.
  const MassSpringSolverOptions& solverOptions() const noexcept { return options_; }

  /// One semi-implicit (symplectic) Euler step of `h` seconds (finite, > 0):
  /// forces at (x, v), then v ← v + h f/m, x ← x + h v for free particles;
  /// Maxwell damper states relax exactly over the step at the stretch of its
  /// start. O(n + elements). Fails only on a bad h (nothing changes).
  /// @code
  ///   body.setGravity({0, 0, -9.81});
  ///   for (int i = 0; i < 1000; ++i) (void)body.stepSymplectic(1e-4);
  /// @endcode
  Status stepSymplectic(double h);

  /// One linearly implicit backward-Euler step of `h` seconds (finite, > 0)
  /// (Baraff & Witkin 1998; see the top of this header). O((n + elements) ·
  /// CG iterations). Fails on a bad h, or when CG breaks down (non-finite
  /// state); then nothing changes. Hitting cgMaxIterations is not a failure:
  /// the last iterate is applied and the report says converged = false.
  /// @code
  ///   auto r = body.stepImplicit(1e-2);
  ///   if (!r) dm::log::warn("%s", r.error().message().c_str());
  ///   else if (!r->converged) dm::log::warn("CG residual %g", r->relativeResidual);
  /// @endcode
  Result<ImplicitStepReport> stepImplicit(double h);

 private:
  // The blocks of h C + h² K of two slots (lanes 0 and 1: a slot of each
  // owner of a group) in the implicit step, B = a·I + b·n nᵀ (n: unit
  // direction; B acts on v_i − v_j for the force on the owner i), so that a
  // sweep applies two at once.
  struct SlotPair {
    float a[2], b[2], n0[2], n1[2], n2[2];
    std::uint32_t j3[2];  // 3·(higher end): offset of its x coordinate in a 3n vector
  };
  // Why the implicit solve stopped (RhsNotFinite: the step stopped before it).
  enum class CgStop : std::uint8_t { Converged, NotFinite, NotPositive, MaxIterations, RhsNotFinite };
  // The implicit step's entry points per instruction set (mass_spring.cpp).
  struct Kernels;

  void prepare();  // sizes the workspace and the incidence lists after a topology change
  template <class F>
  void forEachRange(std::size_t count, F&& fn) const;
  template <class Lead, class Trail>
  void sweepLinks(const double* v, double* y, Lead&& lead, Trail&& trail) const;
  // What the implicit solve's rounding-error bound needs of the system A Δv =
  // b of a step: anorm ≥ ‖A‖₂ (and the norm of its entries' magnitudes,
  // which bound a sweep's rounding), lambda ≤ its smallest eigenvalue (0
  // when no bound is known), x0 = ‖Δv‖ of the warm start.
  struct SystemBounds {
    double anorm = 0.0, lambda = 0.0, x0 = 0.0;
  };
  // CG from the residual r = cgR_ of the warm start dv_ (rr0 = rᵀr, rz = rᵀz, z = cgZ_).
  CgStop solveImplicit(double bnorm, double rr0, double rz, const SystemBounds& bounds,
                       ImplicitStepReport& report);
  CgStop stepImplicitCore(double h, ImplicitStepReport& report);  // stepImplicit after its checks
  void updateMaxwellDecay(double h);

  // Particles (structure of arrays).
  VecX x_, v_, fext_;                 // 3n
  std::vector<double> mass_;          // n
  std::vector<std::uint8_t> pinned_;  // n
  Vec3 gravity_ = Vec3::Zero();
  double drag_ = 0.0;

  // Elements (structure of arrays).
  std::vector<std::uint32_t> ei_, ej_;
  std::vector<double> rest_, k_, c_, ed_;
  std::vector<std::uint8_t> maxwell_, layout_;
  std::size_t layoutCount_[kSpringLayoutCount] = {0, 0, 0, 0};

  MassSpringSolverOptions options_;

  // Workspace (derived; rebuilt by prepare()).
  bool prepared_ = false;
  std::vector<std::uint32_t> incStart_, incElem_;  // CSR: elements incident to each particle
  // Implicit path: the elements in "slots" of their lower end, the owner;
  // owners 2g and 2g + 1 form group g and share its slot pairs, one lane
  // each (prepare()). ownStart_: CSR of the slot pairs over the groups;
  // linkElem_: the element in each slot (kNoElement: padding), linkOther_:
  // its higher end (padding: the owner); leadUntil_[g]: one past the highest
  // particle reached by groups 0 … g, their owners included.
  static constexpr std::uint32_t kNoElement = 0xffffffffu;
  std::vector<std::uint32_t> ownStart_, linkElem_, linkOther_, leadUntil_;
  std::vector<SlotPair> blocks_;  // per two slots (implicit)
  // Per slot (padding: zeros): rest length, axial stiffness and damping of
  // the element over a step of slotH_ (Maxwell: k/(1 + h k/c) and 0), damper
  // extension (Maxwell only, copied at each implicit step).
  std::vector<double> slotRest_, slotK_, slotC_, slotEd_;
  double slotH_ = -1.0;
  std::size_t maxwellCount_ = 0;
  double massMin_ = 0.0, massMax_ = 0.0;  // over all particles
  bool massRangeStale_ = false;           // setMass ran: massMin_/massMax_ to redo
  std::uint32_t degreeMax_ = 0;           // most elements at one particle
  // 3 per element: force on i (explicit); 6 per slot pair, x x' y y' z z':
  // the right-hand-side terms on the owners of its two slots (implicit).
  std::vector<double> ef_;
  std::vector<double> decay_;  // per element: exp(−h k/c) for Maxwell, at decayH_
  double decayH_ = -1.0;
  double massScale_ = 1.0;      // 1 + h·drag during an implicit step
  std::vector<double> dsum_;  // 6 per particle: diagonal block xx xy xz yy yz zz while assembled (implicit)
  // Inverse diagonal blocks, interleaved by particle pairs: entry c of
  // particle i at 12 (i/2) + 2 c + i%2 (implicit).
  std::vector<double> dinv_;
  // Per particle, padded to an even count: 1 for a free particle, 0 for a
  // pinned one and the padding (implicit; set by each step's assembly).
  std::vector<double> freeMask_;
  VecX rhs_, dv_;               // 3n: right-hand side and solution Δv of the implicit step
  VecX cgR_, cgZ_, cgP_, cgQ_;  // 3n: CG residual, preconditioned residual, direction, A·direction
};

}  // namespace dm
