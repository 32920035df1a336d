// dmtool's shared pieces: the subcommand table, exit codes, error and JSON
// printing, and the conversions every subcommand uses. Private to dmtool.
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>
#include <dm/math/mesh_topology.hpp>

#include <nlohmann/json.hpp>

#include <CLI/CLI.hpp>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace dmtool {

/// Exit codes: success, a failed operation (message on stderr), a bad
/// command line (usage on stderr).
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;

/// A subcommand: its CLI11 parser and what runs when it was chosen (after
/// parsing), returning the exit code.
struct Command {
  CLI::App* app = nullptr;
  std::function<int()> run;
};

/// Each subcommand lives in its own <name>.cpp and adds itself to `parent`.
Command addInfoCommand(CLI::App& parent);
Command addConvertCommand(CLI::App& parent);
Command addIsosurfaceCommand(CLI::App& parent);
Command addSimplifyCommand(CLI::App& parent);
Command addVoxelizeCommand(CLI::App& parent);
Command addSpheretreeCommand(CLI::App& parent);
Command addDevicesCommand(CLI::App& parent);
Command addCollideCommand(CLI::App& parent);
Command addProbeCommand(CLI::App& parent);
Command addValidateCommand(CLI::App& parent);
Command addPhantomCommand(CLI::App& parent);
#ifdef DM_HAVE_NETWORK
Command addTeleopDeviceCommand(CLI::App& parent);
#endif
#ifdef DM_HAVE_RENDERER
Command addRenderCommand(CLI::App& parent);
#endif

/// Prints "dmtool: error: <where: what (hint)>" on stderr; returns kExitFailure.
int printError(const dm::Error& error);

/// Prints `value` on stdout as one line of JSON followed by a newline.
void printJson(const nlohmann::json& value);

/// A user-given resource name as a path: a mount name ("mricron:ch2.nii.gz")
/// or search-path name resolved by dm::FileSystem::global(), otherwise the
/// name unchanged (so the reader's error names it as the user wrote it).
std::filesystem::path resolveInput(const std::string& name);

/// [x, y, z] with each coordinate finite (null otherwise, per nlohmann).
nlohmann::json toJson(const dm::Vec3& v);

/// Geometry and topology of one mesh (or of all parts together).
struct MeshSummary {
  std::string name;
  dm::MeshTopology topology;
  dm::Aabb bounds;
  std::size_t vertices = 0;
  std::optional<double> volume;      ///< m³, closed oriented manifolds with positive volume
  std::optional<dm::Vec3> centroid;  ///< m, with `volume`
};

/// analyzeTopology(), bounds and, for closed oriented manifolds,
/// computeMassProperties() of `mesh`.
MeshSummary summarize(const dm::Mesh& mesh);

/// The summary as a JSON object (counts, bounds, flags, area, volume).
nlohmann::json toJson(const MeshSummary& s);

/// The summary as indented human-readable lines.
std::string toText(const MeshSummary& s);

/// CLI11 validator accepting finite numbers only.
const CLI::Validator& finiteNumber();

}  // namespace dmtool
