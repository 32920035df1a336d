// python_script.cpp — a scene script in Python: the file runs once in a
// module namespace of its own; its start(sim), event(sim, event),
// tick(sim) and finish(sim) (any of them) are the callbacks, called with
// the GIL held on the script engine's thread. `sim` is the script's
// dm::ScriptContext as the class dmplatform_script.Context; bodies, the
// tool and events come as dicts of floats and lists (world frame, SI). A
// Python exception stops the run with its type, message and the script's
// line (python_script.hpp).
#include "python_script.hpp"

#include <dm/engine/script.hpp>
#include <dm/io/scene_file.hpp>

#include <pybind11/embed.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <fstream>
#include <map>
#include <mutex>
#include <sstream>

namespace dm::python {

namespace py = pybind11;

namespace {

// The process's interpreter: the caller's (the dmplatform package), or
// one started here for the dmplatform program — without Python's signal
// handlers (Ctrl-C stays the program's), its GIL released at once since
// every call below takes it.
void ensureInterpreter() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (Py_IsInitialized()) return;
    py::initialize_interpreter(false);
    PyEval_SaveThread();
  });
}

py::object toPython(const nlohmann::json& j) { return py::module_::import("json").attr("loads")(j.dump()); }

nlohmann::json toJson(const py::handle& value, const std::string& what) {
  try {
    return nlohmann::json::parse(py::module_::import("json").attr("dumps")(value).cast<std::string>());
  } catch (const py::error_already_set& e) {
    throw py::value_error(what + " is not JSON-serialisable (numbers, strings, lists, dicts): " + e.what());
  }
}

py::list list3(const Vec3& v) { return py::cast(std::vector<double>{v.x(), v.y(), v.z()}); }
py::list wxyz(const Isometry3& pose) {
  const Quat q(pose.rotation());
  return py::cast(std::vector<double>{q.w(), q.x(), q.y(), q.z()});
}
Vec3 vec3(const py::handle& h, const char* what) {
  std::vector<double> v;
  try {
    v = h.cast<std::vector<double>>();
  } catch (const py::cast_error&) {
    throw py::type_error(std::string(what) + " must be 3 numbers");
  }
  if (v.size() != 3)
    throw py::value_error(std::string(what) + " must be 3 numbers, got " + std::to_string(v.size()));
  return {v[0], v[1], v[2]};
}

// dm errors from the context's methods, as Python exceptions the script
// can catch (and, uncaught, come back as the run's error).
void check(const Status& s) {
  if (s) return;
  if (s.error().code == ErrorCode::NotFound) throw py::key_error(s.error().message());
  throw py::value_error(s.error().message());
}

// The Python class of ScriptContext, made once in a module of its own
// (module-local: the dmplatform package may bind its own classes in the same
// process).
void bindContext() {
  static bool bound = false;
  if (bound) return;
  bound = true;
  py::module_ types = py::module_::import("types");
  py::object m = types.attr("ModuleType")("dmplatform_script",
                                          "The context a scene script's callbacks get (docs/python.md).");
  py::module_::import("sys").attr("modules")["dmplatform_script"] = m;
  py::class_<ScriptContext>(m, "Context", py::module_local(),
                            "What a scene script sees and changes: time, args, bodies, the tool, metrics.")
      .def_property_readonly("name", &ScriptContext::name, "The script's name in the scene.")
      .def_property_readonly("time", &ScriptContext::time, "s, scene time of this tick.")
      .def_property_readonly(
          "args", [](const ScriptContext& c) { return toPython(c.args()); },
          "The scene's \"args\" for the script, as a dict.")
      .def_property_readonly("bodies", &ScriptContext::bodies,
                             "Names of the moving (dynamic) bodies, in scene order.")
      .def(
          "body",
          [](const ScriptContext& c, const std::string& name) {
            auto b = c.body(name);
            check(b ? ok() : Status(b.error()));
            py::dict d;
            d["position"] = list3(b->pose.translation());
            d["orientation_wxyz"] = wxyz(b->pose);
            d["velocity"] = list3(b->linearVelocity);
            d["angular_velocity"] = list3(b->angularVelocity);
            d["center_of_mass"] = list3(b->centerOfMass);
            return d;
          },
          py::arg("name"),
          "The body's newest state (world frame, m, m/s, rad/s): position and orientation_wxyz of its "
          "object frame, velocity, angular_velocity, center_of_mass. KeyError for a body that does not move.")
      .def(
          "set_force",
          [](ScriptContext& c, const std::string& name, const py::object& force, const py::object& torque) {
            check(c.setBodyForce(name, vec3(force, "force"),
                                 torque.is_none() ? Vec3::Zero() : vec3(torque, "torque")));
          },
          py::arg("name"), py::arg("force"), py::arg("torque") = py::none(),
          "Holds a force (N, through the centre of mass) and torque (N·m) on a moving body, world frame, "
          "from the next physics step until set again.")
      .def(
          "set_inlet_flow_rate",
          [](ScriptContext& c, const std::string& fluid, const std::string& inlet, double rate) {
            check(c.setInletFlowRate(fluid, inlet, rate));
          },
          py::arg("fluid"), py::arg("inlet"), py::arg("flow_rate"),
          "Sets a scene fluid inlet's flow rate (m³/s at zero back pressure) from the next physics step: a "
          "cut "
          "opening, irrigation on; 0 closes it.")
      .def_property_readonly(
          "tool",
          [](const ScriptContext& c) -> py::object {
            if (!c.hasTool()) return py::none();
            const ScriptTool t = c.tool();
            py::dict d;
            d["time"] = t.time;
            d["proxy_position"] = list3(t.proxy.translation());
            d["proxy_orientation_wxyz"] = wxyz(t.proxy);
            d["handle_position"] = list3(t.handle.translation());
            d["force"] = list3(t.force);
            d["contacts"] = t.contacts;
            d["penetration"] = t.penetration;
            return d;
          },
          "The haptic tool's newest tick (world frame): time, proxy_position, proxy_orientation_wxyz, "
          "handle_position, force (N, sent to the hand), contacts, penetration (m); None without haptics.")
      .def(
          "metric",
          [](ScriptContext& c, const std::string& key, const py::object& value) {
            c.setMetric(key, toJson(value, "metric \"" + key + "\""));
          },
          py::arg("key"), py::arg("value"),
          "Sets a custom metric of summary.json's scripts/NAME/metrics (JSON-serialisable).")
      .def_property_readonly(
          "metrics", [](const ScriptContext& c) { return toPython(c.metrics()); }, "The metrics set so far.");
}

// The script's line where `e` was raised (the innermost frame in its file).
std::string scriptLine(const py::error_already_set& e, const std::string& file) {
  std::string where = file;
  if (!e.trace()) return where;
  try {
    py::object frames = py::module_::import("traceback").attr("extract_tb")(e.trace());
    for (py::handle f : frames)
      if (f.attr("filename").cast<std::string>() == file)
        where = file + ":" + std::to_string(f.attr("lineno").cast<long>());
  } catch (const std::exception&) {  // (no line then)
  }
  return where;
}

Error pythonError(const py::error_already_set& e, const std::string& file, const std::string& callback) {
  std::string type = "Exception";
  try {
    type = e.type().attr("__name__").cast<std::string>();
  } catch (const std::exception&) {
  }
  std::string message;
  try {
    // A KeyError's str() is its key's repr: take a message given as one string as is.
    const py::tuple args = e.value().attr("args");
    message = args.size() == 1 && py::isinstance<py::str>(args[0]) ? args[0].cast<std::string>()
                                                                   : py::str(e.value()).cast<std::string>();
  } catch (const std::exception&) {
  }
  return fail(ErrorCode::InvalidArgument,
              type + (message.empty() ? "" : ": " + message) +
                  (callback == "loading" ? " while loading" : " in " + callback + "()"),
              scriptLine(e, file));
}

class PythonScript final : public ScriptInstance {
 public:
  PythonScript(std::string file, py::dict ns) : file_(std::move(file)), ns_(std::move(ns)) {
    for (const char* name : {"start", "event", "tick", "finish"})
      if (ns_.contains(name) && PyCallable_Check(ns_[name].ptr())) fns_[name] = ns_[name];
  }
  ~PythonScript() override {
    // Every Python reference goes with the GIL held (the members'
    // destructors run after it is released).
    py::gil_scoped_acquire gil;
    fns_.clear();
    ns_.release().dec_ref();
  }
  bool empty() const { return fns_.empty(); }

  Status start(ScriptContext& c) override { return call("start", c, {}); }
  Status tick(ScriptContext& c) override { return call("tick", c, {}); }
  Status event(ScriptContext& c, const ScriptEvent& e) override { return call("event", c, &e); }
  Status finish(ScriptContext& c) override { return call("finish", c, {}); }

 private:
  Status call(const char* name, ScriptContext& c, const ScriptEvent* e) {
    const auto it = fns_.find(name);
    if (it == fns_.end()) return ok();
    py::gil_scoped_acquire gil;
    try {
      py::object sim = py::cast(&c, py::return_value_policy::reference);
      py::object result;
      if (e != nullptr) {
        py::dict ev;
        ev["type"] = std::string(toString(e->type));
        ev["time"] = e->time;
        ev["object"] = e->object;
        ev["layer"] = e->layer;
        ev["value"] = e->value;
        result = it->second(sim, ev);
      } else {
        result = it->second(sim);
      }
      // finish() may return its metrics as a dict.
      if (std::string_view(name) == "finish" && py::isinstance<py::dict>(result))
        for (auto [k, v] : result.cast<py::dict>())
          c.setMetric(py::str(k).cast<std::string>(), toJson(v, "metric"));
      return ok();
    } catch (py::error_already_set& err) {
      return pythonError(err, file_, name);
    } catch (const std::exception& err) {  // a value the script handed back (a metric that is not JSON)
      return fail(ErrorCode::InvalidArgument, std::string(err.what()) + " in " + name + "()", file_);
    }
  }

  std::string file_;
  py::dict ns_;
  std::map<std::string, py::object> fns_;
};

Result<std::unique_ptr<ScriptInstance>> loadPythonScript(const SceneScript& s) {
  const std::string file = s.path.string();
  std::ifstream in(s.path, std::ios::binary);
  if (!in) return fail(ErrorCode::Io, "cannot read the script", file);
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return fail(ErrorCode::Io, "cannot read the script", file);
  ensureInterpreter();
  py::gil_scoped_acquire gil;
  try {
    bindContext();
    py::dict ns;
    ns["__name__"] = "dmplatform_script_" + s.name;
    ns["__file__"] = file;
    ns["__builtins__"] = py::module_::import("builtins");
    py::object builtins = py::module_::import("builtins");
    py::object code = builtins.attr("compile")(text.str(), file, "exec");
    builtins.attr("exec")(code, ns);
    auto script = std::make_unique<PythonScript>(file, ns);
    if (script->empty())
      return fail(ErrorCode::InvalidArgument, "the script defines none of start, event, tick, finish", file,
                  "define e.g. def tick(sim): ... (docs/python.md, \"Scripted scenes\")");
    return std::unique_ptr<ScriptInstance>(std::move(script));
  } catch (py::error_already_set& err) {
    Error out = pythonError(err, file, "loading");
    if (err.matches(PyExc_SyntaxError)) {
      out.code = ErrorCode::Parse;
      try {
        out.where = file + ":" + py::str(err.value().attr("lineno")).cast<std::string>();
      } catch (const std::exception&) {
      }
    }
    return out;
  }
}

}  // namespace

void registerPythonScripts() { registerScriptLanguage(".py", loadPythonScript); }

}  // namespace dm::python
