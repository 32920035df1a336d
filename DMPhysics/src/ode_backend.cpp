// ODE backend: mirrors a PhysicsWorld in an ODE world (bodies, geoms,
// joints, contact surfaces) and steps a WorldState with dWorldQuickStep.
// ODE's headers stay in this file.
#include <dm/physics/ode_backend.hpp>

#include <ode/ode.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace dm {

namespace {

std::string bodyName(std::size_t index, const std::string& name) {
  std::string w = "bodies[" + std::to_string(index) + "]";
  if (!name.empty()) w += " '" + name + "'";
  return w;
}

void toOde(const Quat& q, dQuaternion out) {
  out[0] = q.w();
  out[1] = q.x();
  out[2] = q.y();
  out[3] = q.z();
}

Quat fromOde(const dReal* q) { return Quat(q[0], q[1], q[2], q[3]).normalized(); }

Vec3 vec(const dReal* v) { return {v[0], v[1], v[2]}; }

bool supported(const Shape& s, BodyKind kind) {
  switch (s.type()) {
    case ShapeType::Sphere:
    case ShapeType::Box:
    case ShapeType::Capsule:
    case ShapeType::Cylinder:
    case ShapeType::ConvexHull:
      return true;
    case ShapeType::Plane:
    case ShapeType::TriangleMesh:
      return kind == BodyKind::Static;
    case ShapeType::Compound:  // one geom per part on the body: primitives and hulls
      for (const CompoundChild& c : static_cast<const Compound&>(s).children())
        if (c.shape->type() == ShapeType::Compound || c.shape->type() == ShapeType::Plane ||
            c.shape->type() == ShapeType::TriangleMesh || !supported(*c.shape, kind))
          return false;
      return true;
    default:
      return false;
  }
}

// A convex hull as ODE's dConvex takes it: one plane (n, n·v0) and one
// polygon (3, i, j, k) per hull triangle, CCW from outside as dm::Mesh.
// ODE keeps pointers into these arrays: they live as long as the geom.
struct OdeConvex {
  std::vector<dReal> planes, points;
  std::vector<unsigned> polygons;
};

std::unique_ptr<OdeConvex> odeConvex(const ConvexHull& hull) {
  auto c = std::make_unique<OdeConvex>();
  const Mesh& m = hull.mesh();
  for (const Vec3& p : m.positions) c->points.insert(c->points.end(), {p.x(), p.y(), p.z()});
  for (std::size_t t = 0; t < m.triangles.size(); ++t) {
    const Vec3 n = m.faceNormal(t);
    if (n.isZero()) continue;  // a sliver of the hull's triangulation: its neighbours bound it
    const Triangle& tri = m.triangles[t];
    c->planes.insert(c->planes.end(), {n.x(), n.y(), n.z(), n.dot(m.positions[tri[0]])});
    c->polygons.insert(c->polygons.end(), {3u, tri[0], tri[1], tri[2]});
  }
  return c;
}

}  // namespace

struct OdeWorld::Impl {
  const PhysicsWorld* world = nullptr;
  OdeOptions options;
  dWorldID odeWorld = nullptr;
  dSpaceID space = nullptr;
  dJointGroupID contactGroup = nullptr;
  std::vector<dBodyID> body;  // per world body; null for static bodies
  std::vector<double> masses;
  std::vector<Vec3> force, torque;
  std::vector<dContact> contacts;  // dCollide scratch, maxContactsPerPair entries
  std::vector<std::unique_ptr<OdeConvex>> convexes;  // the hulls' arrays ODE points into
  std::vector<dTriMeshDataID> meshData;              // the triangle meshes' (vertices: the world's meshes)
  // Each contact joint's feedback, in blocks that never move (ODE keeps a
  // pointer to each until the step is done); reused from step to step.
  static constexpr std::size_t kFeedbackBlock = 64;
  std::vector<std::unique_ptr<std::array<dJointFeedback, kFeedbackBlock>>> feedback;
  std::vector<dJointID> contactJoints;  // this step's, in creation order
  std::vector<Vec3> contactForce;       // per world body, the last step's contact force on it
  double restitutionThreshold = 0.2;
  std::size_t lastContacts = 0;
  bool initialised = false;

  ~Impl() {
    if (contactGroup) dJointGroupDestroy(contactGroup);
    if (space) dSpaceDestroy(space);  // destroys its geoms (cleanup mode on)
    for (dTriMeshDataID d : meshData) dGeomTriMeshDataDestroy(d);
    if (odeWorld) dWorldDestroy(odeWorld);
    if (initialised) dCloseODE();
  }

  dJointFeedback* nextFeedback() {
    const std::size_t k = contactJoints.size();
    if (k / kFeedbackBlock >= feedback.size())
      feedback.push_back(std::make_unique<std::array<dJointFeedback, kFeedbackBlock>>());
    return &(*feedback[k / kFeedbackBlock])[k % kFeedbackBlock];
  }

  // One geom of world body i (ODE body b, null for a static one) for shape
  // s at `offset` in the body frame; a static body's geom at its world pose
  // (bodyPose · offset). Planes are world-frame half-spaces.
  void addGeom(const Shape& s, std::size_t i, dBodyID b, const Isometry3& bodyPose, const Isometry3& offset) {
    dGeomID g = nullptr;
    switch (s.type()) {
      case ShapeType::Sphere:
        g = dCreateSphere(space, static_cast<const Sphere&>(s).radius());
        break;
      case ShapeType::Box: {
        const Vec3 full = 2.0 * static_cast<const Box&>(s).halfExtents();
        g = dCreateBox(space, full.x(), full.y(), full.z());
        break;
      }
      case ShapeType::Capsule: {
        const auto& c = static_cast<const Capsule&>(s);
        g = dCreateCapsule(space, c.radius(), 2.0 * c.halfLength());
        break;
      }
      case ShapeType::Cylinder: {  // both along local z
        const auto& c = static_cast<const Cylinder&>(s);
        g = dCreateCylinder(space, c.radius(), 2.0 * c.halfLength());
        break;
      }
      case ShapeType::ConvexHull: {
        auto c = odeConvex(static_cast<const ConvexHull&>(s));
        g = dCreateConvex(space, c->planes.data(), static_cast<unsigned>(c->planes.size() / 4),
                          c->points.data(), static_cast<unsigned>(c->points.size() / 3), c->polygons.data());
        convexes.push_back(std::move(c));
        break;
      }
      case ShapeType::TriangleMesh: {  // static (checked in create); the world keeps the mesh alive
        const Mesh& m = *static_cast<const TriangleMesh&>(s).mesh();
        static_assert(sizeof(Triangle) == 3 * sizeof(dTriIndex) && sizeof(Vec3) == 3 * sizeof(double));
        dTriMeshDataID data = dGeomTriMeshDataCreate();
        meshData.push_back(data);
        dGeomTriMeshDataBuildDouble(data, m.positions.data(), sizeof(Vec3),
                                    static_cast<int>(m.positions.size()), m.triangles.data(),
                                    static_cast<int>(3 * m.triangles.size()), sizeof(Triangle));
        g = dCreateTriMesh(space, data, nullptr, nullptr, nullptr);
        break;
      }
      default: {  // a plane on a static body (checked in create): world-frame a·x = d
        const auto& p = static_cast<const Plane&>(s);
        const Isometry3 pose = bodyPose * offset;
        const Vec3 nw = pose.linear() * p.normal();
        g = dCreatePlane(space, nw.x(), nw.y(), nw.z(), p.offset() + nw.dot(pose.translation()));
        dGeomSetData(g, reinterpret_cast<void*>(static_cast<std::uintptr_t>(i)));
        return;
      }
    }
    dGeomSetData(g, reinterpret_cast<void*>(static_cast<std::uintptr_t>(i)));
    if (b) {
      dGeomSetBody(g, b);
      if (!offset.isApprox(Isometry3::Identity(), 0.0)) {
        const Vec3 off = offset.translation();
        dQuaternion oq;
        toOde(Quat(offset.rotation()), oq);
        dGeomSetOffsetPosition(g, off.x(), off.y(), off.z());
        dGeomSetOffsetQuaternion(g, oq);
      }
    } else {
      const Isometry3 pose = bodyPose * offset;
      const Vec3 x = pose.translation();
      dQuaternion gq;
      toOde(Quat(pose.rotation()), gq);
      dGeomSetPosition(g, x.x(), x.y(), x.z());
      dGeomSetQuaternion(g, gq);
    }
  }

  // The world-body index of an ODE body (its user data), or -1 for none.
  static std::ptrdiff_t indexOf(dBodyID b) {
    return b ? static_cast<std::ptrdiff_t>(reinterpret_cast<std::uintptr_t>(dBodyGetData(b))) : -1;
  }

  static void nearCallback(void* data, dGeomID g1, dGeomID g2) {
    auto* self = static_cast<Impl*>(data);
    dBodyID b1 = dGeomGetBody(g1), b2 = dGeomGetBody(g2);
    if (!b1 && !b2) return;
    if (b1 && b2 && dAreConnectedExcluding(b1, b2, dJointTypeContact)) return;
    const int n =
        dCollide(g1, g2, static_cast<int>(self->contacts.size()), &self->contacts[0].geom, sizeof(dContact));
    if (n <= 0) return;
    const auto i1 = static_cast<std::size_t>(reinterpret_cast<std::uintptr_t>(dGeomGetData(g1)));
    const auto i2 = static_cast<std::size_t>(reinterpret_cast<std::uintptr_t>(dGeomGetData(g2)));
    const ContactMaterial& m1 = self->world->material(BodyId{static_cast<std::uint32_t>(i1)});
    const ContactMaterial& m2 = self->world->material(BodyId{static_cast<std::uint32_t>(i2)});
    const double mu = std::sqrt(m1.friction * m2.friction);
    const double e = std::max(m1.restitution, m2.restitution);
    for (int k = 0; k < n; ++k) {
      dContact& c = self->contacts[static_cast<std::size_t>(k)];
      c.surface.mode = dContactApprox1 | (e > 0.0 ? dContactBounce : 0);
      c.surface.mu = mu;
      c.surface.bounce = e;
      c.surface.bounce_vel = self->restitutionThreshold;
      dJointID j = dJointCreateContact(self->odeWorld, self->contactGroup, &c);
      dJointAttach(j, b1, b2);
      dJointSetFeedback(j, self->nextFeedback());
      self->contactJoints.push_back(j);
      ++self->lastContacts;
    }
  }
};

OdeWorld::OdeWorld(std::unique_ptr<Impl> impl) noexcept : impl_(std::move(impl)) {}
OdeWorld::OdeWorld(OdeWorld&&) noexcept = default;
OdeWorld& OdeWorld::operator=(OdeWorld&&) noexcept = default;
OdeWorld::~OdeWorld() = default;

std::size_t OdeWorld::lastContactCount() const noexcept { return impl_->lastContacts; }
std::span<const Vec3> OdeWorld::lastContactForces() const noexcept { return impl_->contactForce; }
const OdeOptions& OdeWorld::options() const noexcept { return impl_->options; }

Result<OdeWorld> OdeWorld::create(const PhysicsWorld& world, const OdeOptions& options) {
  if (options.iterations < 1)
    return fail(ErrorCode::InvalidArgument, "iterations is " + std::to_string(options.iterations),
                "OdeOptions::iterations", "give at least 1 (20 is typical)");
  if (!(options.erp > 0.0 && options.erp <= 1.0) || !(options.cfm >= 0.0) || !std::isfinite(options.cfm))
    return fail(ErrorCode::InvalidArgument, "erp must lie in (0, 1] and cfm be finite and >= 0",
                "OdeOptions::erp/cfm", "use erp 0.2 and cfm 1e-9");
  if (options.maxContactsPerPair < 1 || options.maxContactsPerPair > 64)
    return fail(ErrorCode::InvalidArgument,
                "maxContactsPerPair is " + std::to_string(options.maxContactsPerPair),
                "OdeOptions::maxContactsPerPair", "give a value in [1, 64]");
  const std::span<const BodyDesc> bodies = world.bodies();
  // Check every shape first so that nothing is built for an unsupported scene.
  std::ptrdiff_t hull = -1, triangles = -1;  // a body of each kind, if any
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    const BodyDesc& d = bodies[i];
    if (!d.shape || !world.material(BodyId{static_cast<std::uint32_t>(i)}).collides) continue;
    const ShapeType t = d.shape->type();
    if (!supported(*d.shape, d.kind))
      return fail(
          ErrorCode::Unsupported,
          "the ODE backend cannot take a " + std::string(shapeTypeName(t)) + " shape" +
              (t == ShapeType::Plane || t == ShapeType::TriangleMesh ? " on a moving body" : ""),
          bodyName(i, d.name),
          "use sphere, box, capsule, cylinder or convex hull shapes, or compounds of them (planes and "
          "triangle meshes on static bodies), or the built-in solver");
    bool hasHull = t == ShapeType::ConvexHull;
    if (t == ShapeType::Compound)
      for (const CompoundChild& c : static_cast<const Compound&>(*d.shape).children())
        hasHull = hasHull || c.shape->type() == ShapeType::ConvexHull;
    if (hasHull && hull < 0) hull = static_cast<std::ptrdiff_t>(i);
    if (t == ShapeType::TriangleMesh && triangles < 0) triangles = static_cast<std::ptrdiff_t>(i);
  }
  // ODE 0.16 as Debian builds it (without libccd) has no convex–triangle-mesh
  // collider: dCollide on such a pair crashes in OPCODE. Refuse the world.
  if (hull >= 0 && triangles >= 0)
    return fail(ErrorCode::Unsupported,
                "the ODE backend cannot collide a convex hull with a triangle mesh (" +
                    bodyName(std::size_t(hull), bodies[std::size_t(hull)].name) + " and " +
                    bodyName(std::size_t(triangles), bodies[std::size_t(triangles)].name) + ")",
                bodyName(std::size_t(hull), bodies[std::size_t(hull)].name),
                "give the moving body a primitive shape, turn off one body's collisions, or use the built-in "
                "solver");

  auto impl = std::make_unique<Impl>();
  dInitODE2(0);
  impl->initialised = true;
  impl->world = &world;
  impl->options = options;
  impl->restitutionThreshold = world.contactSettings().solver.restitutionThreshold;
  impl->odeWorld = dWorldCreate();
  impl->space = dHashSpaceCreate(nullptr);
  impl->contactGroup = dJointGroupCreate(0);
  impl->contacts.resize(static_cast<std::size_t>(options.maxContactsPerPair));
  dWorldSetGravity(impl->odeWorld, 0, 0, 0);  // gravity comes with the accumulated forces
  dWorldSetQuickStepNumIterations(impl->odeWorld, options.iterations);
  dWorldSetERP(impl->odeWorld, options.erp);
  dWorldSetCFM(impl->odeWorld, options.cfm);
  dWorldSetContactSurfaceLayer(impl->odeWorld, options.surfaceLayer >= 0.0
                                                   ? options.surfaceLayer
                                                   : world.contactSettings().solver.slop);
  dWorldSetContactMaxCorrectingVel(impl->odeWorld, world.contactSettings().solver.maxCorrectionVelocity);

  const std::size_t n = bodies.size();
  impl->body.assign(n, nullptr);
  impl->masses.resize(n);
  impl->force.assign(n, Vec3::Zero());
  impl->torque.assign(n, Vec3::Zero());
  impl->contactForce.assign(n, Vec3::Zero());
  for (std::size_t i = 0; i < n; ++i) {
    const BodyDesc& d = bodies[i];
    impl->masses[i] = d.mass;
    dQuaternion q;
    toOde(d.orientation.normalized(), q);
    dBodyID b = nullptr;
    if (d.kind != BodyKind::Static) {
      b = dBodyCreate(impl->odeWorld);
      dMass m;
      // Particles get a sphere-like inertia and never turn (max angular speed 0).
      const Mat3 I = d.kind == BodyKind::Rigid ? d.inertia : Mat3(d.mass * Mat3::Identity());
      dMassSetParameters(&m, d.mass, 0, 0, 0, I(0, 0), I(1, 1), I(2, 2), I(0, 1), I(0, 2), I(1, 2));
      dBodySetMass(b, &m);
      if (d.kind == BodyKind::Particle) dBodySetMaxAngularSpeed(b, 0.0);
      dBodySetPosition(b, d.position.x(), d.position.y(), d.position.z());
      dBodySetQuaternion(b, q);
      dBodySetGyroscopicMode(b, 1);
      dBodySetData(b, reinterpret_cast<void*>(static_cast<std::uintptr_t>(i)));
      impl->body[i] = b;
    }
    if (!d.shape || !world.material(BodyId{static_cast<std::uint32_t>(i)}).collides) continue;
    const Isometry3 bodyPose = Eigen::Translation3d(d.position) * d.orientation.normalized();
    if (d.shape->type() == ShapeType::Compound) {
      // One geom per part, each on the body at shapeOffset · its pose (ODE
      // never collides two geoms of one body).
      for (const CompoundChild& c : static_cast<const Compound&>(*d.shape).children())
        impl->addGeom(*c.shape, i, b, bodyPose, d.shapeOffset * c.pose);
    } else {
      impl->addGeom(*d.shape, i, b, bodyPose, d.shapeOffset);
    }
  }

  // Joints at the initial poses (where their descriptions were made).
  const std::span<const JointDesc> joints = world.joints();
  for (std::size_t k = 0; k < joints.size(); ++k) {
    const JointDesc& jd = joints[k];
    const auto odeBody = [&](BodyId id) -> dBodyID { return id.valid() ? impl->body[id.index] : nullptr; };
    dBodyID ba = odeBody(jd.a), bb = odeBody(jd.b);
    const Vec3 axis = jd.axis.normalized();
    dJointID j = nullptr;
    switch (jd.type) {
      case JointType::Ball:
        j = dJointCreateBall(impl->odeWorld, nullptr);
        dJointAttach(j, ba, bb);
        dJointSetBallAnchor(j, jd.anchor.x(), jd.anchor.y(), jd.anchor.z());
        break;
      case JointType::Hinge:
        j = dJointCreateHinge(impl->odeWorld, nullptr);
        dJointAttach(j, ba, bb);
        dJointSetHingeAnchor(j, jd.anchor.x(), jd.anchor.y(), jd.anchor.z());
        dJointSetHingeAxis(j, axis.x(), axis.y(), axis.z());
        if (jd.limitEnabled) {
          dJointSetHingeParam(j, dParamLoStop, jd.lower);
          dJointSetHingeParam(j, dParamHiStop, jd.upper);
        }
        break;
      case JointType::Slider:
        j = dJointCreateSlider(impl->odeWorld, nullptr);
        dJointAttach(j, ba, bb);
        dJointSetSliderAxis(j, axis.x(), axis.y(), axis.z());
        if (jd.limitEnabled) {
          dJointSetSliderParam(j, dParamLoStop, jd.lower);
          dJointSetSliderParam(j, dParamHiStop, jd.upper);
        }
        break;
      case JointType::Fixed:
        j = dJointCreateFixed(impl->odeWorld, nullptr);
        dJointAttach(j, ba, bb);
        dJointSetFixed(j);
        break;
    }
  }
  return OdeWorld(std::move(impl));
}

Status OdeWorld::step(WorldState& state, double dt) {
  Impl& im = *impl_;
  const PhysicsWorld& world = *im.world;
  if (!std::isfinite(dt) || !(dt > 0))
    return fail(ErrorCode::InvalidArgument, "dt is " + std::to_string(dt) + " s", "OdeWorld::step",
                "give a finite time step > 0");
  const std::size_t n = im.body.size();
  if (state.s_.position.size() != n || world.bodyCount() != n)
    return fail(ErrorCode::InvalidArgument,
                "the state has " + std::to_string(state.s_.position.size()) + " bodies, the ODE world " +
                    std::to_string(n),
                "OdeWorld::step", "make the state with the mirrored world's makeState()");
  WorldSnapshot& s = state.s_;
  const double t0 = s.time;
  for (const Impulse& imp : world.impulses())
    if (imp.time >= t0 && imp.time < t0 + dt) {
      const std::uint32_t i = imp.body.index;
      if (auto st =
              world.applyImpulse(state, imp.body, imp.impulse, s.position[i] + s.orientation[i] * imp.point);
          !st)
        return st;
    }

  // Forces at the start-of-step state, as the built-in first evaluation.
  const BodyStateView view{t0, s.position, s.orientation, s.linearVelocity, s.angularVelocity, im.masses};
  ForceOutput out{im.force, im.torque};
  accumulateForces(world.forces(), view, out);
  state.force_ = im.force;  // same sizes: no allocation
  state.torque_ = im.torque;
  const std::span<const BodyDesc> bodies = world.bodies();
  for (std::size_t i = 0; i < n; ++i) {
    dBodyID b = im.body[i];
    if (!b) continue;
    dBodySetPosition(b, s.position[i].x(), s.position[i].y(), s.position[i].z());
    dQuaternion q;
    toOde(s.orientation[i], q);
    dBodySetQuaternion(b, q);
    dBodySetLinearVel(b, s.linearVelocity[i].x(), s.linearVelocity[i].y(), s.linearVelocity[i].z());
    dBodySetAngularVel(b, s.angularVelocity[i].x(), s.angularVelocity[i].y(), s.angularVelocity[i].z());
    dBodySetForce(b, im.force[i].x(), im.force[i].y(), im.force[i].z());
    if (bodies[i].kind == BodyKind::Rigid)
      dBodySetTorque(b, im.torque[i].x(), im.torque[i].y(), im.torque[i].z());
    else
      dBodySetTorque(b, 0, 0, 0);
  }

  im.lastContacts = 0;
  im.contactJoints.clear();
  dSpaceCollide(im.space, &im, &Impl::nearCallback);
  // dWorldQuickStep orders its constraints at random from ODE's one global
  // generator: seeded from the step count, a step depends on the state
  // alone (reruns and restored snapshots are bit-identical).
  dRandSetSeed(0x9E3779B97F4A7C15ull * (s.stepCount + 1) >> 32);
  dWorldQuickStep(im.odeWorld, dt);
  // Each contact's force on its two bodies (ODE's feedback: f1 on the
  // joint's first body, f2 on its second; a static side has none).
  std::fill(im.contactForce.begin(), im.contactForce.end(), Vec3::Zero());
  for (std::size_t k = 0; k < im.contactJoints.size(); ++k) {
    const dJointFeedback& f = (*im.feedback[k / Impl::kFeedbackBlock])[k % Impl::kFeedbackBlock];
    const dJointID j = im.contactJoints[k];
    if (const std::ptrdiff_t a = Impl::indexOf(dJointGetBody(j, 0)); a >= 0)
      im.contactForce[std::size_t(a)] += vec(f.f1);
    if (const std::ptrdiff_t b = Impl::indexOf(dJointGetBody(j, 1)); b >= 0)
      im.contactForce[std::size_t(b)] += vec(f.f2);
  }
  dJointGroupEmpty(im.contactGroup);

  for (std::size_t i = 0; i < n; ++i) {
    dBodyID b = im.body[i];
    if (!b) continue;
    s.position[i] = vec(dBodyGetPosition(b));
    s.linearVelocity[i] = vec(dBodyGetLinearVel(b));
    if (bodies[i].kind == BodyKind::Rigid) {
      s.orientation[i] = fromOde(dBodyGetQuaternion(b));
      s.angularVelocity[i] = vec(dBodyGetAngularVel(b));
    }
  }
  s.time = t0 + dt;
  ++s.stepCount;
  for (std::size_t i = 0; i < n; ++i) {
    const BodyDesc& d = bodies[i];
    if (d.shape) {
      const Isometry3 pose = Eigen::Translation3d(s.position[i]) * s.orientation[i] * d.shapeOffset;
      state.bounds_[i] = d.shape->aabb(pose);
    } else {
      state.bounds_[i] = Aabb(s.position[i], s.position[i]);
    }
    if (!s.position[i].allFinite() || !s.orientation[i].coeffs().allFinite() ||
        !s.linearVelocity[i].allFinite() || !s.angularVelocity[i].allFinite())
      return fail(ErrorCode::Unsupported,
                  "ODE produced a non-finite pose or velocity at t = " + std::to_string(s.time) + " s",
                  bodyName(i, d.name),
                  "reduce dt or raise OdeOptions::iterations; restore a snapshot to continue");
  }
  return ok();
}

}  // namespace dm
