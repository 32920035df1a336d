// fluid_sources.cpp — where a Python fluid comes from and goes
// (dm/physics/fluid_sources.hpp): inlets (a cut vessel or a pump), suction
// tips and the region of interest, each with its account; they act on a
// dmplatform.Fluid the caller passes each time.
#include <dm/physics/fluid_sources.hpp>

#include "arrays.hpp"
#include "bindings.hpp"

namespace dm::python {

void bindFluidSources(py::module_& m) {
  py::class_<FluidInlet>(m, "FluidInlet",
                         R"(A source of fluid through a disc: a pump (pressure 0, irrigation) or a cut vessel
whose rate falls linearly with the pressure on it (docs/python.md, "Fluids"). SI units.)")
      .def(py::init([](const SphFluid& fluid, const py::object& center, const py::object& normal,
                       double radius, double flowRate, double pressure) {
             return unwrap(FluidInlet::create({.center = vec3Of(center, "center"),
                                               .normal = vec3Of(normal, "normal"),
                                               .radius = radius,
                                               .flowRate = flowRate,
                                               .drivingPressure = pressure},
                                              fluid));
           }),
           py::arg("fluid"), py::arg("center"), py::arg("normal") = py::make_tuple(0.0, 0.0, 1.0),
           py::arg("radius") = 0.0, py::arg("flow_rate") = 0.0, py::arg("pressure") = 0.0,
           "For `fluid` (its spacing and particle volume): centre, outward normal, radius (m), flow rate "
           "(m³/s at zero back pressure), the vessel's pressure (Pa; 0: a pump).")
      .def("emit", &FluidInlet::emit, py::arg("fluid"), py::arg("dt"),
           "Adds what flowed over dt; returns how many particles.")
      .def_property(
          "flow_rate", [](const FluidInlet& i) { return i.options().flowRate; }, &FluidInlet::setFlowRate,
          "m³/s at zero back pressure.")
      .def("set_applied_pressure", &FluidInlet::setAppliedPressure, py::arg("pascal"),
           "A tool pressing on the source, Pa.")
      .def("back_pressure", &FluidInlet::backPressure, py::arg("fluid"),
           "The applied pressure plus the fluid's one layer above the disc, Pa.")
      .def("flow_rate_at", &FluidInlet::flowRateAt, py::arg("back_pressure"),
           "The rate at that back pressure.")
      .def_property_readonly("last_flow_rate", &FluidInlet::lastFlowRate, "m³/s of the last emit.")
      .def_property_readonly("emitted_volume", &FluidInlet::emittedVolume, "m³ in all.")
      .def_property_readonly("emitted_particles", &FluidInlet::emittedParticles)
      .def_property_readonly("outlet_area", &FluidInlet::outletArea, "m²: the disc's lattice points × d².")
      .def_property_readonly("points_per_layer", &FluidInlet::pointsPerLayer);

  py::class_<FluidSuction>(
      m, "FluidSuction",
      "A suction tip: takes up to its rate, nearest its centre first; banks nothing in air.")
      .def(py::init([](const py::object& center, double radius, double maxFlowRate) {
             return unwrap(FluidSuction::create(
                 {.center = vec3Of(center, "center"), .radius = radius, .maxFlowRate = maxFlowRate}));
           }),
           py::arg("center"), py::arg("radius"), py::arg("max_flow_rate"), "Centre, radius (m), rate (m³/s).")
      .def("apply", &FluidSuction::apply, py::arg("fluid"), py::arg("dt"),
           "Removes up to max_flow_rate·dt inside the tip; returns how many particles.")
      .def_property(
          "center",
          [](const FluidSuction& s) {
            return py::make_tuple(s.options().center.x(), s.options().center.y(), s.options().center.z());
          },
          [](FluidSuction& s, const py::object& c) { s.setCenter(vec3Of(c, "center")); },
          "The tip moves with its tool.")
      .def_property(
          "max_flow_rate", [](const FluidSuction& s) { return s.options().maxFlowRate; },
          &FluidSuction::setMaxFlowRate)
      .def_property_readonly("removed_volume", &FluidSuction::removedVolume, "m³ in all.")
      .def_property_readonly("removed_particles", &FluidSuction::removedParticles);

  py::class_<FluidRegion>(m, "FluidRegion", "The region of interest: particles leaving the box are recycled.")
      .def(py::init([](const py::object& lo, const py::object& hi) {
             return unwrap(FluidRegion::create(vec3Of(lo, "lo"), vec3Of(hi, "hi")));
           }),
           py::arg("lo"), py::arg("hi"))
      .def("apply", &FluidRegion::apply, py::arg("fluid"), "Removes the particles outside; returns how many.")
      .def_property_readonly("removed_particles", &FluidRegion::removedParticles);
}

}  // namespace dm::python
