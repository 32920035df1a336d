// scene.cpp — scene files for Python: load one (or build it from a dict),
// read and edit it as a dict in the file's own JSON form, and run it with
// dm::SceneRuntime in lockstep or real time with the GIL released, or step
// by step (Simulation: advance, state, finish); the run's summary comes back
// as a dict, its files in the output folder.
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>

#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bindings.hpp"

namespace dm::python {

namespace {

// A failed parse: every problem in the message, the first one's place.
[[noreturn]] void raiseScene(const Error& e, const std::vector<Error>& problems) {
  if (problems.empty()) raise(e);
  Error first = problems.front();
  first.what = formatSceneErrors(problems);
  first.hint.clear();
  raise(first);
}

py::object jsonToPython(const nlohmann::json& j) {
  return py::module_::import("json").attr("loads")(j.dump());
}

struct RunResult {
  py::object summary;
  bool interrupted = false;
  double simulatedSeconds = 0;
  std::uint64_t frames = 0;
  std::filesystem::path outDir;
};

}  // namespace

void bindScene(py::module_& m) {
  py::class_<SceneDesc>(m, "Scene", R"(A scene file ("dmplatform-scene", docs/scene-format.md), parsed and
validated: resources, materials, objects, devices, engines, outputs.)")
      .def_static(
          "load",
          [](const std::filesystem::path& file) {
            std::vector<Error> problems;
            auto s = readScene(file, &problems);
            if (!s) raiseScene(s.error(), problems);
            return *s;
          },
          py::arg("path"), "Reads and validates a scene file; dmplatform.Error names every problem.")
      .def_static(
          "from_dict",
          [](const py::dict& d, const std::filesystem::path& baseDir, const std::string& name) {
            const std::string text = py::module_::import("json").attr("dumps")(d).cast<std::string>();
            std::vector<Error> problems;
            auto s = parseScene(text, name, baseDir, &problems);
            if (!s) raiseScene(s.error(), problems);
            return *s;
          },
          py::arg("scene"), py::arg("base_dir") = std::filesystem::path("."), py::arg("name") = "<dict>",
          "A scene from a dict in the file's form; relative sources resolve against `base_dir`.")
      .def(
          "to_dict", [](const SceneDesc& s) { return jsonToPython(toJson(s)); },
          "The scene as a dict in the file's canonical form (every key, defaults written out): edit it and "
          "build a new scene with Scene.from_dict(d, scene.base_dir).")
      .def_property_readonly("name", [](const SceneDesc& s) { return s.name; })
      .def_property_readonly(
          "base_dir", [](const SceneDesc& s) { return s.baseDir; },
          "Where the scene's relative sources resolve.")
      .def("__eq__", [](const SceneDesc& a, const SceneDesc& b) { return a == b; })
      .def("__repr__", [](const SceneDesc& s) {
        return "<dmplatform.Scene '" + s.name + "', " + std::to_string(s.objects.size()) + " objects>";
      });

  py::class_<RunResult>(m, "RunResult", "What a scene run did; its files are in out_dir.")
      .def_readonly("summary", &RunResult::summary, "summary.json as a dict.")
      .def_readonly("interrupted", &RunResult::interrupted)
      .def_readonly("simulated_seconds", &RunResult::simulatedSeconds)
      .def_readonly("frames", &RunResult::frames, "Frames written.")
      .def_readonly("out_dir", &RunResult::outDir);

  // A run stepped from Python: the runtime lives in the Simulation.
  struct Simulation {
    std::unique_ptr<SceneRuntime> runtime;
    std::filesystem::path outDir;
  };
  py::class_<Simulation>(m, "Simulation", R"(A scene run step by step in lockstep: advance(seconds), read state(),
finish() for the outputs. docs/python.md, "Scenes".)")
      .def(py::init([](const SceneDesc& scene, const std::filesystem::path& outDir, double durationHint) {
             auto sim = std::make_unique<Simulation>();
             std::optional<Error> error;
             {
               py::gil_scoped_release release;
               auto rt = SceneRuntime::create(scene);
               if (!rt) {
                 error = rt.error();
               } else {
                 sim->runtime = std::move(*rt);
                 if (auto st = sim->runtime->start(
                         {.mode = RunMode::Lockstep, .duration = durationHint, .outDir = outDir});
                     !st)
                   error = st.error();
               }
             }
             if (error) raise(*error);
             sim->outDir = outDir.empty() ? std::filesystem::path(scene.outputs.directory) : outDir;
             return sim;
           }),
           py::arg("scene"), py::arg("out_dir") = std::filesystem::path(), py::arg("duration_hint") = 10.0,
           "Builds and starts the scene's engines in lockstep (duration_hint sizes the force trace).")
      .def(
          "advance",
          [](Simulation& s, double seconds) {
            unwrap(released([&] { return s.runtime->advance(seconds); }));
          },
          py::arg("seconds"), "Runs the virtual clock on by `seconds` (GIL released).")
      .def_property_readonly("time", [](const Simulation& s) { return s.runtime->time(); })
      .def(
          "state", [](Simulation& s) { return jsonToPython(unwrap(s.runtime->state())); },
          "The engines now: time_s, physics (bodies as in the summary), haptics (force, proxy, contacts), "
          "scripts (their metrics so far).")
      .def(
          "finish",
          [](Simulation& s) {
            auto r = unwrap(released([&] { return s.runtime->finish(); }));
            RunResult out;
            out.summary = jsonToPython(r.summary);
            out.interrupted = r.interrupted;
            out.simulatedSeconds = r.simulatedSeconds;
            out.frames = r.frames;
            out.outDir = s.outDir;
            return out;
          },
          "Stops the engines and writes the outputs; returns the RunResult.");

  m.def(
      "run",
      [](const SceneDesc& scene, double duration, const std::filesystem::path& outDir,
         const std::string& mode) {
        if (mode != "lockstep" && mode != "realtime")
          raise(fail(ErrorCode::InvalidArgument, "mode \"" + mode + "\"", "mode",
                     "\"lockstep\" (virtual clock, reproducible) or \"realtime\""));
        SceneRunResult r;
        std::optional<Error> error;
        {
          py::gil_scoped_release release;  // errors are raised once it is held again
          auto rt = SceneRuntime::create(scene);
          if (!rt) {
            error = rt.error();
          } else {
            auto done = (*rt)->run({.mode = mode == "lockstep" ? RunMode::Lockstep : RunMode::RealTime,
                                    .duration = duration,
                                    .outDir = outDir});
            if (done)
              r = std::move(*done);
            else
              error = done.error();
          }
        }
        if (error) raise(*error);
        RunResult out;
        out.summary = jsonToPython(r.summary);
        out.interrupted = r.interrupted;
        out.simulatedSeconds = r.simulatedSeconds;
        out.frames = r.frames;
        out.outDir = outDir.empty() ? std::filesystem::path(scene.outputs.directory) : outDir;
        return out;
      },
      py::arg("scene"), py::arg("duration"), py::arg("out_dir") = std::filesystem::path(),
      py::arg("mode") = "lockstep",
      "Runs the scene for `duration` seconds (simulated in lockstep, wall time in real time) and writes its "
      "outputs into `out_dir` (default: the scene's outputs.directory); the GIL is released meanwhile.");
}

}  // namespace dm::python
