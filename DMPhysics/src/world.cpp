// PhysicsWorld: model setup, state creation, the step (accumulate →
// integrate → update bounds), snapshots and the state hash.
#include <dm/physics/world.hpp>

#include <algorithm>
#include <cmath>
#include <utility>

namespace dm {

namespace {

std::string bodyWhere(std::uint32_t index, const std::string& name) {
  std::string w = "bodies[" + std::to_string(index) + "]";
  if (!name.empty()) w += " '" + name + "'";
  return w;
}

constexpr int kSecondOrderKinds = 2;  // SymplecticEuler, VelocityVerlet share stepSecondOrder
constexpr int kRk4Kind = 2;
constexpr Eigen::Index kRotationSize = 7;  // q (x, y, z, w), ω
constexpr Eigen::Index kRk4Size = 13;      // x, q, v, ω

Isometry3 bodyPose(const Vec3& x, const Quat& q) {
  Isometry3 pose = Isometry3::Identity();
  pose.linear() = q.toRotationMatrix();
  pose.translation() = x;
  return pose;
}

Quat normalisedQuat(const VecX& y, Eigen::Index offset) {
  Quat q;
  q.coeffs() = y.segment<4>(offset);
  q.normalize();
  return q;
}

/// Name of the first non-finite field of body `i` in `s`, or nullptr.
const char* nonFiniteField(const WorldSnapshot& s, std::size_t i) {
  // x·0 is 0 for a finite x and NaN otherwise: one test for the common case
  // (a sum that overflows only falls through to the tests below).
  const double probe = s.position[i].sum() * 0.0 + s.orientation[i].coeffs().sum() * 0.0 +
                       s.linearVelocity[i].sum() * 0.0 + s.angularVelocity[i].sum() * 0.0;
  if (probe == 0.0) return nullptr;
  if (!s.position[i].allFinite()) return "position";
  if (!s.orientation[i].coeffs().allFinite()) return "orientation";
  if (!s.linearVelocity[i].allFinite()) return "linearVelocity";
  if (!s.angularVelocity[i].allFinite()) return "angularVelocity";
  return nullptr;
}

}  // namespace

// ---------------------------------------------------------------------------
// State

void WorldState::copyTo(WorldSnapshot& out) const {
  out.time = s_.time;
  out.stepCount = s_.stepCount;
  out.position = s_.position;
  out.orientation = s_.orientation;
  out.linearVelocity = s_.linearVelocity;
  out.angularVelocity = s_.angularVelocity;
}

std::uint64_t stateHash(const WorldSnapshot& s) noexcept {
  std::uint64_t h = 0xcbf29ce484222325ull;
  auto bytes = [&h](const void* p, std::size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (std::size_t k = 0; k < n; ++k) {
      h ^= b[k];
      h *= 0x100000001b3ull;
    }
  };
  bytes(&s.time, sizeof s.time);
  bytes(&s.stepCount, sizeof s.stepCount);
  const std::size_t n = s.position.size();
  for (std::size_t i = 0; i < n; ++i) {
    bytes(s.position[i].data(), 3 * sizeof(double));
    bytes(s.orientation[i].coeffs().data(), 4 * sizeof(double));
    bytes(s.linearVelocity[i].data(), 3 * sizeof(double));
    bytes(s.angularVelocity[i].data(), 3 * sizeof(double));
  }
  return h;
}

// ---------------------------------------------------------------------------
// Model setup

Result<BodyId> PhysicsWorld::addBody(const BodyDesc& desc) {
  const auto index = static_cast<std::uint32_t>(bodies_.size());
  if (index == BodyId::kInvalidIndex)
    return fail(ErrorCode::Busy, "the world is full", "PhysicsWorld::addBody", "use fewer bodies");
  if (auto st = validateBodyDesc(desc, bodyWhere(index, desc.name)); !st) return st.error();
  BodyDesc d = desc;
  d.orientation.normalize();
  BodyModel m{d.kind, 0.0, Mat3::Zero(), Mat3::Zero()};
  if (d.kind != BodyKind::Static) m.inverseMass = 1.0 / d.mass;
  if (d.kind == BodyKind::Rigid) {
    m.inertia = d.inertia;
    m.inverseInertia = d.inertia.inverse();
  } else {
    d.angularVelocity.setZero();  // particles and static bodies do not rotate
  }
  if (d.kind == BodyKind::Static) d.linearVelocity.setZero();
  if (d.kind != BodyKind::Static) {
    const auto k = static_cast<std::size_t>(d.integrator);
    members_[k].push_back(index);
    if (k < kSecondOrderKinds && d.kind == BodyKind::Rigid) rigidMembers_[k].push_back(index);
  }
  masses_.push_back(d.mass);
  materials_.emplace_back();
  model_.push_back(m);
  bodies_.push_back(std::move(d));
  return BodyId{index};
}

Status PhysicsWorld::setGravity(const Vec3& acceleration) {
  if (!acceleration.allFinite())
    return fail(ErrorCode::InvalidArgument, "gravity is not finite", "PhysicsWorld::setGravity",
                "give a finite acceleration in m/s², e.g. (0, 0, -9.81)");
  forces_.gravity = acceleration;
  return ok();
}

Status PhysicsWorld::addForce(const ExternalForce& force) {
  if (auto st = validateAccumulator(force, bodies_, "forces[" + std::to_string(forces_.forces.size()) + "]");
      !st)
    return st;
  forces_.forces.push_back(force);
  return ok();
}

Status PhysicsWorld::addTorque(const ExternalTorque& torque) {
  if (auto st =
          validateAccumulator(torque, bodies_, "torques[" + std::to_string(forces_.torques.size()) + "]");
      !st)
    return st;
  forces_.torques.push_back(torque);
  return ok();
}

Status PhysicsWorld::addDrag(const Drag& drag) {
  if (auto st = validateAccumulator(drag, bodies_, "drags[" + std::to_string(forces_.drags.size()) + "]");
      !st)
    return st;
  forces_.drags.push_back(drag);
  return ok();
}

Status PhysicsWorld::addNewtonianGravity(const NewtonianGravity& gravity) {
  if (auto st = validateAccumulator(gravity, bodies_,
                                    "newtonian[" + std::to_string(forces_.newtonian.size()) + "]");
      !st)
    return st;
  forces_.newtonian.push_back(gravity);
  return ok();
}

Status PhysicsWorld::addSpring(const Spring& spring) {
  if (auto st =
          validateAccumulator(spring, bodies_, "springs[" + std::to_string(forces_.springs.size()) + "]");
      !st)
    return st;
  forces_.springs.push_back(spring);
  return ok();
}

Status PhysicsWorld::addImpulse(const Impulse& impulse) {
  if (auto st = validateAccumulator(impulse, bodies_, "impulses[" + std::to_string(impulses_.size()) + "]");
      !st)
    return st;
  impulses_.push_back(impulse);
  return ok();
}

Status PhysicsWorld::addUserForce(std::string name, UserForceFn function) {
  if (!function)
    return fail(ErrorCode::InvalidArgument, "the function is empty", "user force '" + name + "'",
                "pass a callable");
  forces_.user.push_back(UserForce{std::move(name), std::move(function), nullptr, nullptr});
  return ok();
}

Status PhysicsWorld::addUserForce(std::string name, DmForceCallback callback, void* userData) {
  if (!callback)
    return fail(ErrorCode::InvalidArgument, "the callback is null", "user force '" + name + "'",
                "pass a function pointer");
  forces_.user.push_back(UserForce{std::move(name), {}, callback, userData});
  return ok();
}

Status PhysicsWorld::setMaterial(BodyId id, const ContactMaterial& material) {
  if (auto st = checkBody(id, "PhysicsWorld::setMaterial"); !st) return st;
  const std::string where = bodyWhere(id.index, bodies_[id.index].name) + " material";
  if (!std::isfinite(material.friction) || material.friction < 0.0)
    return fail(ErrorCode::InvalidArgument, "friction is " + std::to_string(material.friction), where,
                "give a Coulomb coefficient >= 0, e.g. 0.5");
  if (!std::isfinite(material.restitution) || material.restitution < 0.0 || material.restitution > 1.0)
    return fail(ErrorCode::InvalidArgument, "restitution is " + std::to_string(material.restitution), where,
                "give a coefficient of restitution in [0, 1]");
  materials_[id.index] = material;
  return ok();
}

const ContactMaterial& PhysicsWorld::material(BodyId id) const noexcept {
  DM_ASSERT(id.index < materials_.size(), "BodyId out of range");
  return materials_[id.index];
}

Status PhysicsWorld::setContactSettings(const ContactSettings& settings) {
  // The solver's own validation names the bad option; run it on an empty problem.
  ConstraintSolver probe;
  if (auto st = probe.solve({}, {}, {}, 1.0, settings.solver); !st)
    return fail(ErrorCode::InvalidArgument, st.error().what, "ContactSettings::solver", st.error().hint);
  if (settings.maxContactsPerPair < 1)
    return fail(ErrorCode::InvalidArgument,
                "maxContactsPerPair is " + std::to_string(settings.maxContactsPerPair),
                "ContactSettings::maxContactsPerPair", "give at least 1 (4 keeps box faces stable)");
  if (!std::isfinite(settings.ccdTolerance) || !(settings.ccdTolerance > 0.0))
    return fail(ErrorCode::InvalidArgument, "ccdTolerance is " + std::to_string(settings.ccdTolerance),
                "ContactSettings::ccdTolerance", "give a distance > 0 in m, e.g. 1e-6");
  if (!std::isfinite(settings.sleepLinearVelocity) || settings.sleepLinearVelocity < 0.0 ||
      !std::isfinite(settings.sleepAngularVelocity) || settings.sleepAngularVelocity < 0.0)
    return fail(ErrorCode::InvalidArgument, "a sleep velocity threshold is negative or not finite",
                "ContactSettings::sleepLinearVelocity / sleepAngularVelocity",
                "give thresholds >= 0, e.g. 0.05 m/s and 0.05 rad/s");
  if (!std::isfinite(settings.contactMargin) || settings.contactMargin < 0.0)
    return fail(ErrorCode::InvalidArgument, "contactMargin is " + std::to_string(settings.contactMargin),
                "ContactSettings::contactMargin", "give a distance >= 0 in m (0 turns persistent contacts off)");
  if (!std::isfinite(settings.timeToSleep) || !(settings.timeToSleep > 0.0))
    return fail(ErrorCode::InvalidArgument, "timeToSleep is " + std::to_string(settings.timeToSleep),
                "ContactSettings::timeToSleep", "give a time > 0 in s, e.g. 0.5");
  contactSettings_ = settings;
  return ok();
}

Result<std::size_t> PhysicsWorld::addJoint(const JointDesc& desc) {
  const std::string where = "joints[" + std::to_string(joints_.size()) + "]";
  for (const BodyId id : {desc.a, desc.b})
    if (id.valid())
      if (auto st = checkBody(id, where.c_str()); !st) return std::move(st).error();
  const auto index = [](BodyId id) { return id.valid() ? static_cast<int>(id.index) : kWorldBody; };
  const int a = index(desc.a), b = index(desc.b);
  const auto dynamic = [this](int i) {
    return i != kWorldBody && model_[static_cast<std::size_t>(i)].inverseMass > 0.0;
  };
  if (!dynamic(a) && !dynamic(b))
    return fail(ErrorCode::InvalidArgument, "neither body is dynamic", where,
                "join at least one particle or rigid body (a default BodyId is the static world)");
  if (!desc.anchor.allFinite() || !desc.axis.allFinite() || !std::isfinite(desc.lower) ||
      !std::isfinite(desc.upper))
    return fail(ErrorCode::InvalidArgument, "anchor, axis or a limit is not finite", where,
                "give finite values");
  if (desc.limitEnabled && desc.lower > desc.upper)
    return fail(ErrorCode::InvalidArgument, "lower limit > upper limit", where, "swap the limits");
  std::vector<SolverBody> poses(bodies_.size());
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    poses[i] = SolverBody::fixed(bodies_[i].position, bodies_[i].orientation);
  Result<Joint> joint = fail(ErrorCode::InvalidArgument, "unknown joint type", where, "use dm::JointType");
  switch (desc.type) {
    case JointType::Ball:
      joint = Joint::ball(poses, a, b, desc.anchor);
      break;
    case JointType::Hinge:
      joint = Joint::hinge(poses, a, b, desc.anchor, desc.axis);
      break;
    case JointType::Slider:
      joint = Joint::slider(poses, a, b, desc.anchor, desc.axis);
      break;
    case JointType::Fixed:
      joint = Joint::fixed(poses, a, b, desc.anchor);
      break;
  }
  if (!joint) {
    const Error& e = joint.error();
    return fail(e.code, e.what, where, e.hint);
  }
  joint->limitEnabled = desc.limitEnabled;
  joint->lower = desc.lower;
  joint->upper = desc.upper;
  if (a != kWorldBody && b != kWorldBody) {
    const auto lo = static_cast<std::uint64_t>(std::min(a, b)),
               hi = static_cast<std::uint64_t>(std::max(a, b));
    const std::uint64_t key = (lo << 32) | hi;
    jointedPairs_.insert(std::lower_bound(jointedPairs_.begin(), jointedPairs_.end(), key), key);
  }
  joints_.push_back(*joint);
  jointDescs_.push_back(desc);
  return joints_.size() - 1;
}

Result<const BodyDesc*> PhysicsWorld::meshedBody(BodyId id, const std::string& where) const {
  if (!id.valid() || id.index >= bodies_.size())
    return fail(ErrorCode::InvalidArgument, "the body is not in the world", where, "use an id from addBody");
  const BodyDesc& d = bodies_[id.index];
  if (d.kind == BodyKind::Particle)
    return fail(ErrorCode::InvalidArgument, "body '" + d.name + "' is a particle", where,
                "couple rigid or static bodies (a particle has no orientation for its mesh)");
  return &d;
}

Result<BodyId> PhysicsWorld::findBody(std::string_view name) const {
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    if (bodies_[i].name == name) return BodyId{static_cast<std::uint32_t>(i)};
  return fail(ErrorCode::NotFound, "no body is named '" + std::string(name) + "'", "PhysicsWorld::findBody",
              "check the name given to addBody");
}

Status PhysicsWorld::checkBody(BodyId id, const char* what) const {
  if (id.valid() && id.index < bodies_.size()) return ok();
  return fail(ErrorCode::NotFound,
              "body " + (id.valid() ? std::to_string(id.index) : std::string("<invalid>")) +
                  " does not exist (the world has " + std::to_string(bodies_.size()) + " bodies)",
              what, "pass an id returned by addBody of this world");
}

// ---------------------------------------------------------------------------
// State creation and access

WorldState PhysicsWorld::makeState() const {
  const std::size_t n = bodies_.size();
  WorldState st;
  WorldSnapshot& s = st.s_;
  s.position.resize(n);
  s.orientation.resize(n);
  s.linearVelocity.resize(n);
  s.angularVelocity.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    s.position[i] = bodies_[i].position;
    s.orientation[i] = bodies_[i].orientation;
    s.linearVelocity[i] = bodies_[i].linearVelocity;
    s.angularVelocity[i] = bodies_[i].angularVelocity;
  }
  st.bounds_.resize(n);
  st.force_.assign(n, Vec3::Zero());
  st.torque_.assign(n, Vec3::Zero());
  WorldState::Scratch& sc = st.scratch_;
  sc.stagePosition = s.position;
  sc.stageOrientation = s.orientation;
  sc.stageLinearVelocity = s.linearVelocity;
  sc.stageAngularVelocity = s.angularVelocity;
  sc.force.assign(n, Vec3::Zero());
  sc.torque.assign(n, Vec3::Zero());
  for (int k = 0; k < kSecondOrderKinds; ++k) {
    const auto m = static_cast<Eigen::Index>(3 * members_[k].size());
    sc.x[k].setZero(m);
    sc.v[k].setZero(m);
    sc.secondOrder[k].acc.setZero(m);
    sc.secondOrder[k].accNext.setZero(m);
    sc.secondOrder[k].vPred.setZero(m);
    const auto r = static_cast<Eigen::Index>(rigidMembers_[k].size());
    sc.rotation[k].setZero(kRotationSize * r);
    sc.firstTorque[k].setZero(3 * r);
    sc.rotationWs[k].resize(kRotationSize * r);
  }
  const auto m2 = static_cast<Eigen::Index>(members_[kRk4Kind].size());
  sc.rk4State.setZero(kRk4Size * m2);
  sc.rk4Ws.resize(kRk4Size * m2);
  updateBounds(st);
  reserveContacts(st);
  return st;
}

void PhysicsWorld::updateBound(WorldState& state, std::size_t i) const {
  const WorldSnapshot& s = state.s_;
  const BodyDesc& d = bodies_[i];
  if (d.shape)
    state.bounds_[i] = d.shape->aabb(bodyPose(s.position[i], s.orientation[i]) * d.shapeOffset);
  else
    state.bounds_[i] = Aabb(s.position[i], s.position[i]);
}

void PhysicsWorld::updateBounds(WorldState& state) const {
  for (std::size_t i = 0; i < bodies_.size(); ++i) updateBound(state, i);
}

Status PhysicsWorld::restore(WorldState& state, const WorldSnapshot& snap) const {
  const std::size_t n = bodies_.size();
  if (state.s_.position.size() != n)
    return fail(ErrorCode::InvalidArgument,
                "the state has " + std::to_string(state.s_.position.size()) + " bodies, the world " +
                    std::to_string(n),
                "PhysicsWorld::restore", "make the state with this world's makeState()");
  if (snap.position.size() != n || snap.orientation.size() != n || snap.linearVelocity.size() != n ||
      snap.angularVelocity.size() != n)
    return fail(ErrorCode::InvalidArgument,
                "the snapshot's arrays do not all have " + std::to_string(n) + " entries",
                "PhysicsWorld::restore", "restore a snapshot taken from a state of this world");
  if (!std::isfinite(snap.time))
    return fail(ErrorCode::InvalidArgument, "time is not finite", "PhysicsWorld::restore snapshot",
                "restore a snapshot taken from a state of this world");
  for (std::size_t i = 0; i < n; ++i) {
    const char* field = nonFiniteField(snap, i);
    if (field)
      return fail(ErrorCode::InvalidArgument, std::string(field) + " is not finite",
                  "snapshot " + bodyWhere(static_cast<std::uint32_t>(i), bodies_[i].name),
                  "restore a snapshot taken before the failing step");
  }
  // Same sizes: vector assignment reuses the storage.
  state.s_.time = snap.time;
  state.s_.stepCount = snap.stepCount;
  state.s_.position = snap.position;
  state.s_.orientation = snap.orientation;
  state.s_.linearVelocity = snap.linearVelocity;
  state.s_.angularVelocity = snap.angularVelocity;
  updateBounds(state);
  // Warm-start impulses and sleep are not part of a snapshot: start them afresh.
  state.contact_.cache.clear();
  wakeAll(state);
  for (Joint& j : state.contact_.joints) j.impulses.fill(0.0);
  return ok();
}

Status PhysicsWorld::setBodyState(WorldState& state, BodyId id, const Vec3& position, const Quat& orientation,
                                  const Vec3& linearVelocity, const Vec3& angularVelocity) const {
  if (auto st = checkBody(id, "PhysicsWorld::setBodyState"); !st) return st;
  if (state.s_.position.size() != bodies_.size())
    return fail(ErrorCode::InvalidArgument, "the state does not belong to this world",
                "PhysicsWorld::setBodyState", "make the state with this world's makeState()");
  const auto where = [&] {
    return bodyWhere(id.index, bodies_[id.index].name);
  };  // (errors only: no allocation)
  if (!position.allFinite() || !orientation.coeffs().allFinite() || !linearVelocity.allFinite() ||
      !angularVelocity.allFinite())
    return fail(ErrorCode::InvalidArgument, "a position, orientation or velocity is not finite", where(),
                "give finite values");
  if (!(orientation.norm() > 1e-12))
    return fail(ErrorCode::InvalidArgument, "orientation is a zero quaternion", where(),
                "give a unit quaternion");
  const std::uint32_t i = id.index;
  const BodyKind kind = bodies_[i].kind;
  state.s_.position[i] = position;
  state.s_.orientation[i] = orientation.normalized();
  state.s_.linearVelocity[i] = kind == BodyKind::Static ? Vec3::Zero() : linearVelocity;
  state.s_.angularVelocity[i] = kind == BodyKind::Rigid ? angularVelocity : Vec3::Zero();
  updateBound(state, i);  // only this body moved: O(1), as couplings call it per touched body every step
  wakeIsland(state, i);
  return ok();
}

void PhysicsWorld::applyImpulseAt(WorldState& state, std::uint32_t i, const Vec3& impulse,
                                  const Vec3& r) const {
  const BodyModel& m = model_[i];
  state.s_.linearVelocity[i] += m.inverseMass * impulse;
  if (m.kind == BodyKind::Rigid) {
    const Mat3 rot = state.s_.orientation[i].toRotationMatrix();
    state.s_.angularVelocity[i] += rot * (m.inverseInertia * (rot.transpose() * r.cross(impulse)));
  }
}

Status PhysicsWorld::applyImpulse(WorldState& state, BodyId id, const Vec3& impulse,
                                  const Vec3& point) const {
  if (auto st = checkBody(id, "PhysicsWorld::applyImpulse"); !st) return st;
  if (state.s_.position.size() != bodies_.size())
    return fail(ErrorCode::InvalidArgument, "the state does not belong to this world",
                "PhysicsWorld::applyImpulse", "make the state with this world's makeState()");
  const auto where = [&] {
    return bodyWhere(id.index, bodies_[id.index].name);
  };  // (errors only: no allocation)
  if (bodies_[id.index].kind == BodyKind::Static)
    return fail(ErrorCode::InvalidArgument, "the body is static", where(),
                "apply impulses to dynamic bodies");
  if (!impulse.allFinite() || !point.allFinite())
    return fail(ErrorCode::InvalidArgument, "impulse or point is not finite", where(), "give finite values");
  wakeIsland(state, id.index);
  applyImpulseAt(state, id.index, impulse, point - state.s_.position[id.index]);
  return ok();
}

double PhysicsWorld::kineticEnergy(const WorldState& state) const noexcept {
  double e = 0.0;
  for (std::size_t i = 0; i < bodies_.size(); ++i) {
    if (model_[i].kind == BodyKind::Static) continue;
    e += 0.5 * masses_[i] * state.s_.linearVelocity[i].squaredNorm();
    if (model_[i].kind == BodyKind::Rigid) {
      const Vec3& w = state.s_.angularVelocity[i];
      e += 0.5 * w.dot(worldInertia(state.s_.orientation[i].toRotationMatrix(), model_[i].inertia) * w);
    }
  }
  return e;
}

Vec3 PhysicsWorld::linearMomentum(const WorldState& state) const noexcept {
  Vec3 p = Vec3::Zero();
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    if (model_[i].kind != BodyKind::Static) p += masses_[i] * state.s_.linearVelocity[i];
  return p;
}

Vec3 PhysicsWorld::angularMomentum(const WorldState& state, const Vec3& about) const noexcept {
  Vec3 l = Vec3::Zero();
  for (std::size_t i = 0; i < bodies_.size(); ++i) {
    if (model_[i].kind == BodyKind::Static) continue;
    l += (state.s_.position[i] - about).cross(masses_[i] * state.s_.linearVelocity[i]);
    if (model_[i].kind == BodyKind::Rigid)
      l += worldInertia(state.s_.orientation[i].toRotationMatrix(), model_[i].inertia) *
           state.s_.angularVelocity[i];
  }
  return l;
}

// ---------------------------------------------------------------------------
// Step

void PhysicsWorld::evaluate(WorldState& state, double t) const {
  WorldState::Scratch& sc = state.scratch_;
  const BodyStateView view{
      t, sc.stagePosition, sc.stageOrientation, sc.stageLinearVelocity, sc.stageAngularVelocity, masses_};
  ForceOutput out{sc.force, sc.torque};
  accumulateForces(forces_, view, out);
  if (sc.recordForces) {
    state.force_ = sc.force;  // same sizes: no allocation
    state.torque_ = sc.torque;
    sc.recordForces = false;
  }
}

void PhysicsWorld::stepSecondOrder(WorldState& state, int kind, double t, double dt) const {
  const std::vector<std::uint32_t>& members = members_[kind];
  if (members.empty()) return;
  const std::vector<std::uint32_t>& rigid = rigidMembers_[kind];
  WorldState::Scratch& sc = state.scratch_;
  WorldSnapshot& s = state.s_;
  const Eigen::Index m = static_cast<Eigen::Index>(members.size());
  for (Eigen::Index j = 0; j < m; ++j) {
    sc.x[kind].segment<3>(3 * j) = s.position[members[j]];
    sc.v[kind].segment<3>(3 * j) = s.linearVelocity[members[j]];
  }
  sc.activeKind = kind;
  sc.firstEvaluation = true;
  WorldState* st = &state;
  // Two pointers: small enough for std::function's local storage (no allocation).
  const SecondOrderRhs acceleration = [this, st](double tt, const VecX& x, const VecX& v, VecX& acc) {
    WorldState::Scratch& c = st->scratch_;
    const std::vector<std::uint32_t>& mem = members_[c.activeKind];
    const Eigen::Index count = static_cast<Eigen::Index>(mem.size());
    for (Eigen::Index j = 0; j < count; ++j) {
      c.stagePosition[mem[j]] = x.segment<3>(3 * j);
      c.stageLinearVelocity[mem[j]] = v.segment<3>(3 * j);
    }
    evaluate(*st, tt);
    for (Eigen::Index j = 0; j < count; ++j)
      acc.segment<3>(3 * j) = model_[mem[j]].inverseMass * c.force[mem[j]];
    if (c.firstEvaluation) {
      const std::vector<std::uint32_t>& rig = rigidMembers_[c.activeKind];
      for (std::size_t r = 0; r < rig.size(); ++r)
        c.firstTorque[c.activeKind].segment<3>(3 * static_cast<Eigen::Index>(r)) = c.torque[rig[r]];
      c.firstEvaluation = false;
    }
  };
  // Velocity Verlet's cached end-of-step acceleration is not part of the
  // snapshot, and impulses change v between steps: always start afresh.
  sc.secondOrder[kind].invalidate();
  if (kind == static_cast<int>(IntegratorKind::SymplecticEuler))
    symplecticEulerStep(acceleration, t, dt, sc.x[kind], sc.v[kind], sc.secondOrder[kind]);
  else
    velocityVerletStep(acceleration, t, dt, sc.x[kind], sc.v[kind], sc.secondOrder[kind]);
  for (Eigen::Index j = 0; j < m; ++j) {
    const std::uint32_t i = members[j];
    s.position[i] = sc.stagePosition[i] = sc.x[kind].segment<3>(3 * j);
    s.linearVelocity[i] = sc.stageLinearVelocity[i] = sc.v[kind].segment<3>(3 * j);
  }
  if (rigid.empty()) return;

  // Rotation: RK4 on Euler's equations with the first evaluation's torque.
  VecX& y = sc.rotation[kind];
  for (std::size_t r = 0; r < rigid.size(); ++r) {
    const auto o = kRotationSize * static_cast<Eigen::Index>(r);
    y.segment<4>(o) = s.orientation[rigid[r]].coeffs();
    y.segment<3>(o + 4) = s.angularVelocity[rigid[r]];
  }
  const OdeRhs rotation = [this, st](double, const VecX& yy, VecX& dydt) {
    const WorldState::Scratch& c = st->scratch_;
    const std::vector<std::uint32_t>& rig = rigidMembers_[c.activeKind];
    for (std::size_t r = 0; r < rig.size(); ++r) {
      const auto o = kRotationSize * static_cast<Eigen::Index>(r);
      const BodyModel& bm = model_[rig[r]];
      Quat q;
      q.coeffs() = yy.segment<4>(o);
      const Vec3 w = yy.segment<3>(o + 4);
      dydt.segment<4>(o) = quaternionDerivative(q, w);
      const Vec3 tau = c.firstTorque[c.activeKind].segment<3>(3 * static_cast<Eigen::Index>(r));
      dydt.segment<3>(o + 4) =
          angularAcceleration(q.normalized().toRotationMatrix(), bm.inertia, bm.inverseInertia, w, tau);
    }
  };
  rk4Step(rotation, t, dt, y, sc.rotationWs[kind]);
  for (std::size_t r = 0; r < rigid.size(); ++r) {
    const auto o = kRotationSize * static_cast<Eigen::Index>(r);
    const std::uint32_t i = rigid[r];
    s.orientation[i] = sc.stageOrientation[i] = normalisedQuat(y, o);
    s.angularVelocity[i] = sc.stageAngularVelocity[i] = y.segment<3>(o + 4);
  }
}

void PhysicsWorld::stepRk4(WorldState& state, double t, double dt) const {
  const std::vector<std::uint32_t>& members = members_[kRk4Kind];
  if (members.empty()) return;
  WorldState::Scratch& sc = state.scratch_;
  WorldSnapshot& s = state.s_;
  VecX& y = sc.rk4State;
  for (std::size_t j = 0; j < members.size(); ++j) {
    const auto o = kRk4Size * static_cast<Eigen::Index>(j);
    const std::uint32_t i = members[j];
    y.segment<3>(o) = s.position[i];
    y.segment<4>(o + 3) = s.orientation[i].coeffs();
    y.segment<3>(o + 7) = s.linearVelocity[i];
    y.segment<3>(o + 10) = s.angularVelocity[i];
  }
  WorldState* st = &state;
  const OdeRhs rhs = [this, st](double tt, const VecX& yy, VecX& dydt) {
    WorldState::Scratch& c = st->scratch_;
    const std::vector<std::uint32_t>& mem = members_[kRk4Kind];
    for (std::size_t j = 0; j < mem.size(); ++j) {
      const auto o = kRk4Size * static_cast<Eigen::Index>(j);
      const std::uint32_t i = mem[j];
      c.stagePosition[i] = yy.segment<3>(o);
      if (model_[i].kind == BodyKind::Rigid) c.stageOrientation[i] = normalisedQuat(yy, o + 3);
      c.stageLinearVelocity[i] = yy.segment<3>(o + 7);
      c.stageAngularVelocity[i] = yy.segment<3>(o + 10);
    }
    evaluate(*st, tt);
    for (std::size_t j = 0; j < mem.size(); ++j) {
      const auto o = kRk4Size * static_cast<Eigen::Index>(j);
      const std::uint32_t i = mem[j];
      const BodyModel& bm = model_[i];
      dydt.segment<3>(o) = yy.segment<3>(o + 7);
      dydt.segment<3>(o + 7) = bm.inverseMass * c.force[i];
      if (bm.kind == BodyKind::Rigid) {
        Quat q;
        q.coeffs() = yy.segment<4>(o + 3);
        const Vec3 w = yy.segment<3>(o + 10);
        dydt.segment<4>(o + 3) = quaternionDerivative(q, w);
        dydt.segment<3>(o + 10) = angularAcceleration(c.stageOrientation[i].toRotationMatrix(), bm.inertia,
                                                      bm.inverseInertia, w, c.torque[i]);
      } else {
        dydt.segment<4>(o + 3).setZero();
        dydt.segment<3>(o + 10).setZero();
      }
    }
  };
  rk4Step(rhs, t, dt, y, sc.rk4Ws);
  for (std::size_t j = 0; j < members.size(); ++j) {
    const auto o = kRk4Size * static_cast<Eigen::Index>(j);
    const std::uint32_t i = members[j];
    s.position[i] = sc.stagePosition[i] = y.segment<3>(o);
    if (model_[i].kind == BodyKind::Rigid)
      s.orientation[i] = sc.stageOrientation[i] = normalisedQuat(y, o + 3);
    s.linearVelocity[i] = sc.stageLinearVelocity[i] = y.segment<3>(o + 7);
    s.angularVelocity[i] = sc.stageAngularVelocity[i] = y.segment<3>(o + 10);
  }
}

Status PhysicsWorld::step(WorldState& state, double dt) const {
  if (!std::isfinite(dt) || !(dt > 0))
    return fail(ErrorCode::InvalidArgument, "dt is " + std::to_string(dt) + " s", "PhysicsWorld::step",
                "give a finite time step > 0");
  const std::size_t n = bodies_.size();
  if (state.s_.position.size() != n || state.scratch_.force.size() != n ||
      state.scratch_.rk4State.size() != kRk4Size * static_cast<Eigen::Index>(members_[kRk4Kind].size()))
    return fail(ErrorCode::InvalidArgument,
                "the state has " + std::to_string(state.s_.position.size()) + " bodies, the world " +
                    std::to_string(n),
                "PhysicsWorld::step", "bodies were added after makeState(): make a new state");
  if (state.contact_.joints.size() != joints_.size() || state.contact_.bodies.size() != n)
    return fail(ErrorCode::InvalidArgument, "the state was made before joints or bodies were added",
                "PhysicsWorld::step", "make a new state with makeState()");
  WorldSnapshot& s = state.s_;
  WorldState::Scratch& sc = state.scratch_;
  const double t0 = s.time;
  const bool contacts = contactsActive();
  if (contacts) beginContacts(state);

  // 0. Impulses due in [t0, t0 + dt).
  for (const Impulse& imp : impulses_)
    if (imp.time >= t0 && imp.time < t0 + dt)
      applyImpulseAt(state, imp.body.index, imp.impulse, s.orientation[imp.body.index] * imp.point);

  // 1. Accumulate and integrate, one integrator kind after another.
  sc.stagePosition = s.position;  // same sizes: no allocation
  sc.stageOrientation = s.orientation;
  sc.stageLinearVelocity = s.linearVelocity;
  sc.stageAngularVelocity = s.angularVelocity;
  sc.recordForces = true;
  if (members_[0].empty() && members_[1].empty() && members_[kRk4Kind].empty()) evaluate(state, t0);
  for (int k = 0; k < kSecondOrderKinds; ++k) stepSecondOrder(state, k, t0, dt);
  stepRk4(state, t0, dt);
  if (contacts && state.contact_.sleeping > 0) holdSleepers(state);

  // 2. Contacts and joints.
  if (contacts) {
    if (auto st = finishContacts(state, dt); !st) return st;
  }

  // 3. Time and bounds.
  s.time = t0 + dt;
  ++s.stepCount;
  updateBounds(state);

  for (std::size_t i = 0; i < n; ++i) {
    const char* field = nonFiniteField(s, i);
    if (field)
      return fail(
          ErrorCode::Unsupported,
          std::string(field) + " became non-finite at t = " + std::to_string(s.time) + " s",
          bodyWhere(static_cast<std::uint32_t>(i), bodies_[i].name),
          "reduce dt, soften stiff springs or use another integrator; restore a snapshot to continue");
  }
  return ok();
}

}  // namespace dm
