// dm/core/helper_program.hpp — finds one of DMPlatform's helper programs:
// the small executables the libraries start (posix_spawn, never a bare
// fork of a threaded caller) to run risky work apart from the caller's
// process — dm-isolate (Assimp and OpenVDB parses, dm/io/isolation.hpp) and
// dm-plugin-probe (a plugin's first load in probe mode, dm/core/plugin.hpp).
//
// spawnHelperProgram() starts one the same way for every caller. A program
// is looked for, in order: at the path its environment variable
// names (which must then be an executable file); beside the shared library
// that asks (found with dladdr from an object in it); in that folder's
// dmplatform/ subfolder (the install layout, <libdir>/dmplatform/); beside
// the running executable. A missing program is a NotFound error listing
// where it was looked for.
//
// @code
//   static const char kAnchor = 0;
//   auto path = dm::findHelperProgram({"dm-isolate", "DM_ISOLATE_HELPER",
//       "runs Assimp and OpenVDB apart from this process", "build the dm-isolate target", &kAnchor});
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <sys/types.h>

#include <span>
#include <string>

namespace dm {

/// What findHelperProgram() looks for.
struct HelperProgram {
  const char* name = "";         ///< the file name, e.g. "dm-isolate"
  const char* envVar = "";       ///< the variable whose path overrides the search
  const char* purpose = "";      ///< what it does, for the message ("runs ... apart from this process")
  const char* otherwise = "";    ///< the hint when it is missing
  const void* anchor = nullptr;  ///< an object in the asking library (dladdr finds the library's file)
};

/// The program's path, or NotFound naming the variable or the folders
/// looked in. Reads the environment and the file system; O(1).
Result<std::string> findHelperProgram(const HelperProgram& program);

/// Starts `program` with `args` (argv[1], ...) by posix_spawn: no fork of
/// this process, so no lock another of its threads holds comes along. The
/// program gets `channel` as its fd 3, /dev/null as fd 0 and 1 (a helper
/// never reads our stdin or writes into our stdout), our stderr, and every
/// signal unblocked and at its default whatever our threads block or catch.
/// Sets `pid` and returns 0, or returns the errno of the failure. The
/// caller reaps the program (waitpid).
int spawnHelperProgram(const std::string& program, std::span<const std::string> args, int channel,
                       pid_t& pid);

}  // namespace dm
