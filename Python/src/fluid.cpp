// fluid.cpp — the particle fluid for Python (dm::SphFluid, DFSPH): build
// it, add a container, blocks and sources, remove by a mask (suction), step
// it with the GIL released, and read positions, velocities, densities and
// pressures as NumPy arrays (copies: the particle arrays move as particles
// come and go).
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
}

}  // namespace dm::python
