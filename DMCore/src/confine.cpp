// FileSystem::confine: a file named inside another file leads only into the
// allowed roots (dm/core/filesystem.hpp, "Confinement").

#include <dm/core/confine.hpp>
#include <dm/core/filesystem.hpp>

#include <algorithm>
#include <optional>
#include <string>
#include <vector>

namespace dm {

namespace fs = std::filesystem;

namespace {

// True when `path` is `root` or lies below it; both are canonical (absolute,
// no symlinks, no "." or ".."), so comparing their elements is enough.
bool isWithin(const fs::path& path, const fs::path& root) {
  auto p = path.begin();
  for (auto r = root.begin(); r != root.end(); ++r) {
    if (r->empty()) continue;  // a trailing '/' of the root
    if (p == path.end() || *p != *r) return false;
    ++p;
  }
  return true;
}

// `dir` made absolute with its symlinks resolved (as far as it exists: the
// folder of a header that was never written is still its own root).
std::optional<fs::path> realFolder(const fs::path& dir) {
  std::error_code ec;
  fs::path real = fs::weakly_canonical(fs::absolute(dir.empty() ? fs::path(".") : dir, ec), ec);
  if (ec || real.empty()) return std::nullopt;
  return real;
}

}  // namespace

std::vector<fs::path> FileSystem::allowedRoots(const fs::path& folder) const {
  std::vector<fs::path> candidates{folder};
  {
    std::lock_guard lock(mutex_);
    for (const Mount& m : mounts_) candidates.push_back(m.dir);
    candidates.insert(candidates.end(), searchPaths_.begin(), searchPaths_.end());
    candidates.insert(candidates.end(), allowedRoots_.begin(), allowedRoots_.end());
  }
  std::vector<fs::path> roots;
  for (const fs::path& c : candidates) {
    auto real = realFolder(c);
    if (real && std::find(roots.begin(), roots.end(), *real) == roots.end()) roots.push_back(std::move(*real));
  }
  return roots;
}

Result<fs::path> confineToRoots(std::span<const fs::path> roots, const fs::path& folder,
                                std::string_view reference, std::string_view field) {
  const std::string where(field);
  const std::string shownRef = "\"" + shownText(reference, 200) + "\"";
  const std::string allowHint =
      "keep the file in the referring file's folder or a data root, or allow its folder with "
      "DM_ALLOW_PATH=<folder> in the environment (dm::FileSystem::global().allowRoot() in code)";
  if (reference.empty()) return fail(ErrorCode::InvalidArgument, "the file name is empty", where);
  if (reference.size() > FileSystem::kMaxReferenceBytes)
    return fail(ErrorCode::Denied,
                "the file name is " + std::to_string(reference.size()) + " bytes long; the limit is " +
                    std::to_string(FileSystem::kMaxReferenceBytes),
                where, "name a file with a shorter path");
  if (reference.find('\0') != std::string_view::npos)
    return fail(ErrorCode::Denied, "the file name " + shownRef + " contains a NUL byte", where);
  const fs::path named(reference);
  const fs::path candidate = named.is_absolute() ? named : (folder.empty() ? fs::path(".") : folder) / named;
  std::error_code ec;
  const fs::path real = fs::weakly_canonical(candidate, ec);
  if (ec)
    return fail(ErrorCode::Denied, "cannot resolve " + shownRef + ": " + ec.message(), where,
                "check the path (a symlink loop, or a folder name that is too long)");
  for (const fs::path& root : roots)
    if (isWithin(real, root)) return real;
  std::string listed;
  for (const fs::path& root : roots) listed += (listed.empty() ? "" : ", ") + root.string();
  return fail(ErrorCode::Denied,
              shownRef + " resolves to " + shownText(real.string(), 200) + ", outside the allowed folders (" +
                  listed + "); nothing was read from it",
              where, allowHint);
}

Result<fs::path> FileSystem::confine(const fs::path& folder, std::string_view reference,
                                     std::string_view field) const {
  const std::vector<fs::path> roots = allowedRoots(folder);
  return confineToRoots(roots, folder, reference, field);
}

}  // namespace dm
