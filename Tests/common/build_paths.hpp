// Paths into the build tree for the tests. CMake passes them relative to the
// test executable's folder (dm_path_definition in cmake/DMHelpers.cmake:
// DMTOOL_PATH, DM_DRIVER_PLUGIN_DIR, ...), so that a compile command, and
// with it ccache's key, is the same text in every clone of the project;
// besideExecutable resolves one at run time.
#pragma once

#include <filesystem>
#include <string>
#include <system_error>

namespace dm::test {

inline std::string besideExecutable(const char* relative) {
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) return relative;
  return (exe.parent_path() / relative).lexically_normal().string();
}

}  // namespace dm::test
