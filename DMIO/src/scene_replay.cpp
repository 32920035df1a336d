// scene_replay.cpp — a scene run's recording header, the recording turned
// back into a scene (dm/io/scene_replay.hpp), force traces compared tick by
// tick.
#include <dm/io/scene_replay.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <map>
#include <vector>

namespace dm {

nlohmann::json sceneRecordingMetadata(const SceneDesc& scene, const SceneDevice& device,
                                      const HapticInfo& info, bool lockstep) {
  std::error_code ec;
  const std::filesystem::path base = std::filesystem::absolute(scene.baseDir, ec);
  const double halfExtent =
      std::max(info.workspace.min().cwiseAbs().maxCoeff(), info.workspace.max().cwiseAbs().maxCoeff());
  return {{"format", std::string(kSceneRecordingFormat)},
          {"version", 1},
          {"mode", lockstep ? "lockstep" : "realtime"},
          {"base_dir", (ec ? scene.baseDir : base).string()},
          {"device",
           {{"name", device.name},
            {"driver", device.driver},
            {"max_force", info.maxForce},
            {"max_torque", (info.capabilities & DM_HAPTIC_CAP_TORQUE) ? info.maxTorque : 0.0},
            {"max_stiffness", info.maxStiffness},
            {"max_damping", info.maxDamping},
            {"servo_rate_hz", info.servoRateHz},
            {"workspace", std::isfinite(halfExtent) && halfExtent > 0 ? halfExtent : 0.15}}},
          {"scene", toJson(scene)}};
}

namespace {

Error badRecording(const std::filesystem::path& file, const std::string& key, std::string what,
                   std::string hint = {}) {
  return fail(ErrorCode::Parse, std::move(what), file.string() + ": metadata/" + key,
              hint.empty() ? "record a scene run with \"outputs\": {\"recording\": true}" : std::move(hint));
}

}  // namespace

Result<SceneReplay> loadReplay(const std::filesystem::path& recording) {
  auto rec = readRecording(recording);
  if (!rec) return rec.error();
  return loadReplay(*rec, recording);
}

Result<SceneReplay> loadReplay(const Recording& rec, const std::filesystem::path& recording) {
  const nlohmann::json meta = nlohmann::json::parse(rec.metadata, nullptr, false);
  if (meta.is_discarded() || !meta.is_object())
    return badRecording(recording, "", "the recording's metadata is not a JSON object",
                        "this recording was not written by a scene run (dmplatform run with a recording)");
  if (!meta.contains("format") || meta["format"] != std::string(kSceneRecordingFormat))
    return badRecording(recording, "format", "format is not \"" + std::string(kSceneRecordingFormat) + "\"",
                        "this recording was not written by a scene run (dmplatform run with a recording)");
  if (!meta.contains("version") || !meta["version"].is_number_integer() || meta["version"] != 1)
    return badRecording(recording, "version",
                        "version " +
                            (meta.contains("version") ? meta["version"].dump() : std::string("missing")) +
                            " (this build reads 1)");
  for (const char* key : {"base_dir", "mode"})
    if (!meta.contains(key) || !meta[key].is_string())
      return badRecording(recording, key, "missing or not a string");
  for (const char* key : {"scene", "device"})
    if (!meta.contains(key) || !meta[key].is_object())
      return badRecording(recording, key, std::string("no \"") + key + "\" object");
  const nlohmann::json& dev = meta["device"];
  for (const char* key :
       {"max_force", "max_torque", "max_stiffness", "max_damping", "servo_rate_hz", "workspace"})
    if (!dev.contains(key) || !dev[key].is_number())
      return badRecording(recording, std::string("device/") + key, "missing or not a number");
  if (!dev.contains("name") || !dev["name"].is_string())
    return badRecording(recording, "device/name", "missing or not a string");

  std::vector<Error> problems;
  auto scene = parseScene(meta["scene"].dump(), recording.string() + " (recorded scene)",
                          std::filesystem::path(meta["base_dir"].get<std::string>()), &problems);
  if (!scene) return scene.error();
  SceneReplay r;
  r.recordedMode = meta["mode"].get<std::string>();
  r.tail = rec.tail;

  // The haptic device replays the recording under the recorded limits.
  if (!scene->engines.haptics || scene->engines.haptics->device != dev["name"].get<std::string>())
    return badRecording(
        recording, "device/name",
        "the recorded scene's haptics engine does not drive \"" + dev["name"].get<std::string>() + "\"");
  std::int64_t first = 0, last = 0;
  for (const RecordedRecord& record : rec.records) {
    if (record.type != static_cast<std::uint16_t>(RecordType::HapticState)) continue;
    if (auto s = decodeHapticState(record); !s) return s.error().within(recording.string());
    if (r.records == 0) first = record.timeNs;
    last = record.timeNs;
    ++r.records;
  }
  if (r.records == 0)
    return fail(ErrorCode::Parse,
                "the recording holds no haptic state" + (rec.tail.empty() ? "" : ": " + rec.tail),
                recording.string(), "the run was stopped before its first haptic tick");
  // A lockstep run of D seconds ticks at t < D: one period past the last
  // recorded tick, in whole nanoseconds as the clock counts them.
  const std::int64_t periodNs = std::llround(1e9 / scene->engines.haptics->rateHz);
  r.duration = static_cast<double>(last - first + periodNs) * 1e-9;
  for (SceneDevice& d : scene->devices) {
    d.serve.reset();
    if (d.name != dev["name"].get<std::string>()) continue;
    d.driver = "replay-haptic";
    std::error_code ec;
    const std::filesystem::path file = std::filesystem::absolute(recording, ec);
    d.config = {{"file", (ec ? recording : file).string()},
                {"max_force", dev["max_force"]},
                {"max_torque", dev["max_torque"]},
                {"max_stiffness", dev["max_stiffness"]},
                {"max_damping", dev["max_damping"]},
                {"servo_rate", dev["servo_rate_hz"]},
                {"workspace", dev["workspace"]}};
    d.files.clear();
  }
  scene->engines.igtl.reset();
  scene->outputs.recording = false;
  scene->outputs.forces = true;
  r.scene = std::move(*scene);
  const std::filesystem::path forces = recording.parent_path() / "forces.csv";
  std::error_code ec;
  if (std::filesystem::exists(forces, ec)) r.recordedForces = forces;
  return r;
}

namespace {

// forces.csv rows by their time: every column as written.
Result<std::map<std::string, std::vector<double>>> traceRows(std::string_view csv, const char* which) {
  std::map<std::string, std::vector<double>> rows;
  std::size_t line = 0, at = 0;
  while (at < csv.size()) {
    const std::size_t end = std::min(csv.find('\n', at), csv.size());
    const std::string_view row = csv.substr(at, end - at);
    at = end + 1;
    if (++line == 1 || row.empty()) continue;  // the header
    std::vector<double> values;
    std::size_t from = 0;
    while (from <= row.size()) {
      const std::size_t comma = std::min(row.find(',', from), row.size());
      double v = 0;
      const auto [p, ec] = std::from_chars(row.data() + from, row.data() + comma, v);
      if (ec != std::errc() || p != row.data() + comma)
        return fail(ErrorCode::Parse, "not a number: \"" + std::string(row.substr(from, comma - from)) + "\"",
                    formatString("%s force trace, line %zu", which, line));
      values.push_back(v);
      from = comma + 1;
    }
    if (values.size() < 4)
      return fail(ErrorCode::Parse,
                  formatString("%zu columns, a force trace has t, fx, fy, fz, ...", values.size()),
                  formatString("%s force trace, line %zu", which, line));
    rows.emplace(std::string(row.substr(0, row.find(','))), std::move(values));
  }
  return rows;
}

}  // namespace

Result<ForceTraceComparison> compareForceTraces(std::string_view recorded, std::string_view replayed) {
  auto a = traceRows(recorded, "recorded");
  if (!a) return a.error();
  auto b = traceRows(replayed, "replayed");
  if (!b) return b.error();
  ForceTraceComparison c;
  for (const auto& [t, row] : *a) {
    const auto it = b->find(t);
    if (it == b->end()) {
      ++c.onlyInRecorded;
      continue;
    }
    ++c.compared;
    const std::vector<double>& other = it->second;
    const double df = (Vec3(row[1], row[2], row[3]) - Vec3(other[1], other[2], other[3])).norm();
    c.maxForceDifference = std::max(c.maxForceDifference, df);
    if (row == other) {
      ++c.identical;
    } else if (c.firstDifferenceT < 0 || row[0] < c.firstDifferenceT) {
      c.firstDifferenceT = row[0];
    }
  }
  for (const auto& [t, row] : *b) c.onlyInReplayed += a->count(t) == 0;
  return c;
}

}  // namespace dm
