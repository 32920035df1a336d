// module.cpp — the dmplatform._core extension module: its errors, then the
// data model (data.cpp) and scenes (scene.cpp).
#include <pybind11/eval.h>

#include "bindings.hpp"
#include "python_script.hpp"

namespace dm::python {

[[noreturn]] void raise(const Error& e) {
  const py::object cls = py::module_::import("dmplatform._core").attr("Error");
  const py::object exc = cls(e.message(), toString(e.code), e.where, e.hint, e.what);
  PyErr_SetObject(cls.ptr(), exc.ptr());
  throw py::error_already_set();
}

void bindErrors(py::module_& m) {
  // A Python class (its attributes are plain Python ones), defined in the
  // module's namespace.
  py::exec(R"py(
class Error(RuntimeError):
    """A DMPlatform failure: str(e) is the one-line message "where: what
    (hint)"; e.code names the kind ("invalid argument", "not found", "I/O
    error", "parse error", "unsupported", ...), e.where the file, JSON path,
    byte or field, e.hint what to do, e.what what failed."""

    def __init__(self, message, code="internal error", where="", hint="", what=""):
        super().__init__(message)
        self.code = code
        self.where = where
        self.hint = hint
        self.what = what if what else message

Error.__module__ = "dmplatform"
)py",
           m.attr("__dict__"));
}

}  // namespace dm::python

PYBIND11_MODULE(_core, m) {
  m.doc() = "DMPlatform's C++ core: the data model as NumPy arrays, I/O, isosurfaces and scene runs";
  dm::python::bindErrors(m);
  dm::python::bindData(m);
  dm::python::bindScene(m);
  dm::python::bindCollide(m);
  dm::python::bindHaptics(m);
  dm::python::bindPhysics(m);
  dm::python::bindFluid(m);
  dm::python::bindFluidSources(m);
  dm::python::bindGeometry(m);
  dm::python::registerPythonScripts();  // scenes run from Python run their .py scripts here
}
