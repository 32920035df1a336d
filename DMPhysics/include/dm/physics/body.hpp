// dm/physics/body.hpp — particles and rigid bodies: their description and
// the rigid-body kinematics shared by the integrators.
//
// A body is described once, read-only, by a BodyDesc (mass properties, the
// integrator that advances it, an optional collision shape and its initial
// state); the world keeps its moving state in a WorldState
// (dm/physics/world.hpp). Units are SI: m, kg, s, N, N·m, kg·m².
//
// Frames. A body's frame has its origin at the centre of mass; `position` is
// the centre of mass in world coordinates, `orientation` rotates body
// coordinates into world coordinates (unit quaternion, R = orientation
// matrix). The inertia tensor is given in the body frame about the centre of
// mass; its world form is I_w = R I Rᵀ. Velocities are world-frame: `linear`
// of the centre of mass (m/s), `angular` ω (rad/s).
//
// Rotational dynamics (Euler's equations in the world frame):
//   q̇ = ½ (0, ω) ⊗ q,   I_w ω̇ = τ − ω × (I_w ω).
// The gyroscopic term ω × I_w ω keeps torque-free precession of asymmetric
// bodies correct; the world integrates (q, ω) with RK4 (dm/math
// integrators.hpp), which conserves energy and angular momentum to O(h⁴)
// per unit time, and renormalises q after every step.
//
// @code
//   auto box = dm::rigidBodyFromMesh(dm::makeBox({0.1, 0.05, 0.02}), 7900.0);
//   if (!box) return box.error();
//   box->name = "scalpel"; box->linearVelocity = {0, 0, 1};
// @endcode
#pragma once

#include <dm/collide/shapes.hpp>
#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <cstdint>
#include <string>

namespace dm {

/// Handle of a body in a PhysicsWorld: the dense index it was added at.
/// Bodies are never removed, so an index names the same body for the life of
/// the world. Default-constructed ids name no body.
struct BodyId {
  static constexpr std::uint32_t kInvalidIndex = 0xffffffffu;
  std::uint32_t index = kInvalidIndex;
  /// False for a default-constructed id.
  bool valid() const noexcept { return index != kInvalidIndex; }
  friend bool operator==(const BodyId&, const BodyId&) = default;
};

/// What moves and how.
enum class BodyKind : std::uint8_t {
  Particle,  ///< point mass: translation only, orientation stays fixed, no torque response
  Rigid,     ///< mass + inertia tensor: translation and rotation
  Static,    ///< never moves (infinite mass): an anchor for springs, ground
};

/// Integrator that advances a body's translation (and, for RK4, everything).
/// Bodies that share a kind are advanced together as one coupled system by
/// the dm/math step functions; see PhysicsWorld::step for how kinds mix.
enum class IntegratorKind : std::uint8_t {
  SymplecticEuler,  ///< dm::symplecticEulerStep: order 1, symplectic, 1 force evaluation
  VelocityVerlet,   ///< dm::velocityVerletStep: order 2, symplectic, 2 force evaluations
  Rk4,              ///< dm::rk4Step on the full state (x, q, v, ω): order 4, 4 force evaluations
};

/// Name of an integrator kind ("symplectic-euler", "velocity-verlet", "rk4").
const char* toString(IntegratorKind kind) noexcept;

/// Read-only description of one body, with its initial state.
struct BodyDesc {
  std::string name;  ///< for messages; may be empty (the index is used then)
  BodyKind kind = BodyKind::Particle;
  IntegratorKind integrator = IntegratorKind::SymplecticEuler;
  /// kg, > 0 and finite for particles and rigid bodies; ignored for static bodies.
  double mass = 1.0;
  /// kg·m², body frame about the centre of mass; symmetric positive definite
  /// for rigid bodies (checked), ignored otherwise.
  Mat3 inertia = Mat3::Identity();
  Vec3 position = Vec3::Zero();         ///< m, centre of mass, world frame
  Quat orientation = Quat::Identity();  ///< body → world; normalised when added (must be nonzero)
  Vec3 linearVelocity = Vec3::Zero();   ///< m/s, world frame
  Vec3 angularVelocity = Vec3::Zero();  ///< rad/s, world frame (rigid bodies only)
  /// Optional collision shape; the world keeps its world AABB up to date.
  ShapePtr shape;
  /// Pose of the shape's frame in the body frame (e.g. the mesh's origin
  /// relative to its centre of mass, as set by rigidBodyFromMesh).
  Isometry3 shapeOffset = Isometry3::Identity();
};

/// Checks `desc` as PhysicsWorld::addBody does: finite values, mass > 0
/// (dynamic bodies), a symmetric positive-definite inertia (rigid bodies,
/// relative asymmetry ≤ 1e-9, smallest eigenvalue > 0, triangle inequality
/// of the principal moments within 1e-9 relative), a nonzero orientation.
/// The message names the body (`where`) and the field. O(1).
/// @code
///   dm::BodyDesc d; d.mass = -1;
///   auto st = dm::validateBodyDesc(d, "bodies[3]");  // InvalidArgument: "mass is -1"
/// @endcode
Status validateBodyDesc(const BodyDesc& desc, const std::string& where);

/// A rigid body of uniform `density` (kg/m³) filling the closed `mesh`
/// (metres, its own frame): mass and inertia from dm::computeMassProperties,
/// `position` at the mesh's centroid (mesh frame = world frame initially),
/// `shapeOffset` = translation by −centroid (mesh frame in the body frame).
/// Attach a shape of the same mesh to `shape` for bounds. O(F log F).
/// Fails as computeMassProperties does (open mesh, bad density, ...).
/// @code
///   auto d = dm::rigidBodyFromMesh(dm::makeBox({0.5, 0.25, 0.1}), 1000.0);
///   if (!d) return d.error();
///   auto id = world.addBody(*d);
/// @endcode
Result<BodyDesc> rigidBodyFromMesh(const Mesh& mesh, double density);

/// The body's shape frame (its mesh's) in the world, at a body position
/// and orientation: position · orientation · desc.shapeOffset. O(1).
Isometry3 bodyShapePose(const Vec3& position, const Quat& orientation, const BodyDesc& desc) noexcept;

/// World inertia tensor R I Rᵀ (kg·m²) of a body-frame tensor `inertia`. O(1).
Mat3 worldInertia(const Mat3& rotation, const Mat3& inertia) noexcept;

/// ω̇ (rad/s², world frame) from Euler's equations I_w ω̇ = τ − ω × I_w ω,
/// with R the body → world rotation and `inverseInertia` the body-frame
/// inverse tensor. O(1), no allocation.
Vec3 angularAcceleration(const Mat3& rotation, const Mat3& inertia, const Mat3& inverseInertia,
                         const Vec3& omega, const Vec3& torque) noexcept;

/// Time derivative of the orientation, q̇ = ½ (0, ω) ⊗ q, for a world-frame ω
/// (coefficients x, y, z, w as Quat::coeffs()). O(1).
Vec4 quaternionDerivative(const Quat& q, const Vec3& omega) noexcept;

}  // namespace dm
