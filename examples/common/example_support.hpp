// example_support.hpp — what the example programs share: running a
// MasterEngine's engines for a while in lockstep or real time, the output
// directory and files, and the command line's exit codes.
#pragma once

#include <dm/core/filesystem.hpp>
#include <dm/engine/master_engine.hpp>
#include <dm/engine/scene_runtime.hpp>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <chrono>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

namespace dm_example {

/// Loads `master`'s engines, starts them and runs them for `seconds`: in
/// lockstep on the virtual clock (bit-reproducible), or on real-time threads
/// (polled every 20 ms for a failed engine), leaving them running. The
/// engines' statistics go to `stats` (taken before they stop), then the
/// master stops. A failing engine's error is returned.
inline dm::Status runEngines(dm::MasterEngine& master, const std::string& name, bool realtime, double seconds,
                             std::vector<dm::EngineStats>& stats) {
  if (auto s = master.load(name); !s) return s;
  if (auto s = master.start(realtime ? dm::RunMode::RealTime : dm::RunMode::Lockstep); !s) return s;
  dm::Status ran = dm::ok();
  if (realtime) {
    const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (std::chrono::steady_clock::now() < until && (ran = master.poll()))
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
  } else {
    ran = master.advance(seconds);
  }
  stats = master.stats();
  dm::Status stopped = master.stop(ran ? "done" : "failed");
  if (!ran) return ran;
  return stopped;
}

/// Creates `dir` (and its parents); the error names it.
inline dm::Status makeOutputDir(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return dm::fail(dm::ErrorCode::Io, ec.message(), dir.string(), "choose a writable --out");
  return dm::ok();
}

/// Writes `text` to `file` atomically and notes its name in `written`.
inline dm::Status writeOutput(const std::filesystem::path& file, const std::string& text,
                              std::vector<std::string>& written) {
  if (auto s = dm::writeFileAtomic(file, text.data(), text.size()); !s) return s;
  written.push_back(file.filename().string());
  return dm::ok();
}

/// Parses the command line: 0 on success, otherwise the exit code (0 for
/// --help, 2 for a bad command line) with the message printed.
inline int parseCommandLine(CLI::App& app, int argc, char** argv, bool& parsed) {
  parsed = false;
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  parsed = true;
  return 0;
}

}  // namespace dm_example
