// bindings.hpp (private) — shared by the dmplatform module's sources: a
// failed dm::Result becomes a dmplatform.Error (message, code, where, hint),
// and each source registers its part of the module.
#pragma once

#include <dm/core/result.hpp>

#include <pybind11/pybind11.h>

#include <type_traits>
#include <utility>

namespace dm::python {

namespace py = pybind11;

/// Raises dmplatform.Error for `e` (never returns).
[[noreturn]] void raise(const Error& e);

/// The value of `r`, or dmplatform.Error.
template <class T>
requires(!std::is_void_v<T>) T unwrap(Result<T>&& r) {
  if (!r) raise(r.error());
  return std::move(*r);
}
inline void unwrap(const Status& s) {
  if (!s) raise(s.error());
}

/// fn() with the GIL released (file I/O, geometry, runs: other Python
/// threads go on); its Result is unwrapped once the GIL is held again.
template <class Fn>
auto released(Fn&& fn) {
  py::gil_scoped_release release;
  return fn();
}

void bindErrors(py::module_& m);
void bindData(py::module_& m);      // Volume, Mesh, readers and writers, isosurfaces
void bindScene(py::module_& m);     // scenes: load, edit as dicts, run
void bindCollide(py::module_& m);   // MeshTree: closest points, rays, distances, contacts
void bindHaptics(py::module_& m);   // renderers ticked from Python, device paths replayed (probe)
void bindPhysics(py::module_& m);   // PhysicsWorld: bodies, steps, states, contacts
void bindFluid(py::module_& m);     // Fluid: DFSPH particles, sources, suction
void bindFluidSources(py::module_& m);  // FluidInlet, FluidSuction, FluidRegion
void bindGeometry(py::module_& m);  // voxelize, simplify, Hausdorff; Image and PNG

}  // namespace dm::python
