// physics.cpp — rigid-body physics for Python: a dm::PhysicsWorld with its
// state, bodies added as spheres, boxes, closed meshes (uniform density:
// mass and inertia from the mesh) or static planes and meshes, joints (ball,
// hinge, slider, fixed, with limits) between them or to the world, stepped
// with the GIL released by the built-in solver or by ODE (dm::OdeWorld,
// made at the first step); each body's state, the contacts of the last step
// with their forces (each body's contact force on either backend), the
// joints' anchor gaps, forces and impulses applied, energy and momentum.
#include <dm/collide/shapes.hpp>
#include <dm/core/config.hpp>
#include <dm/core/mesh.hpp>
#include <dm/physics/body.hpp>
#include <dm/physics/constraint_solver.hpp>
#include <dm/physics/ode_backend.hpp>
#include <dm/physics/world.hpp>
#include <dm/physics/world_report.hpp>

#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "arrays.hpp"
#include "bindings.hpp"

namespace dm::python {

namespace {

constexpr std::array<std::pair<std::string_view, JointType>, 4> kJointTypes{{{"ball", JointType::Ball},
                                                                             {"hinge", JointType::Hinge},
                                                                             {"slider", JointType::Slider},
                                                                             {"fixed", JointType::Fixed}}};

std::string jointTypeName(JointType t) {
  for (const auto& [name, type] : kJointTypes)
    if (type == t) return std::string(name);
  return "ball";
}

// A world and its state; bodies and joints are added before the first step.
struct PyWorld {
  PhysicsWorld world;
  std::optional<WorldState> state;  // made on the first step (or query)
  bool useOde = false;
  OdeOptions odeOptions;
  std::optional<OdeWorld> ode;          // the "ode" backend, built with the state
  std::vector<std::string> jointNames;  // addJoint order
  double lastDt = 0.0;

  WorldState& current() {
    if (!state) {
      if (useOde) ode = unwrap(OdeWorld::create(world, odeOptions));
      state = world.makeState();
    }
    return *state;
  }
  BodyId id(const std::string& name) const { return unwrap(world.findBody(name)); }
  std::string nameOf(int body) const {
    return body == kWorldBody ? std::string() : world.bodies()[std::size_t(body)].name;
  }
  void beforeFirstStep(const std::string& what, const char* hint) const {
    if (state) raise(fail(ErrorCode::InvalidArgument, "the world has stepped", what, hint));
  }
  // Adds `d` with its contact material; refused once the world stepped.
  BodyId add(BodyDesc d, double friction, double restitution) {
    beforeFirstStep("add body \"" + d.name + "\"", "add every body before the first step");
    if (d.name.empty()) raise(fail(ErrorCode::InvalidArgument, "a body needs a name", "name"));
    if (world.findBody(d.name))
      raise(fail(ErrorCode::InvalidArgument, "a body \"" + d.name + "\" exists", "name", "names are unique"));
    const BodyId id = unwrap(world.addBody(d));
    unwrap(world.setMaterial(id, {.friction = friction, .restitution = restitution}));
    return id;
  }
};

BodyDesc bodyOf(const std::string& name, bool isStatic, double mass, const py::object& position,
                const py::object& velocity) {
  BodyDesc d;
  d.name = name;
  d.kind = isStatic ? BodyKind::Static : BodyKind::Rigid;
  d.mass = mass;
  d.position = vec3Of(position, "position");
  if (!velocity.is_none()) d.linearVelocity = vec3Of(velocity, "velocity");
  return d;
}

py::dict stateDict(const PyWorld& w, BodyId id) {
  const WorldState& s = *w.state;
  const Quat& q = s.orientation(id);
  py::dict d;
  d["position"] = arrayOf(s.position(id));
  d["orientation_wxyz"] = py::make_tuple(q.w(), q.x(), q.y(), q.z());
  d["velocity"] = arrayOf(s.linearVelocity(id));
  d["angular_velocity"] = arrayOf(s.angularVelocity(id));
  d["asleep"] = s.asleep(id);
  return d;
}

}  // namespace

void bindPhysics(py::module_& m) {
  py::class_<PyWorld, std::shared_ptr<PyWorld>>(
      m, "PhysicsWorld",
      R"(Rigid bodies with contact and friction (dm::PhysicsWorld): add bodies, then step. SI units,
world frame; a body's position is its centre of mass.)")
      .def(py::init([](const py::object& gravity, const std::string& backend, int odeIterations) {
             auto w = std::make_shared<PyWorld>();
             unwrap(w->world.setGravity(vec3Of(gravity, "gravity")));
             if (backend != "builtin" && backend != "ode") {
               const std::string near = closestMatch(backend, {"builtin", "ode"});
               raise(fail(ErrorCode::InvalidArgument, "no backend \"" + backend + "\"", "backend",
                          near.empty() ? "use \"builtin\" or \"ode\"" : "did you mean \"" + near + "\"?"));
             }
             if (odeIterations < 1)
               raise(fail(ErrorCode::InvalidArgument, "ode_iterations is " + std::to_string(odeIterations),
                          "ode_iterations", "give at least 1 (20 is ODE's usual)"));
             if (backend != "ode" && odeIterations != 20)
               raise(fail(ErrorCode::InvalidArgument, "ode_iterations with the built-in solver",
                          "ode_iterations", "pass backend=\"ode\" or leave ode_iterations out"));
             w->useOde = backend == "ode";
             w->odeOptions.iterations = odeIterations;
             w->odeOptions.surfaceLayer = 0.0;  // ODE's own default, as in scenes
             return w;
           }),
           py::arg("gravity") = py::make_tuple(0.0, 0.0, -9.81), py::arg("backend") = "builtin",
           py::arg("ode_iterations") = 20,
           "backend: \"builtin\" (the contact solver of DMPhysics) or \"ode\" (ODE's dWorldQuickStep with "
           "ode_iterations sweeps, built at the first step).")
      .def(
          "add_sphere",
          [](PyWorld& w, const std::string& name, double radius, double mass, const py::object& position,
             const py::object& velocity, bool isStatic, double friction, double restitution) {
            if (!(radius > 0.0)) raise(fail(ErrorCode::InvalidArgument, "radius must be > 0", "radius"));
            BodyDesc d = bodyOf(name, isStatic, mass, position, velocity);
            d.inertia = sphereInertia(mass, radius);
            d.shape = std::make_shared<Sphere>(radius);
            w.add(std::move(d), friction, restitution);
          },
          py::arg("name"), py::arg("radius"), py::arg("mass") = 1.0,
          py::arg("position") = py::make_tuple(0, 0, 0), py::arg("velocity") = py::none(),
          py::arg("static") = false, py::arg("friction") = 0.5, py::arg("restitution") = 0.0,
          "A solid sphere (m, kg).")
      .def(
          "add_box",
          [](PyWorld& w, const std::string& name, const py::object& halfExtents, double mass,
             const py::object& position, const py::object& velocity, bool isStatic, double friction,
             double restitution) {
            const Vec3 h = vec3Of(halfExtents, "half_extents");
            if (!(h.minCoeff() > 0.0))
              raise(fail(ErrorCode::InvalidArgument, "half extents must be > 0", "half_extents"));
            BodyDesc d = bodyOf(name, isStatic, mass, position, velocity);
            d.inertia = boxInertia(mass, h);
            d.shape = std::make_shared<Box>(h);
            w.add(std::move(d), friction, restitution);
          },
          py::arg("name"), py::arg("half_extents"), py::arg("mass") = 1.0,
          py::arg("position") = py::make_tuple(0, 0, 0), py::arg("velocity") = py::none(),
          py::arg("static") = false, py::arg("friction") = 0.5, py::arg("restitution") = 0.0,
          "A solid box, axis-aligned at the start (m, kg).")
      .def(
          "add_mesh",
          [](PyWorld& w, const std::string& name, const Mesh& mesh, double density, bool isStatic,
             double friction, double restitution) {
            BodyDesc d;
            if (isStatic) {
              d.name = name;
              d.kind = BodyKind::Static;
              d.shape = unwrap(TriangleMesh::create(std::make_shared<const Mesh>(mesh)));
            } else {
              d = unwrap(released([&] { return rigidBodyFromMesh(mesh, density); }));
              d.name = name;
              d.kind = BodyKind::Rigid;
              d.shape = unwrap(ConvexHull::create(mesh.positions));
            }
            w.add(std::move(d), friction, restitution);
          },
          py::arg("name"), py::arg("mesh"), py::arg("density") = 1000.0, py::arg("static") = false,
          py::arg("friction") = 0.5, py::arg("restitution") = 0.0,
          "A body of a mesh where it lies: dynamic, a closed mesh of uniform density (kg/m³) colliding as "
          "its "
          "convex hull; static, its triangles.")
      .def(
          "add_plane",
          [](PyWorld& w, const std::string& name, const py::object& normal, double offset, double friction,
             double restitution) {
            const Vec3 n = vec3Of(normal, "normal");
            if (!(n.norm() > 0.0)) raise(fail(ErrorCode::InvalidArgument, "a zero normal", "normal"));
            BodyDesc d;
            d.name = name;
            d.kind = BodyKind::Static;
            d.shape = std::make_shared<Plane>(n.normalized(), offset);
            w.add(std::move(d), friction, restitution);
          },
          py::arg("name"), py::arg("normal") = py::make_tuple(0, 0, 1), py::arg("offset") = 0.0,
          py::arg("friction") = 0.5, py::arg("restitution") = 0.0,
          "The static half-space n·x <= offset (the ground by default).")
      .def(
          "step",
          [](PyWorld& w, double dt, int steps) {
            if (steps < 1) raise(fail(ErrorCode::InvalidArgument, "steps must be >= 1", "steps"));
            WorldState& s = w.current();
            unwrap(released([&]() -> Status {
              for (int i = 0; i < steps; ++i)
                if (auto st = w.ode ? w.ode->step(s, dt) : w.world.step(s, dt); !st) return st;
              return ok();
            }));
            w.lastDt = dt;
          },
          py::arg("dt"), py::arg("steps") = 1, "Advances `steps` steps of dt seconds (GIL released).")
      .def(
          "add_joint",
          [](PyWorld& w, const std::string& name, const std::string& type, const std::string& a,
             const py::object& b, const py::object& anchor, const py::object& axis,
             const py::object& limits) {
            w.beforeFirstStep("add joint \"" + name + "\"", "add every joint before the first step");
            if (name.empty()) raise(fail(ErrorCode::InvalidArgument, "a joint needs a name", "name"));
            for (const std::string& n : w.jointNames)
              if (n == name)
                raise(fail(ErrorCode::InvalidArgument, "a joint \"" + name + "\" exists", "name",
                           "names are unique"));
            JointDesc d;
            bool typed = false;
            for (const auto& [n, t] : kJointTypes)
              if (n == type) {
                d.type = t;
                typed = true;
              }
            if (!typed) {
              const std::string near = closestMatch(type, {"ball", "hinge", "slider", "fixed"});
              raise(
                  fail(ErrorCode::InvalidArgument, "no joint type \"" + type + "\"", "type",
                       near.empty() ? "use ball, hinge, slider or fixed" : "did you mean \"" + near + "\"?"));
            }
            const bool axial = d.type == JointType::Hinge || d.type == JointType::Slider;
            d.a = w.id(a);
            if (!b.is_none()) d.b = w.id(b.cast<std::string>());
            d.anchor = vec3Of(anchor, "anchor");
            if (axial && axis.is_none())
              raise(fail(ErrorCode::InvalidArgument, "a " + type + " joint needs an axis", "axis",
                         "the world direction it turns about or slides along"));
            if (!axial && !axis.is_none())
              raise(fail(ErrorCode::InvalidArgument, "a " + type + " joint has no axis", "axis",
                         "leave it out"));
            if (!axis.is_none()) d.axis = vec3Of(axis, "axis");
            if (!limits.is_none()) {
              if (!axial)
                raise(fail(ErrorCode::InvalidArgument, "a " + type + " joint has no limits", "limits",
                           "limits bound a hinge's angle or a slider's travel"));
              const auto l = limits.cast<std::pair<double, double>>();
              d.limitEnabled = true;
              d.lower = l.first;
              d.upper = l.second;
            }
            unwrap(w.world.addJoint(d));
            w.jointNames.push_back(name);
          },
          py::arg("name"), py::arg("type"), py::arg("a"), py::arg("b") = py::none(),
          py::arg("anchor") = py::make_tuple(0, 0, 0), py::arg("axis") = py::none(),
          py::arg("limits") = py::none(),
          "A joint (dm::JointDesc) of body a to body b (None: the world) from their poses now: type ball, "
          "hinge, slider or fixed; anchor (m, world); axis (world) for hinge and slider; limits (lower, "
          "upper) "
          "about the start: rad for a hinge, m for a slider.")
      .def(
          "joints",
          [](PyWorld& w) {
            const WorldState& s = w.current();
            py::list out;
            for (std::size_t k = 0; k < w.jointNames.size(); ++k) {
              const Joint& j = s.joints()[k];
              const JointGap g = jointGap(s, k);
              py::dict d;
              d["name"] = w.jointNames[k];
              d["type"] = jointTypeName(j.type);
              d["a"] =
                  j.bodyA == kWorldBody ? py::object(py::none()) : py::object(py::str(w.nameOf(j.bodyA)));
              d["b"] =
                  j.bodyB == kWorldBody ? py::object(py::none()) : py::object(py::str(w.nameOf(j.bodyB)));
              d["anchor_gap"] = g.gap;
              if (j.type == JointType::Slider) d["travel"] = g.travel;
              out.append(d);
            }
            return out;
          },
          "Each joint: name, type, a, b (None: the world), anchor_gap (m: how far its anchors on the two "
          "bodies "
          "are apart, what the solver left) and a slider's travel (m) along its axis.")
      .def_property_readonly("backend", [](const PyWorld& w) { return w.useOde ? "ode" : "builtin"; })
      .def_property_readonly("time", [](PyWorld& w) { return w.current().time(); })
      .def_property_readonly("bodies",
                             [](const PyWorld& w) {
                               std::vector<std::string> names;
                               for (const BodyDesc& d : w.world.bodies()) names.push_back(d.name);
                               return names;
                             })
      .def(
          "state",
          [](PyWorld& w, const std::string& name) {
            const BodyId id = w.id(name);
            w.current();
            return stateDict(w, id);
          },
          py::arg("name"), "position, orientation_wxyz, velocity, angular_velocity, asleep.")
      .def(
          "set_state",
          [](PyWorld& w, const std::string& name, const py::object& position, const py::object& velocity,
             const py::object& angularVelocity) {
            const BodyId id = w.id(name);
            WorldState& s = w.current();
            unwrap(w.world.setBodyState(
                s, id, position.is_none() ? s.position(id) : vec3Of(position, "position"), s.orientation(id),
                velocity.is_none() ? s.linearVelocity(id) : vec3Of(velocity, "velocity"),
                angularVelocity.is_none() ? s.angularVelocity(id)
                                          : vec3Of(angularVelocity, "angular_velocity")));
          },
          py::arg("name"), py::arg("position") = py::none(), py::arg("velocity") = py::none(),
          py::arg("angular_velocity") = py::none(), "Sets what is given; the rest stays.")
      .def(
          "apply_impulse",
          [](PyWorld& w, const std::string& name, const py::object& impulse, const py::object& point) {
            const BodyId id = w.id(name);
            WorldState& s = w.current();
            unwrap(w.world.applyImpulse(s, id, vec3Of(impulse, "impulse"),
                                        point.is_none() ? s.position(id) : vec3Of(point, "point")));
          },
          py::arg("name"), py::arg("impulse"), py::arg("point") = py::none(),
          "An instantaneous impulse (N·s) at a world point (default: the centre of mass).")
      .def(
          "add_force",
          [](PyWorld& w, const std::string& name, const py::object& force) {
            if (w.state)
              raise(fail(ErrorCode::InvalidArgument, "the world has stepped", "add_force",
                         "add forces before the first step"));
            const BodyId id = w.id(name);
            unwrap(w.world.addForce({.body = id, .force = vec3Of(force, "force"), .point = Vec3::Zero()}));
          },
          py::arg("name"), py::arg("force"), "A constant force (N, world) through the centre of mass.")
      .def(
          "contact_forces",
          [](PyWorld& w) {
            const WorldState& s = w.current();
            std::vector<Vec3> force(w.world.bodyCount(), Vec3::Zero());
            if (w.ode) {
              const auto f = w.ode->lastContactForces();
              std::copy(f.begin(), f.end(), force.begin());
            } else {
              addContactForces(s, w.lastDt, force);
            }
            py::dict out;
            const auto bodies = w.world.bodies();
            for (std::size_t i = 0; i < bodies.size(); ++i)
              if (bodies[i].kind != BodyKind::Static) out[py::str(bodies[i].name)] = arrayOf(force[i]);
            return out;
          },
          "Each moving body's contact force over the last step (N, world), on either backend.")
      .def(
          "contacts",
          [](PyWorld& w) {
            const WorldState& s = w.current();
            if (w.ode)
              raise(fail(ErrorCode::Unsupported, "the ODE backend reports no contact points", "contacts",
                         "contact_forces() gives each body's contact force on either backend"));
            const auto names = w.world.bodies();
            py::list out;
            for (const ContactConstraint& c : s.contacts()) {
              py::dict d;
              d["a"] = c.bodyA >= 0 ? py::object(py::str(names[std::size_t(c.bodyA)].name)) : py::none();
              d["b"] = c.bodyB >= 0 ? py::object(py::str(names[std::size_t(c.bodyB)].name)) : py::none();
              d["point"] = arrayOf(c.point.position);
              d["normal"] = arrayOf(c.point.normal);
              d["depth"] = c.point.depth;
              // The force on B over the last step (the normal pushes B along +normal).
              d["force_on_b"] = arrayOf(
                  w.lastDt > 0.0 ? Vec3((c.normalImpulse * c.point.normal + c.frictionImpulse) / w.lastDt)
                                 : Vec3::Zero());
              out.append(d);
            }
            return out;
          },
          "The contacts the last step solved: bodies a and b (None: the world), point, normal (a to b), "
          "depth (m) and the force on b over the step (N).")
      .def_property_readonly("kinetic_energy", [](PyWorld& w) { return w.world.kineticEnergy(w.current()); })
      .def_property_readonly("linear_momentum",
                             [](PyWorld& w) { return arrayOf(w.world.linearMomentum(w.current())); });
}

}  // namespace dm::python
