// dm/core/filesystem.hpp — mount points, search paths and streaming reads.
//
// Names resolve in this order: an existing absolute or relative path; a
// mounted name "mount:rest/of/path"; then each search path in order. The
// default mounts point at the Debian data packages (shared/DATA.md):
//   mricron:  /usr/share/mricron/templates        (package mricron-data)
//   assimp:   /usr/share/assimp/models            (package assimp-testmodels)
//   opencv:   /usr/share/doc/opencv-doc/examples/data (package opencv-doc)
//   haar:     /usr/share/opencv4/haarcascades     (package opencv-data)
// and the environment variable DM_DATA_PATH (colon-separated) adds search
// paths. A failed lookup lists every place it tried and, for a default mount,
// the package to install.
//
// Confinement: a file named *inside* another file (a MetaImage header's
// ElementDataFile, an NRRD header's data file, a scene's resource source, a
// file of a DICOM series folder) comes from whoever wrote that file, so
// confine() lets it lead only into an allowed root, after every symlink is
// resolved: the referring file's own folder, the mounts, the search paths
// (DM_DATA_PATH) and the roots allowed explicitly, by DM_ALLOW_PATH
// (colon-separated) or allowRoot(). Anything else, "..", an absolute path, a
// symlink that leaves the roots, a NUL byte or a reference longer than
// kMaxReferenceBytes, is refused with ErrorCode::Denied before a byte of it
// is read; the error names the field and how to allow the folder. Paths a
// program passes in itself are not confined: they are the user's choice.
//
// FileStreamReader reads a large file on a background thread in chunks, so
// the caller polls without blocking (tryNext) or waits with a timeout.
//
// @code
//   auto path = dm::FileSystem::global().resolve("mricron:ch2.nii.gz");
//   auto reader = dm::FileStreamReader::open(*path, 1 << 20);
//   while (auto chunk = (*reader)->next()) { if (chunk->data.empty()) break; consume(*chunk); }
// @endcode
#pragma once

#include <dm/core/result.hpp>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

class FileSystem {
 public:
  /// A file system with the default mounts and DM_DATA_PATH search paths.
  FileSystem();
  /// The process-wide instance used by importers and the resource manager.
  static FileSystem& global();

  /// Maps "name:" to `dir`. Fails on an empty or malformed name. Thread-safe.
  Status mount(const std::string& name, const std::filesystem::path& dir, std::string package = {});
  void unmount(const std::string& name);
  /// Appends a directory searched for bare relative names.
  void addSearchPath(const std::filesystem::path& dir);
  std::vector<std::filesystem::path> searchPaths() const;

  /// Resolves `name` to an existing file or directory (see header comment).
  Result<std::filesystem::path> resolve(std::string_view name) const;

  /// Longest file reference confine() accepts, in bytes (PATH_MAX - 1).
  static constexpr std::size_t kMaxReferenceBytes = 4095;
  /// Allows files under `dir` (and its subfolders) as references from any
  /// file; DM_ALLOW_PATH does the same from the environment. Thread-safe.
  void allowRoot(const std::filesystem::path& dir);
  /// Takes back allowRoot(dir) (every entry equal to `dir`). Thread-safe.
  void disallowRoot(const std::filesystem::path& dir);
  /// The folders references may lead into from a file in `folder`: that
  /// folder, the mounts, the search paths and the allowed roots, each with
  /// its symlinks resolved as far as it exists.
  std::vector<std::filesystem::path> allowedRoots(const std::filesystem::path& folder) const;
  /// Resolves `reference`, written in `field` of a file in `folder` (relative
  /// references are taken from that folder), to a path without symlinks that
  /// lies in one of allowedRoots(folder); Denied otherwise (see the header
  /// comment). The file need not exist: reading it reports that.
  Result<std::filesystem::path> confine(const std::filesystem::path& folder, std::string_view reference,
                                        std::string_view field) const;

 private:
  struct Mount {
    std::string name;
    std::filesystem::path dir;
    std::string package;  ///< Debian package that provides it, for the hint
  };
  mutable std::mutex mutex_;
  std::vector<Mount> mounts_;
  std::vector<std::filesystem::path> searchPaths_;
  std::vector<std::filesystem::path> allowedRoots_;  ///< DM_ALLOW_PATH and allowRoot()
};

/// Reads a whole file; fails if it is missing, unreadable or larger than
/// `maxBytes` (default 4 GiB) — errors name the file.
Result<std::vector<std::byte>> readFile(const std::filesystem::path& file,
                                        std::size_t maxBytes = std::size_t{1} << 32);

/// Writes `bytes` to `file` atomically: a temporary file in the same
/// directory, fsync, then rename — readers never see a partial file.
Status writeFileAtomic(const std::filesystem::path& file, const void* bytes, std::size_t size);

/// Streams a file in chunks from a background thread.
class FileStreamReader {
 public:
  struct Chunk {
    std::uint64_t offset = 0;     ///< byte offset of data[0] in the file
    std::vector<std::byte> data;  ///< empty marks the end of the file
  };

  /// Opens `file` and starts reading ahead up to `maxQueued` chunks of
  /// `chunkBytes`. Fails if the file cannot be opened.
  static Result<std::unique_ptr<FileStreamReader>> open(const std::filesystem::path& file,
                                                        std::size_t chunkBytes = std::size_t{1} << 20,
                                                        std::size_t maxQueued = 4);
  ~FileStreamReader();
  FileStreamReader(const FileStreamReader&) = delete;
  FileStreamReader& operator=(const FileStreamReader&) = delete;

  /// A ready chunk, or nullopt if none is ready yet. Never blocks.
  /// Returns an error once if a read fails (naming file and offset).
  std::optional<Result<Chunk>> tryNext();
  /// Waits up to `timeout` for the next chunk; a Timeout error if none came.
  Result<Chunk> next(std::chrono::milliseconds timeout = std::chrono::milliseconds(10000));

  std::uint64_t fileSize() const;
  /// Stops the background thread early; later calls see the end.
  void cancel();

 private:
  struct Impl;
  explicit FileStreamReader(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
