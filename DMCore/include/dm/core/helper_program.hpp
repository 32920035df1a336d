// dm/core/helper_program.hpp — finds one of DMPlatform's helper programs:
// the small executables the libraries start (posix_spawn, never a bare
// fork of a threaded caller) to run risky work apart from the caller's
// process — dm-isolate (Assimp and OpenVDB parses, dm/io/isolation.hpp) and
// dm-plugin-probe (a plugin's first load in probe mode, dm/core/plugin.hpp).
//
// A program is looked for, in order: at the path its environment variable
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

}  // namespace dm
