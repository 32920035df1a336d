// dm/physics/fem.hpp — volumetric soft tissue: co-rotational linear FEM on
// tetrahedra, implicit (backward Euler) integration, Rayleigh damping.
//
// What it is for: deformable organs and tissue blocks built from a voxel
// model (segmentation mask, CT/MRI threshold) or from a box, simulated at
// interactive rates and rendered / collided through their boundary surface.
//
// Model
//  * TetMesh: rest positions (m) and tetrahedra (4 node indices, positive
//    orientation: det[x1−x0, x2−x0, x3−x0] > 0). Built from voxels by the
//    Kuhn (Freudenthal) split of each cube into six tetrahedra around its
//    main diagonal, so neighbouring cubes' faces are split the same way and
//    the mesh is conforming; nodes shared by voxels are deduplicated.
//  * Hierarchical grids (tetMeshHierarchical): an octree over the voxels,
//    voxel-sized cells where the tool works and cells of 2, 4, … voxels
//    away from it, 2:1 balanced, each cell split the same Kuhn way. Where a
//    fine cell meets a coarse one, the fine corners on the coarse edge or
//    face are hanging nodes constrained to the midpoint of the coarse edge
//    or of the face's Kuhn diagonal (so every fine face lies inside a coarse
//    triangle and the displacement stays continuous).
//  * Linear elasticity (Young's modulus E in Pa, Poisson ratio ν), constant
//    strain tetrahedra: the 12×12 element stiffness Kₑ is fixed by the rest
//    shape, K_ij = V(μ(g_i·g_j)I + μ g_j g_iᵀ + λ g_i g_jᵀ) with g_i the shape
//    function gradients, μ, λ the Lamé parameters (evaluated from the rest
//    gradients when assembling rather than stored: less memory traffic).
//  * Co-rotation (Müller & Gross 2004, "Interactive virtual materials",
//    GI'04; Müller et al. 2002 "Stable real-time deformations"): each step the
//    rotation Rₑ of the element is extracted from its deformation gradient
//    F = D_s D_m⁻¹ (rotational part of the polar decomposition, computed with
//    the warm-started quaternion iteration of Müller, Bender, Chentanez &
//    Macklin 2016, "A robust method to extract the rotational part of
//    deformations", which stays a proper rotation for inverted elements) and
//    the elastic force is fₑ = −Rₑ Kₑ (Rₑᵀ x − x₀), stiffness Rₑ Kₑ Rₑᵀ. Rigid
//    motions therefore produce no force, unlike plain linear FEM.
//  * Lumped mass: each tetrahedron gives ρV/4 to each of its nodes.
//  * Rayleigh damping C = αM + βK (α in 1/s, β in s).
//
// Integration (Baraff & Witkin 1998, "Large steps in cloth simulation"):
// one linearised backward-Euler step of size h solves
//     (M + hC + h²K) Δv = h (f(x) + f_ext + M g − C v − h K v),
//     v ← v + Δv,  x ← x + h v,
// with K, f linearised at the current rotations. The system is symmetric
// positive definite (M > 0, RKRᵀ ⪰ 0) and is solved by preconditioned
// conjugate gradient (dm::PcgSolver, matrix-free entry point) on our own
// 3×3-block sparse matrix (node-by-node pattern fixed at creation, upper
// triangle only since K is symmetric; each element knows the block slots it
// adds into, so re-assembly neither allocates nor searches), with a block
// symmetric Gauss–Seidel preconditioner (or block Jacobi, the inverse of
// each node's 3×3 diagonal block) and the previous Δv as the initial guess. Fixed nodes
// (Dirichlet) are eliminated by projection: their rows and columns are the
// identity and their right-hand side is zero; a fixed node moves with its
// prescribed velocity (zero unless set), which enters the free rows'
// right-hand side through −h(β + h)·K v.
// Hanging nodes are eliminated the same way as fixed ones: with P the map
// from independent to all node velocities, PCG solves Pᵀ A P Δv = Pᵀ b
// matrix-free (assembly is unchanged; the product expands the input to the
// hanging rows and folds their output back onto the masters), and a
// hanging node's state is its masters' mean after every step.
// Contact: rigid obstacles (FemObstacle, closed meshes) push the boundary
// nodes they contain out along their normal with penalty springs, and one
// contact spring pulls a boundary point toward an anchor (a haptic tool),
// and point springs (FemPointSpring: anisotropic, at points inside
// tetrahedra) hold material points to a tool (a needle's shaft); all enter
// the system matrix (h²k terms), so stiff contact stays stable.
// A dynamic obstacle (mass > 0, a free rigid body) adds six unknowns, its
// velocity change, to that system: the contact springs act on both sides
// (dm/physics/soft_rigid.hpp couples such bodies to a PhysicsWorld).
// Cutting: dm::TetCutter (dm/physics/tet_cut.hpp) splits elements along a
// blade's swept surface by the virtual node algorithm, and applyCut() takes
// each of its updates into the body in place (new nodes, element copies
// whose material fraction, TetMesh::fractions, scales their mass and
// stiffness, the block pattern and colouring updated, not rebuilt).
// Element loops run in parallel with dm::parallelFor over a greedy element
// colouring (elements of one colour share no node) and the system product
// row by row, so the result does not depend on the thread count.
//
// Units: SI throughout (m, kg, s, N, Pa, J).
//
// @code
//   auto mesh = dm::tetMeshBox({8, 8, 8}, dm::Vec3(0.05, 0.05, 0.05));
//   auto body = dm::FemBody::create(*mesh, {.youngsModulus = 3e4, .poissonRatio = 0.45, .density = 1000});
//   body->setGravity({0, 0, -9.81});  auto rep = body->step(1.0 / 100);  // rep->cgIterations
// @endcode
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/pose.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/math/linear.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace dm {

class MeshBvh;
class Volume;
class TetCutter;
struct CutUpdate;

/// A zero-length spring from a material point of the body, Σ wᵢ x_{nodes[i]}
/// over up to four nodes (a point inside a tetrahedron: its barycentric
/// coordinates; unused entries weigh 0), to an anchor, with a 3×3 stiffness:
/// anisotropic where a tool holds tissue differently across and along it (a
/// needle's shaft: stiff across, sliding along). Integrated implicitly by
/// FemBody::step() like the contact spring. Set as a group
/// (FemBody::setPointSprings), e.g. by dm::NeedleInsertion each step.
struct FemPointSpring {
  std::array<std::uint32_t, 4> nodes{};
  std::array<double, 4> weights{};  ///< ≥ 0, summing to 1
  Vec3 anchor = Vec3::Zero();       ///< m, the body's frame
  Mat3 stiffness = Mat3::Zero();    ///< N/m, symmetric positive semi-definite
  /// N, a constant force on the point besides the spring's (a needle tip's
  /// cutting force); zero stiffness and a load make a point load.
  Vec3 load = Vec3::Zero();
  /// across·(I − d dᵀ) + along·d dᵀ for a unit direction d: a spring that
  /// holds across d with `across` N/m and along it with `along` N/m.
  static Mat3 axial(const Vec3& unitDirection, double across, double along) {
    const Mat3 ddt = unitDirection * unitDirection.transpose();
    return across * (Mat3::Identity() - ddt) + along * ddt;
  }
};

/// A rigid obstacle the tissue rests on or is pushed by (a bone, an
/// instrument, a table): a closed mesh's tree (MeshBvh::isClosed(), so
/// distances are signed) at a pose, moved by the caller between steps.
/// Along the normal a penalty spring; across it viscous friction
/// (`friction`, a damper on the sliding velocity, implicit; no static
/// friction: a body on a slope creeps), 0 = frictionless.
///
/// Kinematic (mass 0): the caller moves it (setObstaclePose, and
/// setObstacleVelocity for the contact's damping term); the tissue does not
/// move it. Dynamic (mass > 0): a free rigid body (a bone fragment, a
/// dropped instrument) whose velocity each step solves together with the
/// tissue's, with the same implicit contact springs between them (two-way
/// coupling, stable for stiff contact on light bodies); its other forces
/// (gravity, joints) are the caller's, e.g. dm::SoftRigidCoupling applies
/// the solved velocity change to a PhysicsWorld body.
struct FemObstacle {
  const MeshBvh* tree = nullptr;  ///< closed, local frame; must outlive its use
  Isometry3 pose = Isometry3::Identity();  ///< local → body frame, rigid
  /// N/m per boundary node in contact, > 0: the implicit penalty spring
  /// along the obstacle's normal. A node sinks about (its load) / stiffness.
  double stiffness = 1e4;
  /// N·s/m per boundary node in contact, ≥ 0: the tangential damper −c·(v −
  /// u) on the node's velocity across the normal relative to the obstacle's
  /// surface (and its reaction on a dynamic obstacle), integrated implicitly
  /// with the spring. It stops sliding and spinning on the tissue.
  double friction = 0.0;
  double mass = 0.0;                  ///< kg, ≥ 0; 0 = kinematic
  Mat3 inertia = Mat3::Identity();    ///< kg·m², about the centre of mass, local frame (dynamic only; SPD)
  Vec3 centerOfMass = Vec3::Zero();   ///< m, local frame: where velocities and torques refer to
};

/// Four node indices of a tetrahedron, positively oriented.
using Tet = std::array<std::uint32_t, 4>;

/// A node that is a corner of fine tetrahedra but lies on an edge or face
/// of a coarser neighbour (a T-junction of a hierarchical grid): its position
/// and velocity are the mean of its two masters', which keeps the
/// displacement field continuous across the coarse–fine interface. A master
/// may itself hang (chains resolve to independent nodes). Its rest position
/// must be the masters' midpoint.
struct HangingNode {
  std::uint32_t node = 0;
  std::array<std::uint32_t, 2> masters{};
};

/// A tetrahedral mesh at rest. Positions in metres.
struct TetMesh {
  std::vector<Vec3> nodes;  ///< rest positions, m
  std::vector<Tet> tets;    ///< det[x1−x0, x2−x0, x3−x0] > 0 for each
  /// Constrained nodes (empty for a conforming mesh); tetMeshHierarchical()
  /// fills it, at most one entry per node.
  std::vector<HangingNode> hanging;
  /// The share of each tetrahedron's volume that is material, in (0, 1]:
  /// empty (the usual) = all 1. A cut mesh's copies of one element hold
  /// parts of it (dm/physics/tet_cut.hpp); FemBody scales their mass and
  /// stiffness by it.
  std::vector<double> fractions;

  std::size_t nodeCount() const noexcept { return nodes.size(); }
  std::size_t tetCount() const noexcept { return tets.size(); }
  /// Signed volume of tetrahedron t (m³), positive when correctly oriented.
  double tetVolume(std::size_t t) const;
  /// Σ tetVolume over all tetrahedra, m³. O(T).
  double totalVolume() const;
  /// Checks indices in range, no repeated index within a tetrahedron, finite
  /// positions and positive volumes, fractions (none or one per
  /// tetrahedron, each in (0, 1]), and hanging nodes (indices in range,
  /// two distinct masters other than the node, at their masters' midpoint,
  /// one entry per node, no cycle); errors name the tetrahedron, node or
  /// hanging entry.
  Status validate() const;
};

/// Limits and threshold of the voxel builders.
struct VoxelTetOptions {
  /// A voxel is occupied when its value is ≥ threshold (tetMeshFromVolume).
  double threshold = 0.5;
  /// Upper bound on the number of tetrahedra (6 per occupied voxel); a larger
  /// model is rejected before anything is allocated for it.
  std::size_t maxTets = 4'000'000;
};

/// Tetrahedral mesh of the occupied voxels of a dense grid: `occupancy` has
/// dims.x·dims.y·dims.z entries, x fastest, nonzero = occupied. Voxel
/// (i, j, k) is the box origin + [i, i+1]×[j, j+1]×[k, k+1] ⊙ spacing (m).
/// Six tetrahedra per voxel (Kuhn split), shared corners deduplicated, so the
/// total volume is count · spacing.x·spacing.y·spacing.z. O(voxels) time,
/// O(dims.x·dims.y + output) memory. Fails (InvalidArgument, naming the field)
/// on non-positive dims, a size mismatch, non-positive or non-finite spacing,
/// no occupied voxel, or more than options.maxTets tetrahedra.
/// @code
///   std::vector<std::uint8_t> occ(4 * 4 * 4, 1);
///   auto mesh = dm::tetMeshFromOccupancy(occ, {4, 4, 4}, dm::Vec3::Constant(0.01));
///   // mesh->tetCount() == 384
/// @endcode
Result<TetMesh> tetMeshFromOccupancy(std::span<const std::uint8_t> occupancy, const Vec3i& dims,
                                     const Vec3& spacing, const Vec3& origin = Vec3::Zero(),
                                     const VoxelTetOptions& options = {});

/// Tetrahedral mesh of the voxels of `volume` whose value is ≥
/// options.threshold. Voxel (i, j, k) is the cube of index coordinates
/// [i−½, i+½]×[j−½, j+½]×[k−½, k+½] mapped by volume.indexToWorld() (its
/// centre is the voxel centre), so each tetrahedron volume is scaled by
/// |det| of the affine; a mirroring affine is handled (orientation kept
/// positive). Fails like tetMeshFromOccupancy(), and on a NaN threshold.
/// @code
///   auto seg = dm::loadVolume("liver_mask.nii.gz");
///   auto mesh = dm::tetMeshFromVolume(*seg, {.threshold = 0.5, .maxTets = 200'000});
///   if (!mesh) dm::log::warn("%s", mesh.error().message().c_str());
/// @endcode
Result<TetMesh> tetMeshFromVolume(const Volume& volume, const VoxelTetOptions& options = {});

/// Box [origin, origin + size] split into cells.x·cells.y·cells.z cubes
/// (cuboids) of six tetrahedra each. Fails on non-positive cells or size, or
/// more than maxTets tetrahedra.
/// @code
///   auto beam = dm::tetMeshBox({40, 4, 4}, dm::Vec3(0.2, 0.02, 0.02));
///   // beam->nodeCount() == 41 * 5 * 5
/// @endcode
Result<TetMesh> tetMeshBox(const Vec3i& cells, const Vec3& size, const Vec3& origin = Vec3::Zero(),
                           std::size_t maxTets = VoxelTetOptions{}.maxTets);

/// Options of tetMeshHierarchical(): how coarse cells grow away from the
/// region of interest.
struct HierarchicalTetOptions {
  /// Coarsest cells are 2^levels voxels across (0: every voxel its own cell,
  /// the mesh of tetMeshFromOccupancy). 0..10.
  int levels = 2;
  /// Box (m, the mesh's frame) kept at voxel resolution: where the tool
  /// works. Empty (the default) = no such region: cells are as coarse as
  /// the occupancy allows.
  Aabb fineRegion;
  /// A cell of side s stays whole only while its distance to fineRegion is
  /// at least grading·s (finite, ≥ 0): larger values keep more fine cells
  /// around the region.
  double grading = 1.0;
  /// Upper bound on the number of tetrahedra, checked before any is made.
  std::size_t maxTets = 4'000'000;
};

/// Hierarchical (octree) tetrahedral mesh of the occupied voxels of a dense
/// grid (same layout, spacing and origin as tetMeshFromOccupancy()): voxels
/// in and near options.fineRegion, and cells of 2, 4, … voxels further away
/// wherever all their voxels are occupied (so the boundary keeps the voxel
/// shape).
/// Neighbouring cells across a face or an edge differ by one level at most
/// (2:1 balance); each cell is split into the same six Kuhn tetrahedra, and
/// the fine corners on a coarse neighbour's edge or face are hanging nodes
/// (TetMesh::hanging) at the midpoint of that edge or of the face's Kuhn
/// diagonal, so the displacement is continuous. The cells cover exactly the
/// occupied voxels (volume = count · voxel volume). O(voxels + cells) time;
/// memory one byte per voxel plus the mesh. Fails like tetMeshFromOccupancy()
/// and on levels outside 0..10 or a negative or non-finite grading.
/// @code
///   dm::HierarchicalTetOptions opt{.levels = 3, .fineRegion = dm::Aabb(lo, hi)};
///   auto organ = dm::tetMeshHierarchical(mask, dims, spacing, origin, opt);
///   // organ->hanging.size() nodes follow their coarse neighbours
/// @endcode
Result<TetMesh> tetMeshHierarchical(std::span<const std::uint8_t> occupancy, const Vec3i& dims,
                                    const Vec3& spacing, const Vec3& origin = Vec3::Zero(),
                                    const HierarchicalTetOptions& options = {});

/// Boundary faces of a tetrahedral mesh (faces that belong to exactly one
/// tetrahedron), counter-clockwise seen from outside, indexing mesh.nodes.
/// For a conforming mesh the result is closed and consistently oriented.
/// Faces on a coarse–fine interface of a hierarchical mesh (a coarse face
/// and the fine faces inside it, found through TetMesh::hanging) are
/// interior and left out; the boundary then has T-junctions where a fine
/// face meets a coarse one (no gap: hanging nodes stay on the coarse edge).
/// O(T log T) time, O(T) memory.
std::vector<Triangle> tetMeshSurface(const TetMesh& mesh);

/// Elastic material. E and ν of soft tissue: liver ~ 5–20 kPa, ν ≈ 0.45.
struct FemMaterial {
  double youngsModulus = 1.0e4;  ///< E, Pa (> 0)
  double poissonRatio = 0.45;    ///< ν, in [0, 0.5)
  double density = 1000.0;       ///< ρ, kg/m³ (> 0)
};

/// Rayleigh (viscoelastic) damping C = α M + β K.
struct FemDamping {
  double alpha = 0.0;  ///< mass-proportional, 1/s (≥ 0); also damps free rigid motion
  double beta = 0.0;   ///< stiffness-proportional, s (≥ 0); damps high-frequency strain rates
};

/// PCG preconditioner of FemBody's implicit step.
enum class FemPreconditioner {
  /// Inverse 3×3 diagonal block per node: cheapest per iteration and fully
  /// parallel, but ~3× the iterations on stiff, nearly incompressible tissue.
  BlockJacobi,
  /// Block symmetric Gauss–Seidel, M = (D + L) D⁻¹ (D + U) over the node
  /// blocks of h²K + … (one forward and one backward sweep per iteration, on
  /// the calling thread): a third of block Jacobi's iterations.
  SymmetricGaussSeidel,
};

/// Solver settings of FemBody.
struct FemSolverOptions {
  /// PCG stops when ‖b − AΔv‖ ≤ tolerance · max(‖b‖, h(‖f_elastic‖ +
  /// ‖f_ext + Mg‖)) over free nodes: relative to the right-hand side, or to
  /// the forces it balances when those are larger (near equilibrium).
  double tolerance = 1e-4;
  /// PCG iteration limit per step; reaching it is not an error (the step
  /// uses the last iterate and FemStepReport::converged is false).
  int maxIterations = 200;
  /// Start PCG from the previous step's Δv (else from zero).
  bool warmStart = true;
  FemPreconditioner preconditioner = FemPreconditioner::SymmetricGaussSeidel;
  /// Co-rotational (true) or plain linear FEM (false; Rₑ = I, wrong under
  /// rotation — for comparison only).
  bool corotational = true;
  /// Run element and matrix loops with dm::parallelFor (the calling thread's
  /// task arena); false runs everything on the calling thread. Either way
  /// the result does not depend on the number of threads; the two settings
  /// sum the system product in different orders (rows gathered in parallel,
  /// blocks scattered serially), so they agree to round-off, not bit for bit.
  bool parallel = true;
  /// Iterations of the polar (rotation) extraction per element and step
  /// (warm started from the last step; Newton steps stop once a step is
  /// under 1e-4 rad, which leaves an error of order 1e-8 rad — a relative
  /// force error far below the PCG tolerance — and the next step starts
  /// from there: usually 1–2).
  int polarIterations = 20;
};

/// What one FemBody::step() did.
struct FemStepReport {
  int cgIterations = 0;           ///< PCG iterations of this step
  double relativeResidual = 0.0;  ///< ‖b − AΔv‖/‖b‖ reached
  bool converged = true;          ///< tolerance reached within maxIterations
};

/// A deformable body: co-rotational linear FEM on a TetMesh with implicit
/// integration. Holds the rest model (element stiffness, lumped masses,
/// matrix pattern, colouring) and the state (positions, velocities,
/// rotations). step() does not allocate once created (except the message of
/// a solver failure). Not thread-safe; step() itself may use worker threads.
class FemBody {
 public:
  /// Builds the body at rest (positions = mesh.nodes, velocities 0).
  /// O(T log T) time, O(T) memory (~0.5 kB per tetrahedron). Fails (InvalidArgument)
  /// on an invalid mesh (see TetMesh::validate()), a material or damping
  /// value out of range, or non-positive solver tolerance / iterations.
  /// @code
  ///   auto body = dm::FemBody::create(*mesh, {.youngsModulus = 5e3}, {.alpha = 1.0, .beta = 0.01});
  ///   if (!body) return body.error();
  ///   body->setFixed(0, true);
  /// @endcode
  static Result<FemBody> create(const TetMesh& mesh, const FemMaterial& material,
                                const FemDamping& damping = {}, const FemSolverOptions& options = {});

  /// Advances by h seconds (one linearised backward-Euler step). Fails
  /// (InvalidArgument) on h ≤ 0 or non-finite, or if the system is found not
  /// positive definite / non-finite (a blown-up state: positions untouched).
  /// Cost per step: O(T) assembly plus O(nnz) per CG iteration.
  /// @code
  ///   for (int i = 0; i < 100; ++i)
  ///     if (auto r = body.step(0.01); !r) return r.error();
  ///     else iterations += r->cgIterations;
  /// @endcode
  Result<FemStepReport> step(double h);

  /// Number of nodes / tetrahedra.
  std::size_t nodeCount() const noexcept { return x_.size(); }
  std::size_t tetCount() const noexcept { return tets_.size(); }
  /// The rest mesh given to create().
  const std::vector<Vec3>& restPositions() const noexcept { return x0_; }
  const std::vector<Tet>& tets() const noexcept { return tets_; }
  /// Current node positions (m) and velocities (m/s), one per node.
  const std::vector<Vec3>& positions() const noexcept { return x_; }
  const std::vector<Vec3>& velocities() const noexcept { return v_; }
  /// Lumped node masses (kg) and their sum.
  const std::vector<double>& masses() const noexcept { return mass_; }
  double totalMass() const noexcept { return totalMass_; }

  /// Overwrites all positions / velocities (sizes must equal nodeCount();
  /// DM_DEMAND). Fixed nodes take the given values too: a fixed node's
  /// velocity is its prescribed velocity (see setFixed). Hanging nodes take
  /// their masters' mean instead of the given value.
  void setPositions(std::span<const Vec3> x);
  void setVelocities(std::span<const Vec3> v);

  /// Fixes (Dirichlet) or frees node i. Fixing sets its velocity to zero, so
  /// it keeps its position; a velocity given afterwards (setVelocity,
  /// setVelocities) is prescribed: step(h) moves the node by h·v, and the
  /// free nodes feel that motion implicitly (their stiffness and damping
  /// rows include it), which is how a tool pushes tissue (an indenter, a
  /// clamp). Out-of-range i, or a hanging node (it follows its masters: fix
  /// those), is a DM_DEMAND failure.
  void setFixed(std::size_t i, bool fixed);
  /// Velocity of node i (m/s); for a fixed node, its prescribed velocity.
  /// Out-of-range i, a hanging node or a non-finite v is a DM_DEMAND failure.
  void setVelocity(std::size_t i, const Vec3& v);
  bool isFixed(std::size_t i) const { return fixed_[i] != 0; }
  /// Fixes every node whose rest position p satisfies pred(p), hanging nodes
  /// excepted (on a clamped plane their masters are clamped too). Returns
  /// the count fixed.
  template <class Pred>
  std::size_t fixNodesWhere(Pred&& pred) {
    std::size_t n = 0;
    for (std::size_t i = 0; i < x0_.size(); ++i)
      if (!hanging_[i] && pred(x0_[i])) setFixed(i, true), ++n;
    return n;
  }
  /// Hanging nodes (TetMesh::hanging): their position and velocity are
  /// weighted means of independent nodes, re-derived by every step(),
  /// setPositions() and setVelocities(); forces on them (external, contact,
  /// elastic) act on those nodes with the same weights.
  bool isHanging(std::size_t i) const { return hanging_[i] != 0; }
  std::size_t hangingCount() const noexcept { return hangNode_.size(); }

  /// Constant external force on node i (N), kept until changed or cleared.
  void setExternalForce(std::size_t i, const Vec3& f);
  void clearExternalForces();
  /// A zero-length spring of `stiffness` (N/m) from the body point
  /// Σ wᵢ x_{nodes[i]} to a fixed `anchor` (m), integrated implicitly by
  /// step() (its h²·k wᵢwⱼ terms join the system matrix): how a tool held by
  /// a stiff coupling, such as a haptic proxy's spring of several hundred
  /// N/m, pushes and drags tissue whose nodes weigh milligrams, where the
  /// same force applied explicitly (setExternalForce from the last state)
  /// would oscillate and grow. One spring at a time, kept until replaced or
  /// cleared; a fixed node among `nodes` is not moved by it. Fails
  /// (InvalidArgument, spring unchanged) on a node index out of range,
  /// weights that are negative, not finite or do not sum to 1 (±1e-6), a
  /// non-finite anchor, or a stiffness that is negative or not finite.
  /// Never allocates on success.
  /// @code
  ///   body.setContactSpring(tri, barycentric, devicePointLocal, 800.0);
  ///   body.step(0.01);
  ///   dm::Vec3 onHand = -body.contactSpringForce();
  /// @endcode
  Status setContactSpring(const std::array<std::uint32_t, 3>& nodes, const Vec3& weights, const Vec3& anchor,
                          double stiffness);
  void clearContactSpring() noexcept { spring_.active = false; }
  bool hasContactSpring() const noexcept { return spring_.active; }
  /// The force (N) the contact spring applies to the body at the current
  /// positions, k·(anchor − Σ wᵢxᵢ); zero without one.
  Vec3 contactSpringForce() const noexcept;
  /// Point springs (FemPointSpring), replacing the previous set; an empty
  /// span removes them. They act beside the contact spring and the
  /// obstacles, with the same implicit terms (h²·wᵢwⱼ·K between their
  /// nodes). Fails (InvalidArgument naming the spring, set unchanged) on a
  /// node out of range, weights that are negative, not finite or do not sum
  /// to 1 (±1e-6), a non-finite anchor or load, or a stiffness that is not finite,
  /// not symmetric or not positive semi-definite. Allocates only when the
  /// set outgrows every earlier one.
  /// @code
  ///   dm::FemPointSpring s{.nodes = tet, .weights = bary, .anchor = onShaft,
  ///                        .stiffness = dm::FemPointSpring::axial(shaftDir, 300.0, 50.0)};
  ///   body.setPointSprings({&s, 1});
  ///   body.step(1e-3);
  ///   dm::Vec3 onNeedle = -body.pointSpringForce(0);
  /// @endcode
  Status setPointSprings(std::span<const FemPointSpring> springs);
  std::size_t pointSpringCount() const noexcept { return points_.size(); }
  /// The force (N) point spring i applies to the body at the current
  /// positions, K·(anchor − Σ wᵢxᵢ) + load; zero for an index out of range.
  Vec3 pointSpringForce(std::size_t i) const noexcept;
  /// Rigid obstacles (soft–rigid contact), replacing the previous set; an
  /// empty span removes them. Each step finds the boundary nodes inside an
  /// obstacle (signed distance to its closed mesh, negative inside) and
  /// pushes each out along the obstacle's normal with a penalty spring of
  /// the obstacle's stiffness, integrated implicitly like the contact
  /// spring (h²k·nnᵀ in the node's diagonal block): stable for stiff
  /// obstacles on light nodes. Fixed nodes are not pushed. Fails
  /// (InvalidArgument naming the obstacle, set unchanged) on a null or open
  /// tree, a non-rigid or non-finite pose, a stiffness that is not positive
  /// and finite, a negative or non-finite mass, or (dynamic) an inertia that
  /// is not symmetric positive definite. Velocities start at zero.
  /// Allocates the per-node contact storage and the solver's rows for the
  /// dynamic obstacles (six each) once.
  /// @code
  ///   dm::FemObstacle bone{.tree = &boneTree, .pose = bonePose, .stiffness = 5e4};
  ///   body.setObstacles({&bone, 1});
  ///   body.step(0.01);
  ///   dm::Vec3 onBone = body.obstacleForce(0);
  /// @endcode
  Status setObstacles(std::span<const FemObstacle> obstacles);
  /// Moves obstacle i (a tool following a device) for the next steps;
  /// false (unchanged) for an index out of range or a non-rigid pose.
  bool setObstaclePose(std::size_t i, const Isometry3& pose) noexcept;
  /// Velocity of obstacle i's centre of mass (m/s) and its angular velocity
  /// (rad/s), body frame, at the start of the next step: a kinematic
  /// obstacle keeps it (the contact damps the relative velocity), a dynamic
  /// one starts the step from it. False (unchanged) for an index out of
  /// range or non-finite values.
  bool setObstacleVelocity(std::size_t i, const Twist& velocity) noexcept;
  /// Obstacle i's velocity: for a dynamic obstacle, after the last step's
  /// contact (its start velocity plus what the tissue did to it); zero
  /// twist for an index out of range.
  Twist obstacleVelocity(std::size_t i) const noexcept;
  std::size_t obstacleCount() const noexcept { return obstacles_.size(); }
  /// The force (N, body frame) the tissue applied to obstacle i in the last
  /// step (the penalty springs at the step's end state); zero for an index
  /// out of range.
  Vec3 obstacleForce(std::size_t i) const noexcept;
  /// That force with its torque (N·m) about the obstacle's centre of mass
  /// (pose · centerOfMass); zero for an index out of range.
  Wrench obstacleWrench(std::size_t i) const noexcept;
  /// Boundary nodes in contact with an obstacle during the last step.
  std::size_t obstacleContactCount() const noexcept { return contacts_.size(); }
  /// Uniform gravitational acceleration (m/s²), default zero.
  void setGravity(const Vec3& g) noexcept { gravity_ = g; }
  const Vec3& gravity() const noexcept { return gravity_; }

  void setSolverOptions(const FemSolverOptions& options);
  const FemSolverOptions& solverOptions() const noexcept { return options_; }
  const FemMaterial& material() const noexcept { return material_; }
  const FemDamping& damping() const noexcept { return damping_; }
  void setDamping(const FemDamping& d) noexcept { damping_ = d; }

  /// Elastic (co-rotated or linear, per options) strain energy at the
  /// current positions, J: Σₑ ½ uₑᵀ Kₑ uₑ with uₑ = Rₑᵀx − x₀. O(T).
  double elasticEnergy() const;
  /// Kinetic energy ½ Σ mᵢ|vᵢ|², J.
  double kineticEnergy() const;
  /// Stress of element e (Pa, body frame) at the current positions:
  /// R·σ·Rᵀ with σ = 2μ ε + λ tr(ε) I of the co-rotated strain ε = sym(RᵀF)
  /// − I and R the element's rotation from the last step (identity for
  /// plain linear FEM): the Cauchy stress of small strains, rotations
  /// removed. Constant over the element. Out-of-range e is a DM_DEMAND
  /// failure.
  Mat3 elementStress(std::size_t e) const;
  /// Elastic node forces at the current positions (N), resized to
  /// nodeCount(); same rotations as elasticEnergy(). O(T).
  void computeElasticForces(std::vector<Vec3>& out) const;
  /// The force (N) each fixed node's constraint applies to the body to hold
  /// it on its prescribed motion, at the current state: −(f_elastic +
  /// f_damping + f_ext + m·g) with f_damping = −(αM + βK)v, K as assembled
  /// by the last step; zero for free nodes; resized to nodeCount(). The
  /// fixed node's own inertia is left out (exact at rest and for a constant
  /// prescribed velocity). Summed over an indenter's nodes and negated, it
  /// is the force the tissue exerts on the indenter. O(T + nnz); allocates
  /// only when `out` is smaller than nodeCount().
  /// @code
  ///   std::vector<dm::Vec3> r;  body.computeConstraintForces(r);
  ///   dm::Vec3 onTool = dm::Vec3::Zero();
  ///   for (auto i : punchNodes) onTool -= r[i];
  /// @endcode
  void computeConstraintForces(std::vector<Vec3>& out) const;
  /// Σ mᵢ vᵢ, kg·m/s, and the centre of mass, m.
  Vec3 linearMomentum() const;
  Vec3 centerOfMass() const;

  /// Boundary triangles (CCW from outside) indexing positions(); computed
  /// once at creation.
  const std::vector<Triangle>& surfaceTriangles() const noexcept { return surface_; }
  /// The boundary surface as a Mesh at the current positions. Positions are
  /// all nodes (interior ones unreferenced), so indices stay those of the
  /// body; `out` keeps its capacity between calls.
  void surfaceMesh(Mesh& out) const;

  /// Applies what TetCutter::cut() changed (`update`) to this body, which
  /// must have been created from the cutter's mesh and kept in step with
  /// every update since: new nodes start from their sources' state (position,
  /// velocity, fixed or not; no external force), changed and new elements
  /// take their copies' nodes and material fractions (mass and stiffness
  /// scale with them; a new copy starts from its original's rotation), and
  /// the solver's structures are updated in place: the node masses of the
  /// changed elements, the block pattern merged with their new node pairs
  /// (pairs no element uses any more stay as zero blocks), the changed
  /// elements recoloured into colours their nodes leave free. O(changed
  /// elements + nnz) (a linear pass over the pattern, no sort), far below
  /// building the body anew; it allocates. Fails (InvalidArgument, body
  /// unchanged) on a body with hanging nodes, or an update that does not
  /// fit the body (fewer nodes or elements in the cutter than in the body,
  /// indices out of range). surfaceTriangles() stay the uncut boundary: the
  /// cut surface is TetCutter::surface(), evaluated at positions(); new
  /// nodes join the nodes obstacles push.
  /// @code
  ///   auto up = cutter.cut(dm::bladeSweep(a0, b0, a1, b1), body.positions());
  ///   if (up && !up->changedElements.empty()) body.applyCut(cutter, *up);
  /// @endcode
  Status applyCut(const TetCutter& cutter, const CutUpdate& update);

  /// Statistics of the last step.
  const FemStepReport& lastReport() const noexcept { return report_; }
  /// Number of element colours (parallel phases per assembly).
  std::size_t colourCount() const noexcept { return colourStart_.empty() ? 0 : colourStart_.size() - 1; }

 private:
  FemBody() = default;
  // Rotation of element e from positions x, warm-started from q.
  Mat3 elementRotation(std::size_t e, const std::vector<Vec3>& x, Quat& q) const;
  double elementForces(std::size_t e, const Mat3& R, const std::vector<Vec3>& x, Vec3 (&f)[4],
                       Vec3 (&g)[4]) const;
  void assemble();
  // The solver's structures (see create()): per row the blocks left of the
  // diagonal, a node pair's slot, an element's slots, the greedy colouring
  // of all elements and the grouping by colour.
  void buildLowerBlocks();
  int slotOf(std::uint32_t a, std::uint32_t b) const;
  int findBlock(std::uint32_t row, std::uint32_t col) const;
  void setElementSlots(std::size_t e);
  void colourAll();
  void groupColours(int colours);
  void applySystem(const VecX& in, VecX& out, double massScale, double stiffScale);
  // Hanging nodes' positions and velocities from their masters'.
  void syncHanging();
  // v ← Pᵀv: each hanging row added to its free masters with its weights,
  // then set from identityFrom (the identity row) or to zero.
  void foldHanging(VecX& v, const VecX* identityFrom) const;
  // out = K·in over every row and column (fixed ones included).
  void applyStiffness(Eigen::Ref<const VecX> in, Eigen::Ref<VecX> out) const;
  // Row r of K·in (in: 3 doubles per node), without fixed columns if
  // skipFixed.
  Vec3 stiffnessRow(std::size_t r, const double* in, bool skipFixed) const;
  template <class F>
  void forRange(std::size_t n, std::size_t grain, F&& fn) const;

  FemMaterial material_;
  FemDamping damping_;
  FemSolverOptions options_;
  Vec3 gravity_ = Vec3::Zero();

  // Model (rest).
  std::vector<Vec3> x0_;
  std::vector<Tet> tets_;
  std::vector<Mat3> restInverse_;          // D_m⁻¹ per element
  std::vector<double> restVolume_;         // V per element, m³
  double mu_ = 0.0, lambda_ = 0.0;         // Lamé parameters, Pa
  // Per element, the block slot of node pair (i, j), i ≤ j, in the order
  // (0,0) (0,1) (0,2) (0,3) (1,1) … (3,3); ~slot where the pair is stored
  // transposed (node index of i above j's).
  std::vector<std::array<int, 10>> slot_;
  std::vector<double> mass_;
  double totalMass_ = 0.0;
  // K's blocks as an upper-triangular block CSR over nodes (a row's first
  // block is its diagonal), and per row the blocks left of the diagonal as
  // stored blocks to transpose: half the memory a full CSR takes, which the
  // CG product streams every iteration.
  std::vector<int> rowStart_;
  std::vector<int> colIndex_;
  struct LowerBlock {
    int slot;  // the stored block (col, row), col < row
    int col;
  };
  std::vector<int> lowerStart_;
  std::vector<LowerBlock> lower_;
  std::vector<std::uint32_t> colourOrder_;  // elements grouped by colour
  std::vector<std::size_t> colourStart_;
  std::vector<int> colour_;  // per element
  // Per node, the colours its elements have (had: a bit stays when an
  // element is recoloured), built by the first applyCut(); empty otherwise.
  std::vector<std::uint64_t> nodeColours_;
  std::vector<Triangle> surface_;
  // Hanging nodes, resolved to independent masters: node hangNode_[k] =
  // Σ hangWeight_[s]·(node hangMaster_[s]), s in [hangStart_[k], hangStart_[k+1]).
  std::vector<std::uint8_t> hanging_;  // per node
  std::vector<std::uint32_t> hangNode_, hangStart_, hangMaster_;
  std::vector<double> hangWeight_;

  // State.
  std::vector<Vec3> x_, v_, fext_, force_;
  std::vector<std::uint8_t> fixed_;
  std::vector<Quat> rot_;
  std::vector<Mat3> blocks_;        // K values, per block slot (upper triangle)
  std::vector<Mat3> invBlockDiag_;  // inverse diagonal blocks (both preconditioners)
  std::vector<std::uint8_t> sweepSkip_;  // per node: fixed or hanging (identity rows), this step
  void applyPreconditioner(const VecX& r, VecX& z) const;
  // The contact spring (a FemPointSpring on three nodes, isotropic) and
  // the point springs: one code path for their implicit terms.
  struct ContactSpring {
    bool active = false;
    FemPointSpring spring;
  };
  ContactSpring spring_;
  std::vector<FemPointSpring> points_;
  template <class F>
  void forEachSpring(F&& fn) const {
    if (spring_.active) fn(spring_.spring);
    for (const FemPointSpring& p : points_) fn(p);
  }
  Vec3 springPoint(const FemPointSpring& s) const noexcept;
  struct NodeContact {
    std::uint32_t node = 0;
    std::uint32_t obstacle = 0;
    Vec3 normal = Vec3::Zero();  // unit, out of the obstacle
    double depth = 0.0;          // m, > 0
    double stiffness = 0.0;      // N/m
    double friction = 0.0;       // N·s/m, tangential
    Vec3 arm = Vec3::Zero();     // m, node − obstacle's centre of mass, at the step's start
  };
  std::vector<FemObstacle> obstacles_;
  std::vector<Isometry3> obstacleInverse_;  // body → obstacle frame, per obstacle
  std::vector<Wrench> obstacleWrench_;    // per obstacle, from the last step
  std::vector<Twist> obstacleVelocity_;   // per obstacle, of its centre of mass
  std::vector<std::int32_t> obstacleRow_;  // per obstacle: first solver row (dynamic) or -1
  std::vector<Eigen::Matrix<double, 6, 6>> obstaclePre_;  // per dynamic obstacle: inverse diagonal block
  std::vector<Vec3> obstacleCenter_;  // centre of mass in the body frame, this step
  std::vector<Mat3> obstacleInertia_;  // body-frame inertia tensor of the dynamic ones, this step
  std::size_t rigidRows_ = 0;          // 6 per dynamic obstacle, after the 3n node rows
  std::vector<std::uint32_t> surfaceNodes_;  // nodes of surface_, sorted, unique
  std::vector<NodeContact> contacts_;     // this step's (capacity: surface nodes)
  std::vector<std::int32_t> contactOf_;   // per node: index into contacts_, or -1
  double sysContactScale_ = 0.0;          // h² of the current step: contact's share of the operator
  double sysDampScale_ = 0.0;             // h of the current step: the contact friction's share
  void findObstacleContacts();
  double contactRate(const NodeContact& c) const noexcept;
  Vec3 contactForce(const NodeContact& c, double h) const noexcept;
  Vec3 contactFriction(const NodeContact& c) const noexcept;
  VecX rhs_, dv_, tmp_;
  VecX full_;  // applySystem's input with hanging rows filled in (P·in)
  double sysMassScale_ = 1.0, sysStiffScale_ = 0.0;  // operator scales of the current step
  PcgSolver pcg_;
  FemStepReport report_;
};

}  // namespace dm
