// dm/core/confine.hpp — the check behind FileSystem::confine against a list
// of roots given by the caller, taking no lock: for a reader that takes the
// roots once (FileSystem::allowedRoots) and checks the files a third-party
// parser opens later, possibly in a forked child where a lock another
// thread held at the fork would never be released (the mesh importer's
// Assimp file system).
//
// @code
//   const auto roots = dm::FileSystem::global().allowedRoots(model.parent_path());
//   auto ok = dm::confineToRoots(roots, model.parent_path(), "../textures/skin.png", "a texture");
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <filesystem>
#include <span>
#include <string_view>

namespace dm {

/// Resolves `reference` (relative ones from `folder`) to a path without
/// symlinks inside one of `roots` (canonical folders, as
/// FileSystem::allowedRoots gives them); Denied naming `field`, the
/// reference, where it leads and how to allow it otherwise (see
/// FileSystem::confine).
Result<std::filesystem::path> confineToRoots(std::span<const std::filesystem::path> roots,
                                             const std::filesystem::path& folder, std::string_view reference,
                                             std::string_view field);

}  // namespace dm
