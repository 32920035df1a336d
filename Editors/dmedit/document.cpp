// dmedit's scene document (document.hpp).
#include "document.hpp"

#include <dm/core/filesystem.hpp>

#include <algorithm>
#include <utility>

namespace dmedit {
namespace {

constexpr std::size_t kUndoDepth = 64;

template <class T>
T* findNamed(std::vector<T>& items, std::string_view name) {
  auto it = std::find_if(items.begin(), items.end(), [&](const T& x) { return x.name == name; });
  return it == items.end() ? nullptr : &*it;
}

dm::Error notFound(const char* what, std::string_view name, const char* where) {
  return dm::fail(dm::ErrorCode::NotFound, std::string("no ") + what + " \"" + std::string(name) + "\"", where,
                  "pick one the scene defines");
}

// A file source relative to the scene's directory ("meshes/a.stl"), as
// opposed to an absolute path or a mounted data source ("mricron:ch2.nii.gz").
bool relativeFileSource(const std::string& source) {
  if (source.empty() || std::filesystem::path(source).is_absolute()) return false;
  const auto colon = source.find(':');
  const auto slash = source.find('/');
  return colon == std::string::npos || (slash != std::string::npos && slash < colon);
}

}  // namespace

dm::Result<SceneDocument> SceneDocument::open(const std::filesystem::path& file) {
  std::vector<dm::Error> problems;
  auto scene = dm::readScene(file, &problems);
  if (!scene) {
    if (problems.size() > 1) {
      dm::Error e = scene.error();
      e.what = dm::formatString("%zu problems:\n", problems.size()) + dm::formatSceneErrors(problems);
      return e;
    }
    return scene.error();
  }
  return SceneDocument(std::move(*scene), file);
}

SceneDocument::SceneDocument(dm::SceneDesc scene, std::filesystem::path file)
    : scene_(std::move(scene)), file_(std::move(file)) {}

std::string SceneDocument::text() const { return dm::toJson(scene_).dump(2) + "\n"; }

dm::Status SceneDocument::apply(dm::SceneDesc next) {
  // Written out and read back: only a scene the platform accepts is kept.
  std::vector<dm::Error> problems;
  auto checked = dm::parseScene(dm::toJson(next).dump(), file_.filename().string(), next.baseDir, &problems);
  if (!checked) return checked.error();
  undo_.push_back(std::move(scene_));
  if (undo_.size() > kUndoDepth) undo_.pop_front();
  redo_.clear();
  scene_ = std::move(*checked);
  dirty_ = true;
  ++revision_;
  return dm::ok();
}

template <class T>
dm::Status SceneDocument::replaceNamed(std::vector<T> dm::SceneDesc::*items, const T& item, const char* what,
                                       const char* where) {
  dm::SceneDesc next = scene_;
  T* old = findNamed(next.*items, item.name);
  if (!old) return notFound(what, item.name, where);
  *old = item;
  return apply(std::move(next));
}

dm::Status SceneDocument::setObject(const dm::SceneObject& object) {
  return replaceNamed(&dm::SceneDesc::objects, object, "object", "/objects");
}

dm::Status SceneDocument::addObject(const dm::SceneObject& object) {
  if (scene_.object(object.name))
    return dm::fail(dm::ErrorCode::InvalidArgument, "an object \"" + object.name + "\" exists already", "/objects",
                    "choose another name");
  dm::SceneDesc next = scene_;
  next.objects.push_back(object);
  return apply(std::move(next));
}

dm::Status SceneDocument::removeObject(std::string_view name) {
  dm::SceneDesc next = scene_;
  auto it = std::find_if(next.objects.begin(), next.objects.end(), [&](const auto& o) { return o.name == name; });
  if (it == next.objects.end()) return notFound("object", name, "/objects");
  next.objects.erase(it);
  return apply(std::move(next));  // a dangling reference (engine, camera) is the reader's error
}

dm::Status SceneDocument::setMaterial(const dm::SceneMaterial& material) {
  return replaceNamed(&dm::SceneDesc::materials, material, "material", "/materials");
}

dm::Status SceneDocument::setVolume(const dm::SceneVolume& volume) {
  return replaceNamed(&dm::SceneDesc::volumes, volume, "volume view", "/volumes");
}

dm::Status SceneDocument::setLight(std::size_t index, const dm::SceneLight& light) {
  if (index >= scene_.lights.size())
    return dm::fail(dm::ErrorCode::NotFound, dm::formatString("no light %zu", index), "/lights",
                    dm::formatString("the scene has %zu lights", scene_.lights.size()));
  dm::SceneDesc next = scene_;
  next.lights[index] = light;
  return apply(std::move(next));
}

bool SceneDocument::undo() {
  if (undo_.empty()) return false;
  redo_.push_back(std::move(scene_));
  scene_ = std::move(undo_.back());
  undo_.pop_back();
  dirty_ = true;
  ++revision_;
  return true;
}

bool SceneDocument::redo() {
  if (redo_.empty()) return false;
  undo_.push_back(std::move(scene_));
  scene_ = std::move(redo_.back());
  redo_.pop_back();
  dirty_ = true;
  ++revision_;
  return true;
}

dm::Status SceneDocument::save(const std::filesystem::path& file) {
  const std::filesystem::path target = file.empty() ? file_ : file;
  if (target.empty())
    return dm::fail(dm::ErrorCode::InvalidArgument, "no file to save to", "save", "give a path");
  std::error_code ec;
  const std::filesystem::path dir = std::filesystem::absolute(target, ec).parent_path();
  dm::SceneDesc out = scene_;
  if (!ec && std::filesystem::absolute(out.baseDir, ec) != dir) {
    // Saved elsewhere, the scene names its files by absolute paths into its
    // old folder. That folder is outside the new one, so this process allows
    // it as a root (FileSystem::confine); another process that opens the
    // moved scene needs DM_ALLOW_PATH, which the refusal then names.
    bool relative = false;
    for (dm::SceneResource& r : out.resources)
      if (relativeFileSource(r.source)) {
        r.source = std::filesystem::absolute(out.baseDir / r.source).string();
        relative = true;
      }
    if (relative) dm::FileSystem::global().allowRoot(std::filesystem::absolute(out.baseDir));
  }
  const std::string json = dm::toJson(out).dump(2) + "\n";
  if (auto s = dm::writeFileAtomic(target, json.data(), json.size()); !s) return s.error();
  out.baseDir = dir;
  scene_ = std::move(out);
  file_ = target;
  dirty_ = false;
  return dm::ok();
}

}  // namespace dmedit
