// fluid.cpp — the particle fluid for Python (dm::SphFluid, DFSPH): build
// it, add a container, blocks and sources, remove by a mask (suction), step
// it with the GIL released, and read positions, velocities, densities and
// pressures as NumPy arrays (copies: the particle arrays move as particles
// come and go); rigid bodies in it (two-way: Python integrates the body,
// the fluid gives back its force and torque) and sample_boundary() for
// their surfaces.
#include <dm/physics/sph_boundary.hpp>
#include <dm/physics/sph_fluid.hpp>

#include <pybind11/numpy.h>

#include <span>
#include <vector>

#include "arrays.hpp"
#include "bindings.hpp"

namespace dm::python {

namespace {

py::array_t<double> rowsOfVec3(std::span<const Vec3> v) {
  py::array_t<double> out({py::ssize_t(v.size()), py::ssize_t(3)});
  for (std::size_t i = 0; i < v.size(); ++i)
    for (int c = 0; c < 3; ++c) out.mutable_at(py::ssize_t(i), c) = v[i][c];
  return out;
}

py::array_t<double> valuesOf(std::span<const double> v) {
  py::array_t<double> out(py::ssize_t(v.size()));
  std::copy(v.begin(), v.end(), out.mutable_data());
  return out;
}

// InvalidArgument naming the body when the fluid has no such rigid body.
void checkBody(const SphFluid& f, std::size_t body) {
  if (body >= f.rigidBodyCount())
    raise(fail(ErrorCode::InvalidArgument,
               "body " + std::to_string(body) + " of " + std::to_string(f.rigidBodyCount()), "body"));
}

void checkSurface(const SphFluid& f, std::size_t surface) {
  if (surface >= f.surfaceCount())
    raise(fail(ErrorCode::InvalidArgument,
               "surface " + std::to_string(surface) + " of " + std::to_string(f.surfaceCount()), "surface"));
}

}  // namespace

void bindFluid(py::module_& m) {
  py::class_<SphFluid>(m, "Fluid",
                       R"(A particle fluid (blood, saline): DFSPH, density error held under max_density_error
(docs/python.md, "Fluids"; dm/physics/sph_fluid.hpp). SI units.)")
      .def(py::init([](double spacing, double restDensity, double viscosity, double surfaceTension,
                       const py::object& gravity, double maxDensityError) {
             return unwrap(SphFluid::create({.particleSpacing = spacing,
                                             .restDensity = restDensity,
                                             .viscosity = viscosity,
                                             .surfaceTension = surfaceTension,
                                             .gravity = vec3Of(gravity, "gravity"),
                                             .maxDensityError = maxDensityError}));
           }),
           py::arg("spacing") = 0.005, py::arg("rest_density") = 1000.0, py::arg("viscosity") = 1e-6,
           py::arg("surface_tension") = 0.0, py::arg("gravity") = py::make_tuple(0.0, 0.0, -9.81),
           py::arg("max_density_error") = 1e-3,
           "spacing (m), rest density (kg/m³), kinematic viscosity (m²/s), Akinci's surface tension γ.")
      .def(
          "add_box_boundary",
          [](SphFluid& f, const py::object& lo, const py::object& hi) {
            return f.addBoxBoundary(vec3Of(lo, "lo"), vec3Of(hi, "hi"));
          },
          py::arg("lo"), py::arg("hi"), "A container without a lid whose inside is the box [lo, hi].")
      .def(
          "add_block",
          [](SphFluid& f, const py::object& lo, const py::object& hi, const py::object& velocity) {
            return f.addBlock(vec3Of(lo, "lo"), vec3Of(hi, "hi"),
                              velocity.is_none() ? Vec3::Zero() : vec3Of(velocity, "velocity"));
          },
          py::arg("lo"), py::arg("hi"), py::arg("velocity") = py::none(),
          "Fills the box with fluid on the lattice; returns how many particles.")
      .def(
          "add_particles",
          [](SphFluid& f, const py::object& points, const py::object& velocity) {
            const std::vector<Vec3> p = pointsOf(points, "positions");
            f.addParticles(p, velocity.is_none() ? Vec3::Zero() : vec3Of(velocity, "velocity"));
          },
          py::arg("positions"), py::arg("velocity") = py::none(), "A source: (n, 3) particles.")
      .def(
          "add_boundary_particles",
          [](SphFluid& f, const py::object& points) {
            const std::vector<Vec3> p = pointsOf(points, "positions");
            f.addBoundaryParticles(p);
          },
          py::arg("positions"), "Static boundary samples (a surface at about the spacing).")
      .def(
          "remove",
          [](SphFluid& f, const py::object& maskIn) {
            const auto mask = py::array_t<bool, py::array::c_style | py::array::forcecast>::ensure(maskIn);
            if (!mask || mask.ndim() != 1 || std::size_t(mask.shape(0)) != f.size())
              raise(fail(ErrorCode::InvalidArgument, "expected a boolean mask of one entry per particle",
                         "mask", "e.g. np.linalg.norm(fluid.positions - tip, axis=1) < 0.01"));
            std::size_t i = 0;
            const bool* m = mask.data();
            return f.removeIf([&](const Vec3&) { return m[i++]; });
          },
          py::arg("mask"), "Removes the particles where mask is True (suction); returns how many.")
      .def(
          "step", [](SphFluid& f, double dt) { unwrap(released([&] { return f.step(dt); })); }, py::arg("dt"),
          "Advances dt seconds in CFL sub-steps (GIL released).")
      .def_property_readonly("positions", [](const SphFluid& f) { return rowsOfVec3(f.positions()); })
      .def_property_readonly("velocities", [](const SphFluid& f) { return rowsOfVec3(f.velocities()); })
      .def_property_readonly("densities", [](const SphFluid& f) { return valuesOf(f.densities()); })
      .def_property_readonly(
          "pressures", [](const SphFluid& f) { return valuesOf(f.pressures()); }, "Pa, of the last sub-step.")
      .def_property_readonly("boundary_positions",
                             [](const SphFluid& f) { return rowsOfVec3(f.boundaryPositions()); })
      .def(
          "add_rigid_body",
          [](SphFluid& f, const py::object& points, const py::object& pose) {
            const std::vector<Vec3> p = pointsOf(points, "points");
            return unwrap(f.addRigidBoundary(p, poseOf(pose, "pose")));
          },
          py::arg("points"), py::arg("pose") = py::none(),
          "A rigid body the fluid pushes: its surface samples (n, 3) in its own frame, e.g.\n"
          "sample_boundary(mesh, spacing, spacing / 3); pose: 4x4. Returns the body's index.")
      .def(
          "set_rigid_state",
          [](SphFluid& f, std::size_t body, const py::object& pose, const py::object& linear,
             const py::object& angular) {
            unwrap(f.setRigidState(body, poseOf(pose, "pose"), vec3Of(linear, "linear_velocity"),
                                   vec3Of(angular, "angular_velocity")));
          },
          py::arg("body"), py::arg("pose"), py::arg("linear_velocity") = py::make_tuple(0.0, 0.0, 0.0),
          py::arg("angular_velocity") = py::make_tuple(0.0, 0.0, 0.0),
          "The body's pose (4x4) and its frame origin's velocities (m/s, rad/s); within the next step it\n"
          "moves on at them.")
      .def(
          "rigid_load",
          [](const SphFluid& f, std::size_t body) {
            checkBody(f, body);
            const SphRigidLoad l = f.rigidLoad(body);
            return py::make_tuple(arrayOf(l.force), arrayOf(l.torque));
          },
          py::arg("body"),
          "(force N, torque N·m about the body frame's origin) the fluid exerted over the last step.")
      .def(
          "rigid_pose",
          [](const SphFluid& f, std::size_t body) {
            checkBody(f, body);
            return arrayOf(Mat4(f.rigidPose(body).matrix()));
          },
          py::arg("body"), "Where the last step left the body (4x4).")
      .def(
          "add_surface",
          [](SphFluid& f, const Mesh& mesh, double inset, const py::object& spacing) {
            auto samples = unwrap(BoundarySurface::create(
                mesh, spacing.is_none() ? f.options().particleSpacing : spacing.cast<double>(), inset));
            return unwrap(f.addSurfaceBoundary(std::move(samples), mesh.positions));
          },
          py::arg("mesh"), py::arg("inset"), py::arg("spacing") = py::none(),
          "A deforming surface (tissue) the fluid flows around: the mesh's surface sampled at `spacing`\n"
          "(default the fluid's; a surface that stretches by s needs spacing / s), `inset` inwards\n"
          "(the fluid's spacing / 3 puts its edge on it), placed on the mesh's vertices as they are.\n"
          "Returns the surface's index.")
      .def(
          "set_surface_state",
          [](SphFluid& f, std::size_t surface, const py::object& vertices, const py::object& velocities) {
            checkSurface(f, surface);
            const std::vector<Vec3> x = pointsOf(vertices, "vertices");
            const std::vector<Vec3> v = velocities.is_none() ? std::vector<Vec3>(x.size(), Vec3::Zero())
                                                             : pointsOf(velocities, "velocities");
            unwrap(f.setSurfaceState(surface, x, v));
          },
          py::arg("surface"), py::arg("vertices"), py::arg("velocities") = py::none(),
          "The surface's vertices (n, 3) where they are now and their velocities (n, 3; none: at rest);\n"
          "within the next step its samples move on at them.")
      .def(
          "surface_loads",
          [](const SphFluid& f, std::size_t surface) {
            checkSurface(f, surface);
            return rowsOfVec3(f.surfaceLoads(surface));
          },
          py::arg("surface"),
          "Per vertex, the force (N) the fluid exerted on the surface over the last step: (n, 3).")
      .def_property_readonly(
          "moving_boundary_positions",
          [](const SphFluid& f) { return rowsOfVec3(f.movingBoundaryPositions()); },
          "Every rigid body's and surface's boundary particles in the world, in the order they were added.")
      .def_property_readonly("time", &SphFluid::time)
      .def_property_readonly("mass", &SphFluid::mass, "kg of fluid.")
      .def_property_readonly("particle_mass", &SphFluid::particleMass)
      .def("__len__", &SphFluid::size)
      .def_property_readonly(
          "last_step",
          [](const SphFluid& f) {
            const SphStepStats& s = f.lastStep();
            py::dict d;
            d["sub_steps"] = s.subSteps;
            d["density_iterations"] = s.densityIterations;
            d["divergence_iterations"] = s.divergenceIterations;
            d["density_error"] = s.densityError;
            d["divergence_error"] = s.divergenceError;
            d["max_density_error"] = s.maxDensityError;
            d["converged"] = s.converged;
            return d;
          },
          "What the last step did: sub-steps, iterations, errors.");
  m.def(
      "sample_boundary",
      [](const Mesh& mesh, double spacing, double inset) {
        return rowsOfVec3(unwrap(sampleBoundary(mesh, spacing, inset)));
      },
      py::arg("mesh"), py::arg("spacing"), py::arg("inset"),
      "Boundary particles on a mesh's surface about `spacing` apart, moved `inset` inwards (spacing / 3\n"
      "puts the fluid's edge on the surface): (n, 3).");
}

}  // namespace dm::python
