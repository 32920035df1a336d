// dm/io/recorder.hpp — recording device streams to a crash-safe file, and
// reading them back.
//
// A recording is append-only (format in DMIO/drivers/record_format.hpp): a
// header with free-form metadata, then self-delimiting records (type, time,
// payload) each with a CRC-32. A reader keeps every complete record and
// stops at the first incomplete or corrupt one, so a writer killed with
// SIGKILL leaves a file whose every complete record replays; the error
// names the byte offset where the damaged tail starts.
//
// DeviceRecorder::push() is real-time safe (no allocation, lock, syscall):
// it copies the record into a fixed queue that a writer thread drains into
// the file with whole-record write(2) calls within about a millisecond. A
// kill therefore loses only the records still queued and the one being
// written. append() writes one record synchronously (not real-time).
// The "replay-haptic" driver (dm/io/drivers.hpp) plays a recording back as a
// haptic device at the recorded or a scaled rate.
//
// @code
//   auto rec = dm::DeviceRecorder::create("stylus.dmrec", {.metadata = R"({"device":"stylus"})"});
//   if (!rec) return rec.error();
//   (*rec)->pushHapticState(device.state());   // haptic loop, every tick
//   (*rec)->close();                           // flush and check for write errors
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/io/haptic_device.hpp>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

namespace dm {

/// Record types written by DMPlatform; user types start at 1000.
enum class RecordType : std::uint16_t { HapticState = 1, HapticOutput = 2, FirstUser = 1000 };

struct RecorderOptions {
  std::string metadata;    ///< stored in the header (e.g. JSON describing the device)
  bool overwrite = false;  ///< false: fail if the file exists
};

/// Writes a recording; see the file comment.
class DeviceRecorder {
 public:
  /// Largest payload push() takes; append() takes up to 1 MiB.
  static constexpr std::size_t kMaxQueuedPayload = 256;
  /// Records the queue holds before push() drops.
  static constexpr std::size_t kQueueCapacity = 8192;

  /// Creates `file` and writes the header. Fails with Io naming the file
  /// (exists without overwrite, directory missing, no permission) or
  /// InvalidArgument (metadata over 1 MiB).
  static Result<std::unique_ptr<DeviceRecorder>> create(const std::filesystem::path& file,
                                                        const RecorderOptions& options = {});
  ~DeviceRecorder();  ///< close(), ignoring its error
  DeviceRecorder(const DeviceRecorder&) = delete;
  DeviceRecorder& operator=(const DeviceRecorder&) = delete;

  /// Queues one record (one producer thread). Real-time safe. Returns false
  /// (and counts a drop) when the queue is full, the payload is larger than
  /// kMaxQueuedPayload, or the recorder is closed.
  bool push(std::uint16_t type, std::int64_t timeNs, std::span<const std::byte> payload) noexcept;
  /// push() of a haptic state (RecordType::HapticState).
  bool pushHapticState(const HapticState& state) noexcept;
  /// Writes one record now (payload ≤ 1 MiB), from any one non-real-time
  /// thread; returns after write(2). Fails with Io on a write error.
  Status append(std::uint16_t type, std::int64_t timeNs, std::span<const std::byte> payload);

  /// Drains the queue, stops the writer thread and closes the file (call it
  /// after the producer stopped pushing; later pushes are dropped). Returns
  /// the first write error (Io, naming the file), if any. Idempotent.
  Status close();

  const std::filesystem::path& path() const noexcept { return path_; }
  std::uint64_t written() const noexcept { return written_.load(std::memory_order_relaxed); }
  std::uint64_t dropped() const noexcept { return dropped_.load(std::memory_order_relaxed); }

 private:
  DeviceRecorder() = default;
  struct Slot {
    std::uint16_t type;
    std::int64_t timeNs;
    std::uint32_t size;
    std::byte payload[kMaxQueuedPayload];
  };
  void writerLoop();
  bool drain(std::vector<unsigned char>& buffer);
  bool writeAll(const unsigned char* data, std::size_t n);

  std::filesystem::path path_;
  int fd_ = -1;
  std::unique_ptr<Slot[]> slots_;
  alignas(64) std::atomic<std::size_t> head_{0};  // next slot the writer reads
  alignas(64) std::atomic<std::size_t> tail_{0};  // next slot the producer fills
  std::atomic<bool> stop_{false}, closed_{false}, failed_{false};
  std::atomic<std::uint64_t> written_{0}, dropped_{0};
  std::string writeError_;  // set by the writer thread before failed_
  std::thread writer_;
};

/// One record read back.
struct RecordedRecord {
  std::uint16_t type = 0;
  std::int64_t timeNs = 0;
  std::vector<std::byte> payload;
};

/// A recording read back: every complete record, and where a damaged tail
/// (if any) starts.
struct Recording {
  std::string metadata;
  std::vector<RecordedRecord> records;
  std::size_t validBytes = 0;  ///< bytes up to the end of the last complete record
  std::string tail;            ///< "" for a clean end, else why reading stopped (with the byte offset)
};

/// Reads a recording from memory; `name` is used in messages. Fails with
/// Parse (bad magic or header, naming the byte) — a damaged tail is not an
/// error, it is reported in Recording::tail. O(size).
Result<Recording> parseRecording(std::span<const std::uint8_t> bytes, std::string_view name = "recording");
/// Reads `file` (at most `maxBytes`, default 1 GiB). Fails with NotFound / Io
/// naming the file, or like parseRecording().
Result<Recording> readRecording(const std::filesystem::path& file, std::size_t maxBytes = std::size_t(1)
                                                                                          << 30);

/// The haptic state in a RecordType::HapticState record; Parse error when the
/// record has another type or size.
Result<HapticState> decodeHapticState(const RecordedRecord& record);

}  // namespace dm
