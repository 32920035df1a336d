// dm/io/scene_replay.hpp — a scene run's recording and its replay: what a
// run with "outputs": {"recording": true} writes, and what `dmplatform
// replay RECORDING` turns back into a scene (dm::SceneRuntime runs it).
//
// A scene whose outputs ask for "recording" writes recording.dmrec as it
// runs (dm::DeviceRecorder: crash-safe, every complete record survives a
// kill): the haptic device's state at every haptic tick, stamped with the
// tick's scene time, and as metadata the whole scene (dm::toJson), its base
// folder, the mode it ran in and what the device reported (force, torque,
// stiffness and damping limits, servo rate), which the haptic loop's safety
// limits come from.
//
// loadReplay() turns a recording back into a scene: the same scene with
// its haptic device replaced by "replay-haptic" over the recording (with
// the recorded device's limits), and nothing that reaches outside the run
// (no served devices, no OpenIGTLink engine, no new recording). Run in
// lockstep for the recorded span, every haptic tick gets the state the
// recorded tick got. The force trace is then the recorded one exactly when
// the force depends only on the device's stream and the run's own clock:
// any scene recorded in lockstep, and in real time a scene without physics
// (god-object, burr, needle on static objects); in real time physics steps
// when its thread gets to it, so a scene with dynamic or soft objects
// replays the same hand but not necessarily the same bodies.
// compareForceTraces() says how close two forces.csv are, tick by tick.
//
// @code
//   auto replay = dm::loadReplay("out/box_push/recording.dmrec");
//   if (!replay) return replay.error();
//   auto rt = dm::SceneRuntime::create(replay->scene);
//   auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = replay->duration, .outDir = "replayed"});
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/io/haptic_device.hpp>
#include <dm/io/recorder.hpp>
#include <dm/io/scene_file.hpp>

#include <nlohmann/json.hpp>

#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>

namespace dm {

/// The file name a scene run records to, in its output folder.
inline constexpr std::string_view kSceneRecordingFile = "recording.dmrec";

/// The "format" in a scene run's recording header.
inline constexpr std::string_view kSceneRecordingFormat = "dmplatform-scene-recording";

/// The header a scene run writes into its recording: the scene, its base
/// folder, the mode, and the haptic device's name, driver and limits.
nlohmann::json sceneRecordingMetadata(const SceneDesc& scene, const SceneDevice& device,
                                      const HapticInfo& info, bool lockstep);

/// A recording turned back into a scene to run (see the file comment).
struct SceneReplay {
  SceneDesc scene;           ///< outputs.directory unchanged; forces on, recording off
  double duration = 0.0;     ///< s of lockstep run: from the first recorded tick to a period past the last
  std::size_t records = 0;   ///< complete haptic-state records
  std::string recordedMode;  ///< "lockstep" or "realtime"
  std::string tail;          ///< "" for a cleanly closed recording, else where it was cut (a crash)
  std::filesystem::path recordedForces;  ///< forces.csv beside the recording; empty when there is none
};

/// Reads `recording` (written by a scene run with "recording": true) and
/// builds its replay. Fails naming the file and the metadata key when the
/// file is not such a recording, holds no haptic state, or its scene no
/// longer parses (e.g. a resource moved: the error names it).
Result<SceneReplay> loadReplay(const std::filesystem::path& recording);
/// The same from a recording read already; `file` names it in errors and
/// is what the replay device reads.
Result<SceneReplay> loadReplay(const Recording& recording, const std::filesystem::path& file);

/// Two force traces (forces.csv) compared tick by tick, rows matched by
/// their scene time (a real-time run may have skipped a tick the replay has).
struct ForceTraceComparison {
  std::size_t compared = 0;         ///< ticks in both
  std::size_t identical = 0;        ///< of those, rows equal in every column
  std::size_t onlyInRecorded = 0;   ///< ticks the replay lacks
  std::size_t onlyInReplayed = 0;   ///< ticks the recorded run skipped
  double maxForceDifference = 0.0;  ///< N, largest |ΔF| over the compared ticks
  double firstDifferenceT = -1.0;   ///< s, the first compared tick that differs; −1 when none
  bool same() const noexcept { return compared > 0 && identical == compared && onlyInRecorded == 0; }
};

/// Compares two forces.csv texts (dm::formatProbeCsv); fails (Parse, naming
/// the trace and line) on a row that is not one.
Result<ForceTraceComparison> compareForceTraces(std::string_view recorded, std::string_view replayed);

}  // namespace dm
