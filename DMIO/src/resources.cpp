// Resource-manager loaders for the DMIO readers, and mesh/volume path
// classification (see dm/io/resources.hpp).
#include <dm/io/mesh_io.hpp>
#include <dm/io/resources.hpp>
#include <dm/io/volume_io.hpp>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <string_view>
#include <system_error>

namespace dm {
namespace {

std::string lowerCase(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

// Splits `list` at any of `separators` and keeps the tokens that start with
// `prefix` (the prefix is dropped), lower-cased, up to the first blank.
std::vector<std::string> extensionTokens(std::string_view list, std::string_view separators,
                                         std::string_view prefix) {
  std::vector<std::string> out;
  std::size_t pos = 0;
  while (pos <= list.size()) {
    std::size_t end = list.find_first_of(separators, pos);
    if (end == std::string_view::npos) end = list.size();
    std::string_view item = list.substr(pos, end - pos);
    const std::size_t first = item.find_first_not_of(" \t");
    if (first != std::string_view::npos) {
      item.remove_prefix(first);
      item = item.substr(0, item.find_first_of(" \t("));
      if (item.size() > prefix.size() && item.starts_with(prefix)) {
        std::string ext = "." + lowerCase(item.substr(prefix.size()));
        if (std::find(out.begin(), out.end(), ext) == out.end()) out.push_back(std::move(ext));
      }
    }
    pos = end + 1;
  }
  return out;
}

Status refuseUnknownKeys(const ImportOptions& options, std::initializer_list<std::string_view> known,
                         const char* type) {
  for (const auto& [key, value] : options.values()) {
    if (std::find(known.begin(), known.end(), key) != known.end()) continue;
    std::string accepted;
    for (std::string_view k : known) accepted += (accepted.empty() ? "" : ", ") + std::string(k);
    return fail(ErrorCode::InvalidArgument, "unknown import option \"" + key + "\" for " + type,
                "import options", "accepted keys: " + accepted);
  }
  return ok();
}

Result<double> parseNumber(const ImportOptions& options, std::string_view key, double fallback) {
  const std::string* text = options.find(key);
  if (!text) return fallback;
  double v = 0.0;
  const char* end = text->data() + text->size();
  auto [ptr, ec] = std::from_chars(text->data(), end, v);
  if (ec != std::errc() || ptr != end || !std::isfinite(v))
    return fail(ErrorCode::InvalidArgument, "import option is not a finite number: \"" + *text + "\"",
                "import options: " + std::string(key), "write a decimal number such as 0.001");
  return v;
}

Result<Mesh> loadMesh(const std::filesystem::path& path, const ImportOptions& options) {
  if (auto s = refuseUnknownKeys(options, {"unit", "scale", "weld_tolerance"}, "dm::Mesh"); !s)
    return std::move(s).error().within(path.string());
  MeshImportOptions o;
  o.unit = options.getOr("unit", o.unit);
  auto scale = parseNumber(options, "scale", o.scale);
  if (!scale) return std::move(scale).error().within(path.string());
  auto weld = parseNumber(options, "weld_tolerance", o.weldTolerance);
  if (!weld) return std::move(weld).error().within(path.string());
  o.scale = *scale;
  o.weldTolerance = *weld;
  return readMesh(path, o);
}

Result<Volume> loadVolume(const std::filesystem::path& path, const ImportOptions& options) {
  if (auto s = refuseUnknownKeys(options, {"volume"}, "dm::Volume"); !s)
    return std::move(s).error().within(path.string());
  VolumeReadOptions o;
  if (const std::string* text = options.find("volume")) {
    const char* end = text->data() + text->size();
    auto [ptr, ec] = std::from_chars(text->data(), end, o.volumeIndex);
    if (ec != std::errc() || ptr != end || o.volumeIndex < 0)
      return fail(ErrorCode::InvalidArgument, "import option is not a volume index: \"" + *text + "\"",
                  path.string() + ": import options: volume", "write a 0-based integer such as 0");
  }
  return readVolume(path, o);
}

}  // namespace

std::vector<std::string> volumeExtensions() { return extensionTokens(supportedVolumeExtensions(), ",", "."); }

std::vector<std::string> meshExtensions() { return extensionTokens(supportedMeshExtensions(), ";", "*."); }

bool isVolumePath(const std::filesystem::path& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) return true;
  const std::string name = lowerCase(path.filename().string());
  for (const std::string& ext : volumeExtensions())
    if (name.size() > ext.size() && name.ends_with(ext)) return true;
  return false;
}

Status registerIoLoaders(ResourceManager& manager) {
  if (auto s = manager.registerLoader<Mesh>(meshExtensions(), loadMesh); !s) return s;
  return manager.registerLoader<Volume>(volumeExtensions(), loadVolume);
}

}  // namespace dm
