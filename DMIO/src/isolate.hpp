// Private to DMIO: run a third-party parser in a forked child process.
//
// Assimp 5.2 loops forever or corrupts its heap on some malformed files and
// OpenVDB allocates buffers as large as lengths read from the file, which no
// check of ours can fully prevent in-process. runIsolated() forks, runs the
// parser in the child (which streams its result back through a pipe with
// FdWriter), enforces a deadline and a memory budget, and turns a crash,
// an allocation beyond the budget or a timeout into an Error. The parent never
// shares the child's heap.
#pragma once

#include <dm/core/result.hpp>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace dm {
struct Mesh;
class Volume;
struct MeshImportOptions;
}  // namespace dm

namespace dm::detail {

/// Writes a result to the parent's pipe (in the child).
class FdWriter {
 public:
  explicit FdWriter(int fd) : fd_(fd) {}
  void bytes(const void* data, std::size_t n);
  void u64(std::uint64_t v) { bytes(&v, sizeof v); }
  void f64(double v) { bytes(&v, sizeof v); }
  void str(const std::string& s) {
    u64(s.size());
    bytes(s.data(), s.size());
  }
  template <class T, class Scalar>
  void array(const std::vector<T>& v) {
    u64(v.size());
    if (!v.empty()) bytes(reinterpret_cast<const Scalar*>(v.data()), v.size() * sizeof(T));
  }
  /// An Error as code, what, where, hint.
  void error(const Error& e);
  bool ok() const { return ok_; }

 private:
  int fd_;
  bool ok_ = true;
};

/// Reads what FdWriter wrote, bounds-checked (in the parent).
class ByteReader {
 public:
  explicit ByteReader(const std::vector<char>& buf) : p_(buf.data()), end_(buf.data() + buf.size()) {}
  bool bytes(void* out, std::size_t n);
  std::uint64_t u64() {
    std::uint64_t v = 0;
    bytes(&v, sizeof v);
    return v;
  }
  double f64() {
    double v = 0;
    bytes(&v, sizeof v);
    return v;
  }
  std::string str();
  template <class T>
  void array(std::vector<T>& v) {
    const std::uint64_t n = u64();
    if (!ok_ || n > remaining() / sizeof(T)) {
      ok_ = false;
      return;
    }
    v.resize(static_cast<std::size_t>(n));
    if (n > 0) bytes(static_cast<void*>(v.data()), static_cast<std::size_t>(n) * sizeof(T));
  }
  /// An Error written by FdWriter::error().
  Error error();
  std::size_t remaining() const { return static_cast<std::size_t>(end_ - p_); }
  bool ok() const { return ok_; }
  /// For a reader that found a field out of range itself.
  void markBroken() { ok_ = false; }

 private:
  const char* p_;
  const char* end_;
  bool ok_ = true;
};

struct IsolateOptions {
  std::string library;        ///< "Assimp", "OpenVDB": named in the messages
  double timeoutSeconds = 0;  ///< 0: no deadline
  /// Bytes the child may allocate beyond what it held at fork; 0: no limit.
  /// Enforced with RLIMIT_AS, or under AddressSanitizer and ThreadSanitizer
  /// (whose shadow memory needs the address space) with allocator hooks
  /// counting heap bytes. Exceeding it fails with Unsupported.
  std::size_t memoryBudget = 0;
  std::string disableHint;  ///< how to choose another isolation, for spawn/fork/pipe failures
  std::string crashHint;    ///< what a crash means for the user
  std::string timeoutHint;  ///< what a timeout means for the user
  std::string budgetHint;   ///< what exceeding the memory budget means for the user
};

/// What the child sent, and how it ended ("exit status 0", ...).
struct IsolatedRun {
  std::vector<char> bytes;
  std::string exitInfo;
};

/// Runs `child` in a forked process; it must write its whole result through
/// the FdWriter and must not log (another thread may have held the logger's
/// lock at fork). Fails with Timeout, Parse (the child died by a signal: a
/// crash), Unsupported (the child exceeded the memory budget) or Io (no
/// pipe, no fork).
Result<IsolatedRun> runIsolated(const std::function<void(FdWriter&)>& child, const IsolateOptions& options,
                                const std::string& where);

/// Runs `job` in the dm-isolate helper program: `writeRequest` writes the
/// request (into a sealed memory file, the job's standard input), the
/// helper runs the job with the deadline and memory budget of `options` and
/// the job writes its result to a pipe. The helper is started once per
/// process (posix_spawn: a fresh program, nothing of the caller's threads
/// or locks) and serves every job after that from a forked child of its own
/// single thread (isolate_helper.cpp). Fails like runIsolated(), and with
/// NotFound when there is no helper program (naming where it looked),
/// Internal when the helper does not know the job (a helper of another
/// version).
Result<IsolatedRun> runHelper(const char* job, const std::function<void(FdWriter&)>& writeRequest,
                              const IsolateOptions& options, const std::string& where);

/// The helper program's path (dm/io/isolation.hpp says where it is looked
/// for), or NotFound naming the places.
Result<std::string> helperProgram();

/// A job of the helper: reads its request, writes its result. It runs in a
/// forked child of the helper's single thread, so it may start threads, but
/// must not write to stdout.
using HelperJob = void (*)(ByteReader& request, FdWriter& result);
struct HelperJobEntry {
  const char* name;
  HelperJob run;
  /// Run once when the helper starts, before it serves (and before it ends
  /// the libraries' threads): what every job would otherwise do again in
  /// its child, such as registering OpenVDB's grid types. May be null.
  void (*prepare)() = nullptr;
};

/// The helper's main(): `dm-isolate --serve`, started by runHelper() with its
/// control socket on fd 3; serves jobs until the socket closes (the caller's
/// process ended). Run by hand it prints what it is for and returns 2.
int helperMain(int argc, char** argv, const HelperJobEntry* jobs, std::size_t jobCount);

/// The caller's reading of an isolated import's result bytes, as a reader
/// does after the helper or child ended cleanly, for
/// Tests/fuzz/isolate_result_fuzz.cpp: a process whose heap a parser
/// corrupted may still end cleanly with garbage, so every length, index and
/// value is checked before use (Internal when the bytes are no result).
Result<std::vector<Mesh>> meshesFromResult(const std::vector<char>& bytes, const MeshImportOptions& options,
                                           bool merge, const std::string& where);  // mesh_io.cpp
Result<Volume> volumeFromResult(const std::vector<char>& bytes, std::size_t maxBytes,
                                const std::string& where);  // vdb.cpp

/// The jobs DMIO's readers hand the helper (defined beside each reader).
void assimpImportJob(ByteReader& request, FdWriter& result);  // mesh_io.cpp
void openVdbParseJob(ByteReader& request, FdWriter& result);  // vdb.cpp
void prepareOpenVdb();                                         // vdb.cpp

// Shared by both modes (isolate.cpp).

/// Caps what this process (a child) may allocate from now on at `budget`
/// bytes (0: no cap): RLIMIT_AS, or allocator hooks under the sanitizers.
/// Beyond it the process exits with the over-budget status.
void limitMemory(std::size_t budget);

/// How the caller ends and reaps the other process.
struct ChildControl {
  std::function<void()> kill;
  std::function<std::optional<int>()> wait;  ///< its wait status; nullopt: unknown
};

/// The caller's side of both modes: reads the result from `readFd` (and
/// closes it) until its end or the deadline, ends (at the deadline) and
/// reaps the other process and turns how it ended into an Error or the run.
Result<IsolatedRun> collectChild(const ChildControl& child, int readFd, const IsolateOptions& options,
                                 const std::string& where);

}  // namespace dm::detail
