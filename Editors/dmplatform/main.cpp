// dmplatform — the main job: runs a simulation scene file, headless or in a
// live window.
//
//   dmplatform run [SCENE.json] [--lockstep | --realtime] [--duration S] [--out DIR]
//                  [--view [--screenshot PNG] [--gamepad DEVICE]]
//   dmplatform replay RECORDING [--out DIR]
//   dmplatform sweep SWEEP.json [--scheduler tcp://HOST:8786 | --workers N | --serial]
//
// With no SCENE it runs the bundled default scene (examples/scenes/
// head_probe.json: the Colin27 head from ch2.nii.gz probed through the
// god-object by a simulated haptic device, rendered headless). Writes what
// the scene's "outputs" ask for into DIR (default: the scene's
// outputs.directory): frames/frame_NNNNN.png, forces.csv, forces.png and
// summary.json. A progress bar shows on a terminal; Ctrl-C stops the run
// cleanly and the outputs are still written. `--view` shows the run in a
// window as it goes (live_view.hpp: the frames as written, Space pauses, N
// steps, Esc ends, the mouse turns the camera; builds with GLFW); with a
// scene whose haptic device is a "pointer" the mouse, the keys and
// `--gamepad` (an evdev device: /dev/input/eventN or a part of its name)
// move the tool.
// `replay` re-runs a run recorded with "outputs": {"recording": true}
// (recording.dmrec) in lockstep, with the recorded device stream, into DIR
// (default: replay/ beside the recording), and compares its forces.csv with
// the recorded one beside the recording, tick by tick (replay.json).
// `sweep` runs many lockstep variants of a scene on a Dask cluster
// (docs/sweeps.md): it is the Python package's `python3 -m
// dmplatform.sweeps`, run by Debian's /usr/bin/python3 with the package this
// binary was built with (DM_PYTHON_PACKAGE_DIR) first on its path; its exit
// code is the sweep's (1 when a variant failed).
// A scene's Python scripts ("scripts", docs/python.md) run in an interpreter
// embedded in this program, started on the first one (builds with pybind11
// and python3-dev; without them such a scene is refused naming the script).
// Exit codes: 0 done (replay: the same force trace, or none to compare), 1
// the run failed (message on stderr), 2 bad command line, scene or
// recording, 3 the replay's force trace differs from the recorded one, 130
// interrupted (outputs written).
#include <dm/core/filesystem.hpp>
#include <dm/core/log.hpp>
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/controller.hpp>
#include <dm/io/drivers.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_replay.hpp>

#include <unistd.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "progress_bar.hpp"
#ifdef DM_HAVE_LIVE_VIEW
#include "live_view.hpp"
#endif
#ifdef DM_HAVE_PYTHON_SCRIPTS
#include "python_script.hpp"
#endif

namespace {

std::atomic<bool> gStop{false};

extern "C" void onSignal(int) { gStop.store(true); }

// The bundled default scene: next to the installed binary
// (../share/dmplatform/scenes) or in the source tree this was built from
// (DM_SOURCE_SCENES_DIR, relative to the built binary's folder).
std::filesystem::path defaultScene() {
  std::error_code ec;
  const auto exe = std::filesystem::canonical("/proc/self/exe", ec);
  if (ec) return std::filesystem::path(DM_SOURCE_SCENES_DIR) / "head_probe.json";
  const auto installed =
      exe.parent_path().parent_path() / "share" / "dmplatform" / "scenes" / "head_probe.json";
  if (std::filesystem::exists(installed, ec)) return installed;
  return (exe.parent_path() / DM_SOURCE_SCENES_DIR / "head_probe.json").lexically_normal();
}

// `dmplatform sweep`: replaces this process by Debian's Python running the
// package's sweep command, the package built beside this binary first on
// PYTHONPATH. Returns only when that cannot start (exit code 1).
int sweep(const std::vector<std::string>& args) {
  std::error_code ec;
  const auto exe = std::filesystem::canonical("/proc/self/exe", ec);
  if (!ec) {
    const auto package = (exe.parent_path() / DM_PYTHON_PACKAGE_DIR).lexically_normal();
    if (std::filesystem::exists(package / "dmplatform" / "__init__.py", ec)) {
      const char* old = std::getenv("PYTHONPATH");
      const std::string path = package.string() + (old != nullptr && *old != 0 ? ":" + std::string(old) : "");
      ::setenv("PYTHONPATH", path.c_str(), 1);
    }
  }
  // argv[0] the full path: Python takes sys.executable (what its worker
  // processes run) from it, and the `python3` first on PATH may be another one.
  std::vector<std::string> words = {DM_PYTHON_EXECUTABLE, "-m", "dmplatform.sweeps"};
  words.insert(words.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& w : words) argv.push_back(w.data());
  argv.push_back(nullptr);
  ::execv(DM_PYTHON_EXECUTABLE, argv.data());
  std::cerr << "dmplatform: cannot start " << DM_PYTHON_EXECUTABLE << ": " << std::strerror(errno)
            << " (install python3, python3-distributed and the dmplatform package: scripts/setup.sh)\n";
  return 1;
}

// The run's figures from its summary, one line per engine and model.
void printSummary(const nlohmann::json& s, const std::filesystem::path& outDir, bool interrupted) {
  for (const auto& e : s["engines"])
    std::printf(
        "engine %-8s %8llu ticks at %7.1f Hz (scheduled %6.0f Hz), tick p50 %8.1f us, p99.9 %8.1f us, "
        "max %8.1f us, deadline misses %llu%s\n",
        e["name"].get<std::string>().c_str(), e["ticks"].get<unsigned long long>(),
        e["achieved_hz"].get<double>(), e["rate_hz"].get<double>(), e["execution_us"]["p50"].get<double>(),
        e["execution_us"]["p999"].get<double>(), e["execution_us"]["max"].get<double>(),
        e["deadline_misses"].get<unsigned long long>(),
        s["mode"] == "realtime"
            ? dm::formatString("; woke p50 %.1f us, p99.9 %.1f us, max %.1f us late",
                               e["wakeup_us"]["p50"].get<double>(), e["wakeup_us"]["p999"].get<double>(),
                               e["wakeup_us"]["max"].get<double>())
                  .c_str()
            : "");
  if (s.contains("haptics"))
    std::printf("haptics: %llu of %llu ticks in contact, max force %.2f N, max depth %.1f mm\n",
                s["haptics"]["contact_ticks"].get<unsigned long long>(),
                s["haptics"]["ticks"].get<unsigned long long>(), s["haptics"]["max_force_N"].get<double>(),
                s["haptics"]["max_depth_m"].get<double>() * 1e3);
  if (s.contains("physics"))
    for (const auto& b : s["physics"]["bodies"])
      std::printf("physics: %s moved %.1f mm, now at (%.1f, %.1f, %.1f) mm\n",
                  b["name"].get<std::string>().c_str(), b["displacement_m"].get<double>() * 1e3,
                  b["position_m"][0].get<double>() * 1e3, b["position_m"][1].get<double>() * 1e3,
                  b["position_m"][2].get<double>() * 1e3);
  if (s.contains("physics") && s["physics"].contains("fluids"))
    for (const auto& f : s["physics"]["fluids"]) {
      double in = 0.0, out = 0.0;
      for (const auto& i : f["inlets"]) in += i["volume_m3"].get<double>();
      for (const auto& t : f["suction"]) out += t["volume_m3"].get<double>();
      std::printf(
          "fluid %s: %llu particles (%.1f g), %.2f ml in, %.2f ml sucked, %llu particles left the region%s\n",
          f["name"].get<std::string>().c_str(), f["particles"].get<unsigned long long>(),
          f["mass_kg"].get<double>() * 1e3, in * 1e6, out * 1e6,
          f["left_region_particles"].get<unsigned long long>(),
          f["balanced"].get<bool>() ? "" : " (the account does not balance)");
    }
  if (s.contains("render"))
    std::printf("render: %llu frames (%llu written) on %s, frame p50 %.1f ms\n",
                s["render"]["frames"].get<unsigned long long>(),
                s["render"]["frames_written"].get<unsigned long long>(),
                s["render"]["gl_renderer"].get<std::string>().c_str(),
                s["render"]["frame_ms_p50"].get<double>());
  if (s.contains("host") && s["mode"] == "realtime")
    std::printf(
        "host: %d CPUs, %.2f CPU-s busy, %.3f s stolen by the hypervisor%s; memory %s, %llu major and "
        "%llu minor page faults\n",
        s["host"]["cpus"].get<int>(), s["host"]["cpu_busy_s"].get<double>(),
        s["host"]["cpu_steal_s"].get<double>(),
        s["host"]["cpu_steal_s"].get<double>() > 0 ? " (deadline misses may be the host's)" : "",
        s["host"]["memory_locked"].get<bool>() ? "locked" : "not locked",
        s["host"]["page_faults_major"].get<unsigned long long>(),
        s["host"]["page_faults_minor"].get<unsigned long long>());
  std::printf("wrote %s in %s%s\n", s["outputs"].dump().c_str(), outDir.c_str(),
              interrupted ? " (interrupted)" : "");
}

// Prepares and runs `runtime` with a progress bar and Ctrl-C as its stop,
// then prints its figures: 0 with `result` set, or the exit code of a
// failure (2: the scene cannot run, 1: the run failed), reported on stderr.
int runWithProgress(dm::SceneRuntime& runtime, const std::string& label, dm::SceneRunOptions options,
                    dm::SceneRunResult& result) {
  dmtool::ProgressBar bar(label);
  options.stop = &gStop;
  options.progress = [&](double f, const std::string&) { bar.update(f); };
  if (auto s = runtime.prepare(options); !s) {
    bar.finish();
    std::cerr << "dmplatform: " << s.error().message() << '\n';
    return 2;
  }
  auto r = runtime.run(options);
  bar.finish();
  if (!r) {
    std::cerr << "dmplatform: " << r.error().message() << '\n';
    return 1;
  }
  result = std::move(*r);
  printSummary(result.summary, options.outDir, result.interrupted);
  return 0;
}

// `dmplatform replay`: the recorded scene with the recorded device stream,
// in lockstep, its trace compared with the recorded run's forces.csv
// (beside the recording) tick by tick; replay.json says how they compare.
int replayRecording(const std::filesystem::path& recording, const std::string& out) {
  auto plan = dm::loadReplay(recording);
  if (!plan) {
    std::cerr << "dmplatform: " << plan.error().message() << '\n';
    return 2;
  }
  const std::filesystem::path outDir =
      out.empty() ? recording.parent_path() / "replay" : std::filesystem::path(out);
  std::printf(
      "dmplatform: replaying %s (%s, recorded %s: %zu haptic ticks, %.3f s) in lockstep, outputs in %s\n",
      recording.c_str(), plan->scene.name.c_str(), plan->recordedMode.c_str(), plan->records, plan->duration,
      outDir.c_str());
  if (!plan->tail.empty())
    std::printf("dmplatform: the recording was cut (%s): its complete ticks replay\n", plan->tail.c_str());
  std::fflush(stdout);
  auto runtime = dm::SceneRuntime::create(plan->scene);
  if (!runtime) {
    std::cerr << "dmplatform: " << runtime.error().message() << '\n';
    return 2;
  }
  dm::SceneRunResult result;
  if (int code = runWithProgress(
          **runtime, "dmplatform replay " + plan->scene.name,
          {.mode = dm::RunMode::Lockstep, .duration = plan->duration, .outDir = outDir}, result);
      code != 0)
    return code;
  nlohmann::json report = {{"recording", recording.string()},
                           {"recorded_mode", plan->recordedMode},
                           {"records", plan->records},
                           {"cut", plan->tail}};
  int code = result.interrupted ? 130 : 0;
  if (!plan->recordedForces.empty() && !result.interrupted) {
    auto recorded = dm::readFile(plan->recordedForces);
    auto replayed = dm::readFile(outDir / "forces.csv");
    if (!recorded || !replayed) {
      std::cerr << "dmplatform: " << (recorded ? replayed.error() : recorded.error()).message() << '\n';
      return 1;
    }
    auto text = [](const std::vector<std::byte>& b) {
      return std::string_view(reinterpret_cast<const char*>(b.data()), b.size());
    };
    auto c = dm::compareForceTraces(text(*recorded), text(*replayed));
    if (!c) {
      std::cerr << "dmplatform: " << c.error().message() << '\n';
      return 1;
    }
    report["compared_with"] = plan->recordedForces.string();
    report["ticks_compared"] = c->compared;
    report["ticks_identical"] = c->identical;
    report["ticks_only_recorded"] = c->onlyInRecorded;
    report["ticks_only_replayed"] = c->onlyInReplayed;
    report["max_force_difference_N"] = c->maxForceDifference;
    report["identical"] = c->same();
    if (c->same()) {
      std::printf("replay: the force trace is the recorded one, %zu of %zu ticks bit for bit\n", c->identical,
                  c->compared);
    } else {
      std::printf(
          "replay: %zu of %zu ticks identical (%zu recorded ticks missing), first difference at t = %.3f s, "
          "max |dF| = %.3g N%s\n",
          c->identical, c->compared, c->onlyInRecorded, c->firstDifferenceT, c->maxForceDifference,
          plan->recordedMode == "realtime" ? " (a real-time run's physics steps when its thread gets to it)"
                                           : "");
      code = 3;
    }
  }
  const std::string json = report.dump(2) + "\n";
  if (auto s = dm::writeFileAtomic(outDir / "replay.json", json.data(), json.size()); !s) {
    std::cerr << "dmplatform: " << s.error().message() << '\n';
    return 1;
  }
  return code;
}

}  // namespace

int main(int argc, char** argv) {
#ifdef DM_HAVE_PYTHON_SCRIPTS
  dm::python::registerPythonScripts();  // a scene's .py scripts (an interpreter starts on the first)
#endif
  CLI::App app{"dmplatform — run a surgical simulation scene headless", "dmplatform"};
  app.require_subcommand(1);
  std::string scenePath;
  bool lockstep = false, realtime = false;
  double duration = 10.0;
  std::string out;
  CLI::App* run = app.add_subcommand("run", "Run a scene file (default: the bundled Colin27 head probe)");
  run->add_option("scene", scenePath, "scene file (docs/scene-format.md)");
  auto* ls =
      run->add_flag("--lockstep", lockstep, "all engines on one virtual clock: reproducible (default)");
  run->add_flag("--realtime", realtime, "each engine on its own real-time thread at its rate")->excludes(ls);
  run->add_option("--duration", duration, "seconds to run (simulated in lockstep, wall clock in real time)")
      ->check(CLI::Range(1e-3, 1e7));
  run->add_option("--out", out, "output folder (default: the scene's outputs.directory)");
  bool viewFlag = false;
  std::string screenshot;
  run->add_flag("--view", viewFlag,
                "show the run in a window (Space: pause, N: step, Esc: end; needs a display and the scene's "
                "render engine)");
  run->add_option("--screenshot", screenshot, "with --view: write the window's last picture to this PNG");
  std::string gamepad;
  run->add_option(
      "--gamepad", gamepad,
      "with --view: an evdev gamepad (/dev/input/eventN, or a part of its name) moves the tool of "
      "the scene's pointer device");
  std::string recordingPath, replayOut;
  CLI::App* replay = app.add_subcommand(
      "replay", "Re-run a recorded scene run in lockstep and compare its force trace with the recording's");
  replay
      ->add_option("recording", recordingPath,
                   "recording.dmrec of a run with \"outputs\": {\"recording\": true}")
      ->required();
  replay->add_option("--out", replayOut, "output folder (default: replay/ beside the recording)");
  std::string sweepFile, scheduler;
  int workers = 0;
  bool serial = false;
  CLI::App* sweepCmd =
      app.add_subcommand("sweep", "Run many lockstep variants of a scene on a Dask cluster (docs/sweeps.md)");
  sweepCmd->add_option("sweep", sweepFile, "SWEEP.json: {scene, duration, parameters, out, [samples, seed]}")
      ->required();
  auto* sched = sweepCmd->add_option("--scheduler", scheduler, "a Dask scheduler (tcp://HOST:8786)");
  sweepCmd->add_option("--workers", workers, "a LocalCluster of N worker processes (default: one per core)")
      ->check(CLI::Range(1, 1024))
      ->excludes(sched);
  sweepCmd->add_flag("--serial", serial, "one variant after the other in this process")->excludes(sched);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  if (replay->parsed()) return replayRecording(recordingPath, replayOut);
  if (sweepCmd->parsed()) {
    std::vector<std::string> args = {sweepFile};
    if (!scheduler.empty()) args.insert(args.end(), {"--scheduler", scheduler});
    if (workers > 0) args.insert(args.end(), {"--workers", std::to_string(workers)});
    if (serial) args.push_back("--serial");
    return sweep(args);
  }
  const std::filesystem::path scene = scenePath.empty() ? defaultScene() : std::filesystem::path(scenePath);

  // Exit codes: 2 for a scene that cannot be run (invalid, a resource or a
  // model that cannot be built), 1 for a run that failed, 130 interrupted.
  auto runtime = dm::SceneRuntime::load(scene);
  if (!runtime) {
    std::cerr << "dmplatform: " << runtime.error().message() << '\n';
    return 2;
  }
  const auto& desc = (*runtime)->scene();
  const std::filesystem::path outDir =
      out.empty() ? std::filesystem::path(desc.outputs.directory) : std::filesystem::path(out);
  std::printf("dmplatform: running %s (%s) for %.1f s %s, outputs in %s\n", scene.c_str(), desc.name.c_str(),
              duration, realtime ? "in real time" : "in lockstep", outDir.c_str());
  std::fflush(stdout);
  const dm::SceneRunOptions options{.mode = realtime ? dm::RunMode::RealTime : dm::RunMode::Lockstep,
                                    .duration = duration,
                                    .outDir = outDir};
  if (!screenshot.empty() && !viewFlag) {
    std::cerr << "dmplatform: --screenshot is the window's picture: it needs --view\n";
    return 2;
  }
  if (!gamepad.empty() && !viewFlag) {
    std::cerr << "dmplatform: --gamepad moves the tool in the live view: it needs --view\n";
    return 2;
  }
  dm::SceneRunResult result;
  if (viewFlag) {
#ifdef DM_HAVE_LIVE_VIEW
    dm::SceneRunOptions viewed = options;
    viewed.stop = &gStop;
    // The gamepad: a scene whose haptic device is a pointer, an evdev device.
    dm::FactoryRegistry padRegistry;
    dm::PluginLinker padLinker(padRegistry);
    std::unique_ptr<dm::Controller> pad;
    if (!gamepad.empty()) {
      const dm::SceneDevice* dev = desc.engines.haptics ? desc.device(desc.engines.haptics->device) : nullptr;
      if (!dev || dev->driver != "pointer") {
        std::cerr << "dmplatform: --gamepad moves a pointer device's tool, and the scene's haptic device is "
                  << (dev ? "'" + dev->name + "' (" + dev->driver + ")" : std::string("missing"))
                  << ": give the haptic engine a device with \"driver\": \"pointer\"\n";
        return 2;
      }
      auto opened = dm::registerBuiltinDrivers(padLinker).ok()
                        ? dm::Controller::open(padRegistry, "evdev-controller",
                                               {{gamepad.front() == '/' ? "path" : "name", gamepad}})
                        : dm::Result<std::unique_ptr<dm::Controller>>(dm::fail(
                              dm::ErrorCode::Internal, "the built-in drivers did not register", "--gamepad"));
      if (!opened) {
        std::cerr << "dmplatform: --gamepad: " << opened.error().message() << '\n';
        return 2;
      }
      pad = std::move(*opened);
    }
    if (auto s = (*runtime)->prepare(
            {.mode = options.mode, .duration = duration, .outDir = outDir, .liveFrames = true});
        !s) {
      std::cerr << "dmplatform: " << s.error().message() << '\n';
      return 2;
    }
    auto r = dmplatform::runWithView(**runtime, viewed, {.screenshot = screenshot, .gamepad = pad.get()});
    if (!r) {
      std::cerr << "dmplatform: " << r.error().message() << '\n';
      return 1;
    }
    result = std::move(*r);
    printSummary(result.summary, outDir, result.interrupted);
#else
    std::cerr
        << "dmplatform: --view: this build has no live view (it needs GLFW: apt install libglfw3-dev)\n";
    return 2;
#endif
  } else if (int code = runWithProgress(**runtime, "dmplatform " + desc.name, options, result); code != 0) {
    return code;
  }
  return result.interrupted ? 130 : 0;
}
