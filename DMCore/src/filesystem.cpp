#include <dm/core/filesystem.hpp>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <thread>

namespace dm {

namespace fs = std::filesystem;

namespace {

// "a:b::c" -> {a, b, c}; null -> {}.
std::vector<fs::path> splitPathList(const char* list) {
  std::vector<fs::path> out;
  if (list == nullptr) return out;
  const std::string s(list);
  std::size_t start = 0;
  while (start <= s.size()) {
    const std::size_t end = std::min(s.find(':', start), s.size());
    if (end > start) out.emplace_back(s.substr(start, end - start));
    start = end + 1;
  }
  return out;
}

}  // namespace

FileSystem::FileSystem() {
  mounts_ = {
      {"mricron", "/usr/share/mricron/templates", "mricron-data"},
      {"assimp", "/usr/share/assimp/models", "assimp-testmodels"},
      {"opencv", "/usr/share/doc/opencv-doc/examples/data", "opencv-doc"},
      {"haar", "/usr/share/opencv4/haarcascades", "opencv-data"},
  };
  searchPaths_ = splitPathList(std::getenv("DM_DATA_PATH"));
  allowedRoots_ = splitPathList(std::getenv("DM_ALLOW_PATH"));
}

FileSystem& FileSystem::global() {
  static FileSystem fsys;
  return fsys;
}

Status FileSystem::mount(const std::string& name, const fs::path& dir, std::string package) {
  if (name.size() < 2 || name.find_first_of(":/\\") != std::string::npos)
    return fail(ErrorCode::InvalidArgument,
                "mount name '" + name + "' must be 2+ characters without ':' or '/'", "FileSystem::mount");
  std::lock_guard lock(mutex_);
  auto it = std::find_if(mounts_.begin(), mounts_.end(), [&](const Mount& m) { return m.name == name; });
  if (it != mounts_.end())
    *it = {name, dir, std::move(package)};
  else
    mounts_.push_back({name, dir, std::move(package)});
  return ok();
}

void FileSystem::unmount(const std::string& name) {
  std::lock_guard lock(mutex_);
  std::erase_if(mounts_, [&](const Mount& m) { return m.name == name; });
}

void FileSystem::addSearchPath(const fs::path& dir) {
  std::lock_guard lock(mutex_);
  searchPaths_.push_back(dir);
}

void FileSystem::allowRoot(const fs::path& dir) {
  std::lock_guard lock(mutex_);
  allowedRoots_.push_back(dir);
}

void FileSystem::disallowRoot(const fs::path& dir) {
  std::lock_guard lock(mutex_);
  std::erase(allowedRoots_, dir);
}

std::vector<fs::path> FileSystem::searchPaths() const {
  std::lock_guard lock(mutex_);
  return searchPaths_;
}

Result<fs::path> FileSystem::resolve(std::string_view name) const {
  if (name.empty()) return fail(ErrorCode::InvalidArgument, "empty file name", "FileSystem::resolve");
  std::error_code ec;
  const fs::path direct(name);
  if (fs::exists(direct, ec)) return direct;
  std::lock_guard lock(mutex_);
  const std::size_t colon = name.find(':');
  if (colon != std::string_view::npos && colon >= 2) {
    const std::string mountName(name.substr(0, colon));
    const std::string rest(name.substr(colon + 1));
    for (const Mount& m : mounts_) {
      if (m.name != mountName) continue;
      const fs::path p = m.dir / rest;
      if (fs::exists(p, ec)) return p;
      std::string hint = "check the name";
      if (!fs::exists(m.dir, ec) && !m.package.empty())
        hint = "the mount directory " + m.dir.string() + " is missing: install the Debian package " +
               m.package + " (scripts/setup.sh does)";
      return fail(ErrorCode::NotFound, "no file " + p.string(), std::string(name), hint);
    }
    std::string known;
    for (const Mount& m : mounts_) known += (known.empty() ? "" : ", ") + m.name + ":";
    return fail(ErrorCode::NotFound, "unknown mount '" + mountName + ":'", std::string(name),
                "known mounts: " + known);
  }
  std::string tried = fs::absolute(direct, ec).string();
  if (direct.is_relative()) {
    for (const fs::path& dir : searchPaths_) {
      const fs::path p = dir / direct;
      if (fs::exists(p, ec)) return p;
      tried += ", " + p.string();
    }
  }
  return fail(ErrorCode::NotFound, "file not found (tried " + tried + ")", std::string(name),
              "check the path, or add a directory to DM_DATA_PATH");
}

Result<std::vector<std::byte>> readFile(const fs::path& file, std::size_t maxBytes) {
  std::FILE* f = std::fopen(file.c_str(), "rb");
  if (!f)
    return fail(ErrorCode::NotFound, std::string("cannot open: ") + std::strerror(errno), file.string());
  std::vector<std::byte> out;
  // A regular file's size is known before a byte is read: one over the
  // limit is refused with its size, without allocating for it.
  struct stat st {};
  if (::fstat(::fileno(f), &st) == 0 && S_ISREG(st.st_mode)) {
    const auto size = static_cast<std::uint64_t>(st.st_size);
    if (size > maxBytes) {
      std::fclose(f);
      return fail(ErrorCode::InvalidArgument,
                  "file is " + std::to_string(size) + " bytes, more than the limit of " +
                      std::to_string(maxBytes) + " bytes",
                  file.string());
    }
    out.reserve(static_cast<std::size_t>(size));
  }
  std::byte buf[1 << 16];
  for (;;) {
    const std::size_t n = std::fread(buf, 1, sizeof buf, f);
    if (out.size() + n > maxBytes) {  // a pipe, or a file that grew
      std::fclose(f);
      return fail(ErrorCode::InvalidArgument,
                  "file is larger than the limit of " + std::to_string(maxBytes) + " bytes", file.string());
    }
    out.insert(out.end(), buf, buf + n);
    if (n < sizeof buf) break;
  }
  const bool bad = std::ferror(f) != 0;
  std::fclose(f);
  if (bad) return fail(ErrorCode::Io, "read failed at byte " + std::to_string(out.size()), file.string());
  return out;
}

Status writeFileAtomic(const fs::path& file, const void* bytes, std::size_t size) {
  const fs::path tmp = file.string() + ".tmp" + std::to_string(::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return fail(ErrorCode::Io, std::string("cannot create: ") + std::strerror(errno), tmp.string());
  const auto* p = static_cast<const char*>(bytes);
  std::size_t done = 0;
  while (done < size) {
    const ssize_t n = ::write(fd, p + done, size - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(fd);
      ::unlink(tmp.c_str());
      return fail(ErrorCode::Io, std::string("write failed: ") + std::strerror(err), file.string(),
                  "check free disk space");
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    ::unlink(tmp.c_str());
    return fail(ErrorCode::Io, "fsync/close failed", file.string());
  }
  if (::rename(tmp.c_str(), file.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    return fail(ErrorCode::Io, std::string("rename failed: ") + std::strerror(err), file.string());
  }
  return ok();
}

struct FileStreamReader::Impl {
  std::string path;
  int fd = -1;
  std::uint64_t size = 0;
  std::size_t chunkBytes = 0;
  std::size_t maxQueued = 0;
  std::mutex m;
  std::condition_variable cv;
  std::deque<Result<Chunk>> queue;
  bool cancelled = false;
  bool finished = false;  // producer pushed its last item
  std::thread thread;

  void run() {
    std::uint64_t offset = 0;
    for (;;) {
      {
        std::unique_lock lock(m);
        cv.wait(lock, [&] { return cancelled || queue.size() < maxQueued; });
        if (cancelled) break;
      }
      Chunk c;
      c.offset = offset;
      c.data.resize(static_cast<std::size_t>(std::min<std::uint64_t>(chunkBytes, size - offset)));
      std::size_t got = 0;
      bool error = false;
      while (got < c.data.size()) {
        const ssize_t n =
            ::pread(fd, c.data.data() + got, c.data.size() - got, static_cast<off_t>(offset + got));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
          error = true;
          break;
        }
        got += static_cast<std::size_t>(n);
      }
      std::lock_guard lock(m);
      if (error) {
        queue.emplace_back(fail(ErrorCode::Io, "read failed at byte " + std::to_string(offset + got), path,
                                "the file may have been truncated while streaming"));
        break;
      }
      offset += c.data.size();
      const bool last = c.data.empty();
      queue.emplace_back(std::move(c));
      cv.notify_all();
      if (last) break;
    }
    std::lock_guard lock(m);
    finished = true;
    cv.notify_all();
  }
};

FileStreamReader::FileStreamReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Result<std::unique_ptr<FileStreamReader>> FileStreamReader::open(const fs::path& file, std::size_t chunkBytes,
                                                                 std::size_t maxQueued) {
  if (chunkBytes == 0 || maxQueued == 0)
    return fail(ErrorCode::InvalidArgument, "chunkBytes and maxQueued must be positive", file.string());
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0)
    return fail(ErrorCode::NotFound, std::string("cannot open: ") + std::strerror(errno), file.string());
  auto impl = std::make_unique<Impl>();
  impl->path = file.string();
  impl->fd = fd;
  std::error_code ec;
  impl->size = fs::file_size(file, ec);
  if (ec) {
    ::close(fd);
    return fail(ErrorCode::Io, "cannot stat: " + ec.message(), file.string());
  }
  impl->chunkBytes = chunkBytes;
  impl->maxQueued = maxQueued;
  Impl* raw = impl.get();
  raw->thread = std::thread([raw] { raw->run(); });
  return std::unique_ptr<FileStreamReader>(new FileStreamReader(std::move(impl)));
}

FileStreamReader::~FileStreamReader() {
  cancel();
  if (impl_->thread.joinable()) impl_->thread.join();
  ::close(impl_->fd);
}

void FileStreamReader::cancel() {
  std::lock_guard lock(impl_->m);
  impl_->cancelled = true;
  impl_->cv.notify_all();
}

std::uint64_t FileStreamReader::fileSize() const { return impl_->size; }

std::optional<Result<FileStreamReader::Chunk>> FileStreamReader::tryNext() {
  std::lock_guard lock(impl_->m);
  if (impl_->queue.empty()) {
    if (impl_->finished || impl_->cancelled) return Result<Chunk>(Chunk{impl_->size, {}});
    return std::nullopt;
  }
  Result<Chunk> r = std::move(impl_->queue.front());
  impl_->queue.pop_front();
  impl_->cv.notify_all();
  return r;
}

Result<FileStreamReader::Chunk> FileStreamReader::next(std::chrono::milliseconds timeout) {
  std::unique_lock lock(impl_->m);
  if (!impl_->cv.wait_for(lock, timeout,
                          [&] { return !impl_->queue.empty() || impl_->finished || impl_->cancelled; }))
    return fail(ErrorCode::Timeout, "no chunk within " + std::to_string(timeout.count()) + " ms",
                impl_->path);
  if (impl_->queue.empty()) return Chunk{impl_->size, {}};
  Result<Chunk> r = std::move(impl_->queue.front());
  impl_->queue.pop_front();
  impl_->cv.notify_all();
  return r;
}

}  // namespace dm
