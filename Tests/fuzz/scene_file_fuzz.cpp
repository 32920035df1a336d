// libFuzzer target: scene files. Any input must give a scene or dm::Errors
// that each name where (never a crash, hang or huge allocation); a parsed
// scene written back with toJson must parse again to an equal scene.
#include <dm/io/scene_file.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  std::vector<dm::Error> problems;
  auto scene = dm::parseScene(text, "<fuzz>", "/fuzz/scenes", &problems);
  if (!scene) {
    if (problems.empty()) std::abort();
    for (const dm::Error& e : problems)
      if (e.what.empty() || e.where.empty()) std::abort();
    (void)dm::formatSceneErrors(problems);
    return 0;
  }
  if (!problems.empty()) std::abort();
  for (const dm::SceneDevice& d : scene->devices) (void)dm::deviceParams(d);
  auto again = dm::parseScene(dm::toJson(*scene).dump(), "<fuzz re-written>", "/fuzz/scenes");
  if (!again || !(*again == *scene)) std::abort();
  return 0;
}
