// physics_engine.cpp — the scene's rigid bodies on one dm::PhysicsWorld
// (stepped by the built-in solver or by ODE, dm::OdeWorld, as the scene's
// "backend" says), coupled to the haptic tool by impulses and poses, and its
// soft objects (soft_tissue.hpp) (physics_engine.hpp).
#include "physics_engine.hpp"

#include <dm/collide/shapes.hpp>
#include <dm/haptics/haptic_loop.hpp>
#include <dm/haptics/tool_impulse.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/math/mass_properties.hpp>
#include <dm/physics/ode_backend.hpp>
#include <dm/physics/world.hpp>
#include <dm/physics/world_report.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <optional>

#include "engine_json.hpp"
#include "scene_fluids.hpp"
#include "scene_membranes.hpp"
#include "script_engine.hpp"
#include "soft_tissue.hpp"

namespace dm {

namespace {

// A body's collision shape and mass distribution, in the body frame: the
// object frame moved to the centre of mass (axes unchanged), so
// object → world = body → world · objectInBody.
struct BodyGeometry {
  ShapePtr shape;
  Isometry3 shapeOffset = Isometry3::Identity();  // shape frame in the body frame
  Isometry3 objectInBody = Isometry3::Identity();
  double volume = 0.0;               // m³
  Mat3 inertiaPerKg = Mat3::Zero();  // kg·m² per kg of mass, about the centre of mass
};

Mat3 diag(double x, double y, double z) { return Vec3(x, y, z).asDiagonal(); }

// Analytic shapes: the scene's shape resources at the object's scale,
// centred at their origin with their axis along +z.
Result<BodyGeometry> primitiveGeometry(const SceneResource& r, double scale, bool dynamic,
                                       const std::string& where) {
  using S = SceneResource::Shape;
  constexpr double pi = std::numbers::pi;
  BodyGeometry g;
  const double rad = r.radius * scale;
  switch (r.shape) {
    case S::Sphere:
      g.shape = std::make_shared<Sphere>(rad);
      g.volume = 4.0 / 3.0 * pi * rad * rad * rad;
      g.inertiaPerKg = Mat3::Identity() * (0.4 * rad * rad);
      break;
    case S::Box: {
      const Vec3 h = r.halfExtents * scale;
      g.shape = std::make_shared<Box>(h);
      g.volume = 8.0 * h.prod();
      g.inertiaPerKg =
          diag(h.y() * h.y() + h.z() * h.z(), h.x() * h.x() + h.z() * h.z(), h.x() * h.x() + h.y() * h.y()) /
          3.0;
      break;
    }
    case S::Cylinder: {
      const double len = r.height * scale;
      g.shape = std::make_shared<Cylinder>(rad, 0.5 * len);
      g.volume = pi * rad * rad * len;
      const double side = (3.0 * rad * rad + len * len) / 12.0;
      g.inertiaPerKg = diag(side, side, 0.5 * rad * rad);
      break;
    }
    case S::Capsule: {
      // A cylinder of length `len` between two hemispherical caps; per kg:
      // the cylinder's share c and the caps' share s of the volume.
      const double len = r.height * scale;
      g.shape = std::make_shared<Capsule>(rad, 0.5 * len);
      const double vc = pi * rad * rad * len, vs = 4.0 / 3.0 * pi * rad * rad * rad;
      g.volume = vc + vs;
      const double c = vc / g.volume, s = vs / g.volume;
      const double axial = c * 0.5 * rad * rad + s * 0.4 * rad * rad;
      const double side = c * (len * len / 12.0 + rad * rad / 4.0) +
                          s * (0.4 * rad * rad + len * len / 4.0 + 3.0 * len * rad / 8.0);
      g.inertiaPerKg = diag(side, side, axial);
      break;
    }
    case S::Compound: {
      // The parts as one rigid body of uniform density: its centre of mass
      // the parts' volume-weighted centres, its inertia theirs moved there
      // (parallel axes; overlaps counted twice).
      std::vector<CompoundChild> children;
      std::vector<std::pair<BodyGeometry, Isometry3>> parts;
      Vec3 center = Vec3::Zero();
      for (const SceneResource::Part& part : r.parts) {
        auto pg = primitiveGeometry(scenePartShape(r, part), scale, dynamic, where);
        if (!pg) return pg.error();
        Isometry3 pose = part.pose.isometry();
        pose.translation() *= scale;
        g.volume += pg->volume;
        center += pg->volume * pose.translation();
        parts.emplace_back(std::move(*pg), pose);
      }
      if (g.volume > 0) center /= g.volume;
      for (auto& [pg, pose] : parts) {
        const Mat3 rot = pose.linear();
        const Vec3 d = pose.translation() - center;
        g.inertiaPerKg += pg.volume / g.volume *
                          (rot * pg.inertiaPerKg * rot.transpose() +
                           (d.squaredNorm() * Mat3::Identity() - d * d.transpose()));
        children.push_back({pg.shape, pose});
      }
      g.shape = std::make_shared<Compound>(std::move(children));
      g.shapeOffset = Isometry3(Eigen::Translation3d(-center));
      g.objectInBody = g.shapeOffset;
      break;
    }
    case S::Plane: {
      // A finite rectangle in z = 0, solid below: a slab as deep as its
      // shorter side, so nothing that lands on it can tunnel through.
      if (dynamic)
        return fail(ErrorCode::InvalidArgument, "a plane cannot be a dynamic body", where, "use a thin box");
      const Vec3 h(r.halfExtents.x() * scale, r.halfExtents.y() * scale,
                   0.5 * std::min(r.halfExtents.x(), r.halfExtents.y()) * scale);
      g.shape = std::make_shared<Box>(h);
      g.shapeOffset = Isometry3(Eigen::Translation3d(0, 0, -h.z()));
      break;
    }
  }
  return g;
}

// Meshes (files, isosurfaces): a static object collides as its triangles;
// a dynamic one as their convex hull, with the mass distribution of the
// closed mesh itself.
// The resource's mesh is shared, not copied, at scale 1 (a skin isosurface
// holds a million triangles).
Result<BodyGeometry> meshGeometry(std::shared_ptr<const Mesh> mesh, double scale, bool dynamic,
                                  const std::string& where) {
  if (scale != 1.0) {
    auto scaled = std::make_shared<Mesh>(*mesh);
    for (Vec3& p : scaled->positions) p *= scale;
    mesh = std::move(scaled);
  }
  BodyGeometry g;
  if (!dynamic) {
    auto tm = TriangleMesh::create(std::move(mesh));
    if (!tm) return tm.error().within(where);
    g.shape = *tm;
    return g;
  }
  auto mp = computeMassProperties(*mesh, 1.0);
  if (!mp)
    return fail(ErrorCode::InvalidArgument, "its mesh has no mass properties: " + mp.error().message(), where,
                "a dynamic mesh object must be closed and consistently oriented");
  auto hull = ConvexHull::create(mesh->positions);
  if (!hull) return hull.error().within(where);
  g.shape = *hull;
  g.volume = mp->volume;
  g.inertiaPerKg = mp->inertia / mp->mass;  // density 1: mass = volume
  g.shapeOffset = Isometry3(Eigen::Translation3d(-mp->centroid));
  g.objectInBody = g.shapeOffset;
  return g;
}

// A user force adding, each step, the force and torque held per body in
// `force` and `torque` (body order; their owner outlives the world).
Status addHeldForces(PhysicsWorld& world, const char* name, const std::vector<Vec3>& force,
                     const std::vector<Vec3>& torque) {
  return world.addUserForce(name, [&force, &torque](const BodyStateView&, ForceOutput& out) {
    for (std::size_t b = 0; b < force.size(); ++b) {
      out.force[b] += force[b];
      out.torque[b] += torque[b];
    }
  });
}

}  // namespace

struct PhysicsEngine::Impl {
  struct Body {
    std::string object;
    BodyId id;
    bool dynamic = false;
    Isometry3 objectInBody = Isometry3::Identity();
    Vec3 start = Vec3::Zero();  // centre of mass at t = 0
  };
  PhysicsWorld world;
  WorldState state;
  std::optional<OdeWorld> ode;  // the "ode" backend: steps `state` instead of world.step
  bool sleep = false;
  std::vector<Body> bodies;             // by body index
  std::vector<std::string> joints;      // the scene's joint names, by joint index
  std::vector<std::uint32_t> moving;    // dynamic bodies, scene order
  std::vector<int> touchedBody;         // per touched object: body index, or -1 (never moves)
  std::vector<Isometry3> touchedPoses;  // published to the haptic loop
  std::unique_ptr<ToolImpulseChannel> tools;
  std::unique_ptr<HapticLocalModel> model;
  std::vector<ToolImpulse> impulses;        // per touched object, this tick
  std::vector<Vec3> toolForce, toolTorque;  // per body, applied over this step
  // The moving objects' poses for each reader thread (PoseReader order).
  std::array<std::unique_ptr<TripleBuffer<std::vector<Isometry3>>>, 2> readerPoses;
  // Scripts: their channels, the forces they hold (per body, summed over
  // the scripts), and the needle's punctures they last heard of.
  std::vector<ScriptFeed*> scripts;
  std::vector<Vec3> scriptForce, scriptTorque;
  std::size_t punctures = 0;
  std::unique_ptr<SoftTissues> soft;    // the soft objects, stepped after the rigid bodies
  std::unique_ptr<SceneMembranes> membranes;  // then the membranes
  std::vector<std::string> drawnDeformed;     // soft objects, then membranes
  std::unique_ptr<SceneFluids> fluids;  // the fluids, stepped after them
  std::vector<FluidBody> fluidBodies;   // the dynamic bodies as the fluids see them (moving order)
  std::vector<Vec3> fluidForce, fluidTorque;  // per body: what the fluids did over the last step, held
  std::uint64_t steps = 0;
  double lastDt = 0.0;

  Isometry3 bodyPose(std::uint32_t b) const {  // body frame (origin at the centre of mass) → world
    Isometry3 body = Isometry3::Identity();
    body.translate(state.position(bodies[b].id));
    body.rotate(state.orientation(bodies[b].id));
    return body;
  }
  Isometry3 objectPose(std::uint32_t b) const { return bodyPose(b) * bodies[b].objectInBody; }
};

PhysicsEngine::PhysicsEngine(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {
  for (std::uint32_t b : impl_->moving) movingNames_.push_back(impl_->bodies[b].object);
}
PhysicsEngine::~PhysicsEngine() = default;

HapticLocalModel* PhysicsEngine::hapticModel() noexcept { return impl_->model.get(); }
ToolImpulseChannel* PhysicsEngine::toolImpulses() noexcept { return impl_->tools.get(); }

Result<std::shared_ptr<PhysicsEngine>> PhysicsEngine::build(const SceneDesc& scene,
                                                            const SceneResources& resources,
                                                            std::span<const std::string> touched) {
  const ScenePhysicsEngine& cfg = *scene.engines.physics;
  auto m = std::make_unique<Impl>();
  if (auto s = m->world.setGravity(cfg.gravity); !s) return s.error().within("engines/physics/gravity");
  ContactSettings contact = m->world.contactSettings();
  contact.sleep = cfg.sleep;
  if (auto s = m->world.setContactSettings(contact); !s) return s.error().within("engines/physics");
  m->sleep = cfg.sleep;
  const std::string proxy = scene.engines.haptics ? scene.engines.haptics->proxyObject : std::string();

  for (const SceneObject& o : scene.objects) {
    if (o.name == proxy || o.soft || (!o.dynamic && !o.collide)) continue;
    const std::string where = "objects/" + o.name;
    const SceneResource* res = scene.resource(o.mesh);
    auto mesh = resources.mesh(o.mesh);
    if (res == nullptr || !mesh)
      return fail(ErrorCode::NotFound, "mesh \"" + o.mesh + "\" was not loaded", where);
    auto g = res->type == SceneResource::Type::Shape ? primitiveGeometry(*res, o.scale, o.dynamic, where)
                                                     : meshGeometry(mesh, o.scale, o.dynamic, where);
    if (!g) return g.error();
    BodyDesc d;
    d.name = o.name;
    d.shape = g->shape;
    d.shapeOffset = g->shapeOffset;
    const Isometry3 body0 = o.pose.isometry() * g->objectInBody.inverse();
    d.position = body0.translation();
    d.orientation = Quat(body0.rotation());
    if (o.dynamic) {
      d.kind = BodyKind::Rigid;
      d.mass = o.mass > 0.0 ? o.mass : o.density * g->volume;
      d.inertia = g->inertiaPerKg * d.mass;
      d.linearVelocity = o.velocity;
      d.angularVelocity = o.angularVelocity;
    } else {
      d.kind = BodyKind::Static;
    }
    auto id = m->world.addBody(d);
    if (!id) return id.error().within(where);
    if (auto s = m->world.setMaterial(
            *id, {.friction = o.friction, .restitution = o.restitution, .collides = o.collide});
        !s)
      return s.error().within(where + "/contact");
    if (o.dynamic) m->moving.push_back(id->index);
    m->bodies.push_back({o.name, *id, o.dynamic, g->objectInBody, d.position});
  }

  // Joints ("joints"), between the bodies just added or to the world, from
  // their initial poses.
  for (const SceneJoint& j : cfg.joints) {
    const std::string where = "engines/physics/joints/" + j.name;
    const auto bodyOf = [&](const std::string& name) -> Result<BodyId> {
      for (const Impl::Body& b : m->bodies)
        if (b.object == name) return b.id;
      return fail(ErrorCode::NotFound, "object \"" + name + "\" is not a body of the physics world", where);
    };
    JointDesc d;
    d.type = j.type == SceneJoint::Type::Ball     ? JointType::Ball
             : j.type == SceneJoint::Type::Hinge  ? JointType::Hinge
             : j.type == SceneJoint::Type::Slider ? JointType::Slider
                                                  : JointType::Fixed;
    auto a = bodyOf(j.a);
    if (!a) return a.error();
    d.a = *a;
    if (!j.b.empty()) {
      auto b = bodyOf(j.b);
      if (!b) return b.error();
      d.b = *b;
    }
    d.anchor = j.anchor;
    d.axis = j.axis;
    d.limitEnabled = j.limited;
    d.lower = j.lower;
    d.upper = j.upper;
    if (auto id = m->world.addJoint(d); !id) return id.error().within(where);
    m->joints.push_back(j.name);
  }

  // The haptic side: touched objects that move get their poses from here
  // and give their tool impulses back.
  bool anyTouchedMoves = false;
  for (const std::string& name : touched) {
    int body = -1;
    for (std::size_t b = 0; b < m->bodies.size(); ++b)
      if (m->bodies[b].object == name && m->bodies[b].dynamic) body = static_cast<int>(b);
    m->touchedBody.push_back(body);
    const SceneObject* o = scene.object(name);
    m->touchedPoses.push_back(o != nullptr ? o->pose.isometry() : Isometry3::Identity());
    anyTouchedMoves = anyTouchedMoves || body >= 0;
  }
  if (anyTouchedMoves) {
    m->tools = std::make_unique<ToolImpulseChannel>(touched.size());
    m->model = std::make_unique<HapticLocalModel>(touched.size());
    m->impulses.resize(touched.size());
  }
  m->toolForce.assign(m->bodies.size(), Vec3::Zero());
  m->toolTorque.assign(m->bodies.size(), Vec3::Zero());
  Impl* raw = m.get();
  if (anyTouchedMoves) {
    if (auto s = addHeldForces(m->world, "haptic tool", raw->toolForce, raw->toolTorque); !s)
      return s.error();
  }
  for (auto& buffer : m->readerPoses)
    buffer = std::make_unique<TripleBuffer<std::vector<Isometry3>>>(
        std::vector<Isometry3>(m->moving.size(), Isometry3::Identity()));
  m->state = m->world.makeState();
  if (cfg.backend == ScenePhysicsEngine::Backend::Ode) {
    // Bodies and joints are all in the world now; forces added later (the
    // scripts') are evaluated from it at every step.
    OdeOptions options{.iterations = cfg.ode.iterations,
                       .erp = cfg.ode.erp,
                       .cfm = cfg.ode.cfm,
                       .maxContactsPerPair = cfg.ode.contactsPerPair,
                       .surfaceLayer = cfg.ode.surfaceLayer};
    auto ode = OdeWorld::create(m->world, options);
    if (!ode) {
      // Name the scene's object (the world names its body "bodies[i] 'name'").
      Error e = ode.error();
      e.where = "engines/physics/backend";
      for (const Impl::Body& b : m->bodies)
        if (ode.error().where.ends_with("'" + b.object + "'")) e.where = "objects/" + b.object;
      return e;
    }
    m->ode = std::move(*ode);
  }
  auto soft = SoftTissues::build(scene, resources, m->world);
  if (!soft) return soft.error();
  m->soft = std::move(*soft);
  auto membranes = SceneMembranes::build(scene, resources, m->world);
  if (!membranes) return membranes.error();
  m->membranes = std::move(*membranes);
  m->drawnDeformed = m->soft->names();
  m->drawnDeformed.insert(m->drawnDeformed.end(), m->membranes->names().begin(), m->membranes->names().end());
  for (std::uint32_t b : m->moving) {
    FluidBody link{.object = m->bodies[b].object, .objectInBody = m->bodies[b].objectInBody};
    link.pose = m->bodyPose(b);
    link.linearVelocity = m->state.linearVelocity(m->bodies[b].id);
    link.angularVelocity = m->state.angularVelocity(m->bodies[b].id);
    m->fluidBodies.push_back(link);
  }
  auto fluids = SceneFluids::build(scene, resources, *m->soft, m->fluidBodies);
  if (!fluids) return fluids.error();
  m->fluids = std::move(*fluids);
  m->fluidForce.assign(m->bodies.size(), Vec3::Zero());
  m->fluidTorque.assign(m->bodies.size(), Vec3::Zero());
  if (!m->fluids->empty() && !m->moving.empty())
    if (auto s = addHeldForces(m->world, "fluids", raw->fluidForce, raw->fluidTorque); !s) return s.error();
  return std::shared_ptr<PhysicsEngine>(new PhysicsEngine(std::move(m)));
}

bool PhysicsEngine::tick(const TickInfo& info) noexcept {
  Impl& m = *impl_;
  const double dt = info.dt();
  if (!m.scripts.empty()) {
    std::fill(m.scriptForce.begin(), m.scriptForce.end(), Vec3::Zero());
    std::fill(m.scriptTorque.begin(), m.scriptTorque.end(), Vec3::Zero());
    for (ScriptFeed* f : m.scripts) {
      if (f->inletRates.update()) {  // the rates a script set, from this step on
        const std::vector<double>& rates = f->inletRates.readBuffer();
        for (std::size_t k = 0; k < rates.size(); ++k)
          if (!std::isnan(rates[k])) m.fluids->setInletFlowRate(k, rates[k]);
      }
      f->forces.update();  // held: the last value published, until another comes
      const std::vector<ScriptForce>& held = f->forces.readBuffer();
      for (std::size_t i = 0; i < m.moving.size(); ++i) {
        m.scriptForce[m.moving[i]] += held[i].force;
        m.scriptTorque[m.moving[i]] += held[i].torque;
        const BodyId id = m.bodies[m.moving[i]].id;
        if (m.sleep && m.state.asleep(id) && held[i].force.squaredNorm() + held[i].torque.squaredNorm() > 0.0)
          (void)m.world.setBodyState(m.state, id, m.state.position(id), m.state.orientation(id),
                                     m.state.linearVelocity(id), m.state.angularVelocity(id));
      }
    }
  }
  if (m.tools) {
    // The impulse each touched body received since the last step, as a
    // constant force and torque (about its centre of mass) over this step.
    m.tools->take(m.impulses);
    std::fill(m.toolForce.begin(), m.toolForce.end(), Vec3::Zero());
    std::fill(m.toolTorque.begin(), m.toolTorque.end(), Vec3::Zero());
    for (std::size_t k = 0; k < m.touchedBody.size(); ++k) {
      const int b = m.touchedBody[k];
      if (b < 0) continue;
      const ToolImpulse& j = m.impulses[k];
      const BodyId id = m.bodies[static_cast<std::size_t>(b)].id;
      m.toolForce[static_cast<std::size_t>(b)] += j.linear / dt;
      m.toolTorque[static_cast<std::size_t>(b)] += (j.angular - m.state.position(id).cross(j.linear)) / dt;
      if (m.sleep && m.state.asleep(id) && j.linear.squaredNorm() > 0.0)
        (void)m.world.setBodyState(m.state, id, m.state.position(id), m.state.orientation(id),
                                   m.state.linearVelocity(id), m.state.angularVelocity(id));
    }
  }
  // The tissue first: it leaves the bodies it touches the velocity its
  // contact gave them, and the world's step goes on from there
  // (dm::SoftRigidCoupling).
  if (auto s = m.soft->step(dt, m.state); !s) {
    error_ = s.error().within("physics step " + std::to_string(m.steps));
    return false;
  }
  // The membranes next, the same way (dm::MembraneRigidCoupling).
  if (auto s = m.membranes->step(dt, m.state); !s) {
    error_ = s.error().within("physics step " + std::to_string(m.steps));
    return false;
  }
  if (!m.moving.empty())  // (static bodies alone never move)
    if (auto s = m.ode ? m.ode->step(m.state, dt) : m.world.step(m.state, dt); !s) {
      error_ = s.error().within("physics step " + std::to_string(m.steps));
      return false;
    }
  if (!m.fluids->empty()) {
    for (std::size_t i = 0; i < m.moving.size(); ++i) {  // where the world's step left them
      FluidBody& link = m.fluidBodies[i];
      const BodyId id = m.bodies[m.moving[i]].id;
      link.pose = m.bodyPose(m.moving[i]);
      link.linearVelocity = m.state.linearVelocity(id);
      link.angularVelocity = m.state.angularVelocity(id);
    }
    if (auto s = m.fluids->step(time_.seconds(info), dt); !s) {
      error_ = s.error().within("physics step " + std::to_string(m.steps));
      return false;
    }
    for (std::size_t i = 0; i < m.moving.size(); ++i) {  // held on the bodies over the next step
      m.fluidForce[m.moving[i]] = m.fluidBodies[i].force;
      m.fluidTorque[m.moving[i]] = m.fluidBodies[i].torque;
    }
  }
  ++m.steps;
  m.lastDt = dt;
  if (m.model) {
    for (std::size_t k = 0; k < m.touchedBody.size(); ++k)
      if (m.touchedBody[k] >= 0)
        m.touchedPoses[k] = m.objectPose(static_cast<std::uint32_t>(m.touchedBody[k]));
    m.model->publish(m.touchedPoses, info.scheduled_ns);
  }
  for (auto& buffer : m.readerPoses) {
    std::vector<Isometry3>& poses = buffer->writeBuffer();  // sized at build: no allocation
    for (std::size_t i = 0; i < m.moving.size(); ++i) poses[i] = m.objectPose(m.moving[i]);
    buffer->publish();
  }
  if (!m.scripts.empty()) {
    const double t = time_.seconds(info);  // this tick's time (a script at it sees this step)
    const auto needle = m.soft->needleProgress();
    for (ScriptFeed* f : m.scripts) {
      std::vector<ScriptBody>& out = f->bodies.writeBuffer();  // sized at build
      for (std::size_t i = 0; i < m.moving.size(); ++i) {
        const BodyId id = m.bodies[m.moving[i]].id;
        out[i] = {.pose = m.objectPose(m.moving[i]),
                  .linearVelocity = m.state.linearVelocity(id),
                  .angularVelocity = m.state.angularVelocity(id),
                  .centerOfMass = m.state.position(id)};
      }
      f->bodies.publish();
      if (needle && needle->punctures > m.punctures)
        f->push(f->physicsEvents, {.type = ScriptEvent::Type::Puncture,
                                   .time = t,
                                   .source = static_cast<int>(needle->object),
                                   .layer = needle->tipLayer,
                                   .value = double(needle->punctures)});
    }
    if (needle) m.punctures = needle->punctures;
  }
  return true;
}

Status PhysicsEngine::addScriptFeed(ScriptFeed& feed) {
  Impl& m = *impl_;
  if (m.scripts.empty()) {
    m.scriptForce.assign(m.bodies.size(), Vec3::Zero());
    m.scriptTorque.assign(m.bodies.size(), Vec3::Zero());
    Impl* raw = impl_.get();
    if (auto s = addHeldForces(m.world, "scripts", raw->scriptForce, raw->scriptTorque); !s) return s.error();
  }
  m.scripts.push_back(&feed);
  return ok();
}

TripleBuffer<FluidToolSample>* PhysicsEngine::fluidTool() noexcept {
  return impl_->fluids->empty() ? nullptr : &impl_->fluids->toolFeed();
}

bool PhysicsEngine::latestFluidParticles(std::size_t i, std::vector<Vec3>& out) {
  return impl_->fluids->latestParticles(i, out);
}

std::string PhysicsEngine::layerName(std::size_t i, int layer) const {
  return i < impl_->soft->names().size() ? impl_->soft->layerName(i, layer) : std::string();
}

const std::vector<std::string>& PhysicsEngine::softObjects() const noexcept { return impl_->drawnDeformed; }
HapticTissue* PhysicsEngine::tissue(std::string_view object) noexcept { return impl_->soft->tissue(object); }
HapticRenderer* PhysicsEngine::needleRenderer() noexcept { return impl_->soft->needle(); }
HapticRenderer* PhysicsEngine::punchRenderer() noexcept {
  return impl_->soft ? impl_->soft->punch() : nullptr;
}
bool PhysicsEngine::latestSurface(std::size_t i, Mesh& out) {
  const std::size_t soft = impl_->soft->names().size();
  return i < soft ? impl_->soft->latestSurface(i, out) : impl_->membranes->latestSurface(i - soft, out);
}

bool PhysicsEngine::latestPoses(PoseReader reader, std::vector<Isometry3>& out) {
  TripleBuffer<std::vector<Isometry3>>& buffer = *impl_->readerPoses[static_cast<std::size_t>(reader)];
  if (!buffer.update()) return false;
  out = buffer.readBuffer();
  return true;
}

nlohmann::json PhysicsEngine::summary() const {
  const Impl& m = *impl_;
  // Contact forces of the last step on each body: the solver's accumulated
  // impulses over the step length (the normal pushes body B along +n), or
  // ODE's joint feedback.
  std::vector<Vec3> contactForce(m.bodies.size(), Vec3::Zero());
  if (m.ode)
    std::copy_n(m.ode->lastContactForces().begin(), contactForce.size(), contactForce.begin());
  else
    addContactForces(m.state, m.lastDt, contactForce);
  std::vector<Vec3> softForce(m.world.bodyCount(), Vec3::Zero());  // the tissue's contact, by world body
  m.soft->addBodyForces(softForce);
  std::vector<Vec3> membraneForce(m.world.bodyCount(), Vec3::Zero());  // the membranes' contact
  m.membranes->addBodyForces(membraneForce);
  Json bodies = Json::array();
  for (std::size_t b = 0; b < m.bodies.size(); ++b) {
    const Impl::Body& body = m.bodies[b];
    if (!body.dynamic) continue;
    const Quat& q = m.state.orientation(body.id);
    Json j = {{"name", body.object},
              {"mass_kg", m.world.bodies()[body.id.index].mass},
              {"position_m", engine_json::vec3(m.state.position(body.id))},
              {"displacement_m", (m.state.position(body.id) - body.start).norm()},
              {"orientation_wxyz", Json::array({q.w(), q.x(), q.y(), q.z()})},
              {"velocity_m_s", engine_json::vec3(m.state.linearVelocity(body.id))},
              {"angular_velocity_rad_s", engine_json::vec3(m.state.angularVelocity(body.id))},
              {"asleep", m.state.asleep(body.id)},
              {"contact_force_N", engine_json::vec3(contactForce[b])},
              {"soft_force_N", engine_json::vec3(softForce[body.id.index])},
              {"membrane_force_N", engine_json::vec3(membraneForce[body.id.index])},
              {"tool_force_N", engine_json::vec3(m.toolForce[b])},
              {"fluid_force_N", engine_json::vec3(m.fluidForce[b])}};
    for (std::size_t k = 0; k < m.touchedBody.size(); ++k)
      if (m.touchedBody[k] == static_cast<int>(b) && m.tools)
        j["tool_impulse_Ns"] = engine_json::vec3(m.tools->taken(k).linear);
    bodies.push_back(std::move(j));
  }
  // Each joint's anchors on its two bodies, apart by what the solver left
  // (a slider's by its travel along the axis too, reported apart).
  Json joints = Json::array();
  for (std::size_t k = 0; k < m.joints.size(); ++k) {
    const JointGap g = jointGap(m.state, k);
    Json j = {{"name", m.joints[k]}};
    if (m.state.joints()[k].type == JointType::Slider) j["travel_m"] = g.travel;
    j["anchor_gap_m"] = g.gap;
    joints.push_back(std::move(j));
  }
  return {{"steps", m.steps},
          {"backend", m.ode ? "ode" : "builtin"},
          {"bodies", std::move(bodies)},
          {"joints", std::move(joints)},
          {"static_bodies", m.bodies.size() - m.moving.size()},
          {"contacts", m.ode ? m.ode->lastContactCount() : m.state.contacts().size()},
          {"soft", m.soft->summary()},
          {"membranes", m.membranes->summary()},
          {"fluids", m.fluids->summary()}};
}

}  // namespace dm
