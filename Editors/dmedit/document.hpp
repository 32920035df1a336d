// document.hpp — the scene being edited by dmedit: a dm::SceneDesc with
// validated edits, undo and redo, and saving.
//
// Every edit is applied to a copy of the scene, which is written out
// (dm::toJson) and read back (dm::parseScene): only a scene the platform
// accepts replaces the current one, so the document is valid at all times
// and save() never writes a file that `dmplatform run` would refuse. A
// refused edit returns the reader's error, which names the JSON path
// ("/objects/2/scale") and what to do. Edits are kept on an undo stack
// (64 deep); save() clears the dirty flag. Not thread-safe: the editor's UI
// thread owns it.
//
// @code
//   auto doc = dmedit::SceneDocument::open("examples/scenes/head_probe.json");
//   if (!doc) return doc.error();
//   dm::SceneObject tool = *doc->scene().object("tool");
//   tool.pose.p = dm::Vec3(0, 0, 0.02);
//   if (auto s = doc->setObject(tool); !s) std::cerr << s.error() << '\n';
//   doc->save("edited.json");
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/io/scene_file.hpp>

#include <deque>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace dmedit {

/// The scene being edited; see the file comment.
class SceneDocument {
 public:
  /// Reads and validates `file` (dm::readScene: every problem reported).
  static dm::Result<SceneDocument> open(const std::filesystem::path& file);
  /// A document over an already parsed scene, saved to `file` by save().
  SceneDocument(dm::SceneDesc scene, std::filesystem::path file);

  const dm::SceneDesc& scene() const noexcept { return scene_; }
  const std::filesystem::path& file() const noexcept { return file_; }
  /// Edited since the last open() or save().
  bool dirty() const noexcept { return dirty_; }
  /// Counts edits applied since open() (undo and redo count too): the UI
  /// re-uploads what changed when it moves.
  unsigned revision() const noexcept { return revision_; }

  /// Replaces the object of the same name (pose, scale, material, flags).
  /// NotFound when there is none; the reader's error when the result is not
  /// a valid scene.
  dm::Status setObject(const dm::SceneObject& object);
  /// Adds an object (its name unused, its mesh an existing mesh, isosurface
  /// or shape resource).
  dm::Status addObject(const dm::SceneObject& object);
  /// Removes an object; refused (with the path that still names it) when an
  /// engine or camera refers to it.
  dm::Status removeObject(std::string_view name);
  /// Replaces the material of the same name (colours, shading, haptics).
  dm::Status setMaterial(const dm::SceneMaterial& material);
  /// Replaces the volume view of the same name (mode, transfer function,
  /// slice, visibility).
  dm::Status setVolume(const dm::SceneVolume& volume);
  /// Replaces the light at `index`.
  dm::Status setLight(std::size_t index, const dm::SceneLight& light);

  /// Steps back / forward through the edits; false when there is nothing.
  bool undo();
  bool redo();
  bool canUndo() const noexcept { return !undo_.empty(); }
  bool canRedo() const noexcept { return !redo_.empty(); }

  /// Writes the scene to `file` (default: file()) atomically, as
  /// dm::toJson formats it. Relative file sources are rewritten to absolute
  /// paths when the scene moves to another directory, so it still loads.
  /// Then file() is `file` and the document is clean.
  dm::Status save(const std::filesystem::path& file = {});
  /// The document as the scene file it would save.
  std::string text() const;

 private:
  dm::Status apply(dm::SceneDesc next);
  // Replaces the entry of (scene.*items) named item.name; NotFound otherwise.
  template <class T>
  dm::Status replaceNamed(std::vector<T> dm::SceneDesc::*items, const T& item, const char* what, const char* where);
  dm::SceneDesc scene_;
  std::filesystem::path file_;
  std::deque<dm::SceneDesc> undo_, redo_;
  bool dirty_ = false;
  unsigned revision_ = 0;
};

}  // namespace dmedit
