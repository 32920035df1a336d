// Body descriptions: validation, mass properties from meshes, rigid-body kinematics.
#include <dm/math/mass_properties.hpp>
#include <dm/physics/body.hpp>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <sstream>

namespace dm {

namespace {

std::string str(const Vec3& v) {
  std::ostringstream os;
  os << '(' << v.x() << ", " << v.y() << ", " << v.z() << ')';
  return os.str();
}

Status nonFinite(const std::string& where, const char* field) {
  return fail(ErrorCode::InvalidArgument, std::string(field) + " is not finite", where,
              "give finite values (NaN and infinity are not allowed)");
}

}  // namespace

const char* toString(IntegratorKind kind) noexcept {
  switch (kind) {
    case IntegratorKind::SymplecticEuler:
      return "symplectic-euler";
    case IntegratorKind::VelocityVerlet:
      return "velocity-verlet";
    case IntegratorKind::Rk4:
      return "rk4";
  }
  return "unknown";
}

Status validateBodyDesc(const BodyDesc& d, const std::string& where) {
  if (d.kind != BodyKind::Particle && d.kind != BodyKind::Rigid && d.kind != BodyKind::Static)
    return fail(ErrorCode::InvalidArgument, "kind " + std::to_string(int(d.kind)) + " is not a BodyKind",
                where, "use Particle, Rigid or Static");
  if (d.integrator != IntegratorKind::SymplecticEuler && d.integrator != IntegratorKind::VelocityVerlet &&
      d.integrator != IntegratorKind::Rk4)
    return fail(ErrorCode::InvalidArgument, "integrator " + std::to_string(int(d.integrator)) + " is unknown",
                where, "use SymplecticEuler, VelocityVerlet or Rk4");
  if (!d.position.allFinite()) return nonFinite(where, "position");
  if (!d.orientation.coeffs().allFinite()) return nonFinite(where, "orientation");
  if (!d.linearVelocity.allFinite()) return nonFinite(where, "linearVelocity");
  if (!d.angularVelocity.allFinite()) return nonFinite(where, "angularVelocity");
  if (!d.shapeOffset.matrix().allFinite()) return nonFinite(where, "shapeOffset");
  if (!(d.orientation.norm() > 1e-12))
    return fail(ErrorCode::InvalidArgument, "orientation is a zero quaternion", where,
                "give a unit quaternion, e.g. Quat::Identity()");
  if (d.kind == BodyKind::Static) return ok();
  if (!std::isfinite(d.mass)) return nonFinite(where, "mass");
  if (!(d.mass > 0))
    return fail(ErrorCode::InvalidArgument, "mass is " + std::to_string(d.mass) + " kg", where,
                "give a positive mass, or make the body BodyKind::Static");
  if (d.kind != BodyKind::Rigid) return ok();
  if (!d.inertia.allFinite()) return nonFinite(where, "inertia");
  const double scale = d.inertia.cwiseAbs().maxCoeff();
  if (!((d.inertia - d.inertia.transpose()).cwiseAbs().maxCoeff() <= 1e-9 * scale))
    return fail(ErrorCode::InvalidArgument, "inertia is not symmetric", where,
                "give the body-frame inertia tensor about the centre of mass (products of inertia appear "
                "symmetrically)");
  Eigen::SelfAdjointEigenSolver<Mat3> eig(d.inertia, Eigen::EigenvaluesOnly);
  const Vec3 m = eig.eigenvalues();  // ascending
  if (!(m[0] > 1e-12 * scale) || !(scale > 0))
    return fail(ErrorCode::InvalidArgument,
                "inertia is not positive definite (principal moments " + str(m) + ")", where,
                "every principal moment of a rigid body must be > 0; use a Particle for a point mass");
  if (!(m[0] + m[1] >= m[2] * (1.0 - 1e-9)))
    return fail(ErrorCode::InvalidArgument,
                "inertia violates the triangle inequality (principal moments " + str(m) + ")", where,
                "no mass distribution has these moments; compute them with rigidBodyFromMesh");
  return ok();
}

Result<BodyDesc> rigidBodyFromMesh(const Mesh& mesh, double density) {
  auto mp = computeMassProperties(mesh, density);
  if (!mp) return mp.error();
  BodyDesc d;
  d.kind = BodyKind::Rigid;
  d.mass = mp->mass;
  // Symmetrise away rounding so validation's symmetry test is about the input, not the sums.
  d.inertia = 0.5 * (mp->inertia + mp->inertia.transpose());
  d.position = mp->centroid;
  d.shapeOffset = Isometry3::Identity();
  d.shapeOffset.translation() = -mp->centroid;
  return d;
}

Isometry3 bodyShapePose(const Vec3& position, const Quat& orientation, const BodyDesc& desc) noexcept {
  Isometry3 pose = Isometry3::Identity();
  pose.translation() = position;
  pose.linear() = orientation.normalized().toRotationMatrix();
  return pose * desc.shapeOffset;
}

Mat3 worldInertia(const Mat3& rotation, const Mat3& inertia) noexcept {
  return rotation * inertia * rotation.transpose();
}

Vec3 angularAcceleration(const Mat3& rotation, const Mat3& inertia, const Mat3& inverseInertia,
                         const Vec3& omega, const Vec3& torque) noexcept {
  // In body coordinates: I ω̇_b = τ_b − ω_b × I ω_b; then back to world.
  const Vec3 wb = rotation.transpose() * omega;
  const Vec3 tb = rotation.transpose() * torque;
  return rotation * (inverseInertia * (tb - wb.cross(inertia * wb)));
}

Vec4 quaternionDerivative(const Quat& q, const Vec3& omega) noexcept {
  // ½ (0, ω) ⊗ q with q = (w, v): scalar −½ ω·v, vector ½ (w ω + ω × v).
  const Vec3 v = q.vec();
  const Vec3 dv = 0.5 * (q.w() * omega + omega.cross(v));
  return Vec4(dv.x(), dv.y(), dv.z(), -0.5 * omega.dot(v));
}

}  // namespace dm
