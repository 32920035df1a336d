// helper_program.cpp — where DMPlatform's helper programs are found
// (dm/core/helper_program.hpp).
#include <dm/core/helper_program.hpp>

#include <dlfcn.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <system_error>
#include <vector>

namespace dm {

Result<std::string> findHelperProgram(const HelperProgram& program) {
  namespace fs = std::filesystem;
  auto runnable = [](const fs::path& p) {
    std::error_code ec;
    return fs::is_regular_file(p, ec) && ::access(p.c_str(), X_OK) == 0;
  };
  if (const char* env = std::getenv(program.envVar); env != nullptr && *env != '\0') {
    if (runnable(env)) return std::string(env);
    return fail(ErrorCode::NotFound,
                std::string(program.envVar) + " names '" + env + "', which is not an executable file",
                program.envVar,
                std::string("point it at the ") + program.name + " program of this DMPlatform, or unset it");
  }
  std::vector<fs::path> places;
  std::error_code ec;
  Dl_info info{};
  if (program.anchor != nullptr && ::dladdr(program.anchor, &info) != 0 && info.dli_fname != nullptr &&
      *info.dli_fname != '\0') {
    const fs::path lib = fs::weakly_canonical(fs::absolute(info.dli_fname, ec), ec);
    places.push_back(lib.parent_path() / program.name);
    places.push_back(lib.parent_path() / "dmplatform" / program.name);
  }
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) places.push_back(exe.parent_path() / program.name);
  std::string looked;
  for (const fs::path& p : places) {
    if (runnable(p)) return p.string();
    looked += (looked.empty() ? "" : ", ") + p.string();
  }
  return fail(ErrorCode::NotFound,
              std::string("the helper program ") + program.name + ", which " + program.purpose +
                  ", is not in " + (looked.empty() ? std::string("any known folder") : looked),
              "", program.otherwise);
}

}  // namespace dm
