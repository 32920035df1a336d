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
// Typed pushes and decoders cover every device stream: haptic states,
// controller states, DAQ frames and sensor readings. The replay drivers
// "replay-haptic", "replay-controller", "replay-daq" and "replay-sensor"
// (dm/io/drivers.hpp) play a recording back as that device at the recorded
// or a scaled rate.
//
// @code
//   auto rec = dm::DeviceRecorder::create("stylus.dmrec", {.metadata = R"({"device":"stylus"})"});
//   if (!rec) return rec.error();
//   (*rec)->pushHapticState(device.state());   // haptic loop, every tick
//   (*rec)->close();                           // flush and check for write errors
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/io/controller.hpp>
#include <dm/io/daq.hpp>
#include <dm/io/haptic_device.hpp>
#include <dm/io/sensor.hpp>

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
enum class RecordType : std::uint16_t {
  HapticState = 1,      ///< pushHapticState / decodeHapticState
  HapticOutput = 2,     ///< force and torque sent (reserved)
  ControllerState = 3,  ///< pushControllerState / decodeControllerState
  DaqBlock = 4,         ///< pushDaqFrames / decodeDaqBlock
  SensorReading = 5,    ///< pushSensorReading / decodeSensorReading
  FirstUser = 1000
};

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
  /// True when push() would not have to wait (producer thread): a free
  /// queue slot, or a closed or failed recorder, which never drains again
  /// (push() then drops and counts; close() reports the write error). A
  /// producer that may wait (a lockstep run, faster than the disk) yields
  /// until then instead of dropping. Real-time safe.
  bool hasRoom() const noexcept;
  /// push() of a haptic state (RecordType::HapticState).
  bool pushHapticState(const HapticState& state) noexcept;
  /// push() of a controller state (RecordType::ControllerState, 64 bytes:
  /// six axes and 128 buttons; the record time is state.timeNs).
  bool pushControllerState(const ControllerState& state) noexcept;
  /// push() of DAQ frames of `channelCount` (1..16) channels as
  /// RecordType::DaqBlock records, split into as many records as a queue
  /// slot needs (5 frames of 4 channels per record, 1 of 16); each record's
  /// time is its first frame's. `overrunFrames` (e.g. DaqReadResult::
  /// overrunFrames) is stored with the first frame: with no frames it is not
  /// recorded, so add it to the next call. Returns the frames queued (fewer
  /// than frames.size() when the queue filled, 0 for a bad channel count).
  /// Real-time safe. O(frames).
  std::size_t pushDaqFrames(std::span<const DaqFrame> frames, std::uint32_t channelCount,
                            std::uint64_t overrunFrames = 0) noexcept;
  /// push() of a sensor reading (RecordType::SensorReading, 64 bytes: the
  /// type and seven values; the record time is reading.timeNs).
  bool pushSensorReading(const SensorReading& reading) noexcept;
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
  std::size_t index = 0;   ///< position in the recording (0-based), for messages
  std::size_t offset = 0;  ///< byte offset of the record in the file, for messages
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

/// The haptic state in a RecordType::HapticState record; Parse error naming
/// the record index and byte offset when the record has another type or size.
Result<HapticState> decodeHapticState(const RecordedRecord& record);

/// The controller state in a RecordType::ControllerState record. Parse
/// error naming the record index and byte offset when the record has
/// another type or size or an axis outside [-1, 1] (or NaN).
/// @code
///   auto rec = dm::readRecording("pedal.dmrec");
///   for (const dm::RecordedRecord& r : rec->records)
///     if (auto s = dm::decodeControllerState(r)) states.push_back(*s);  // other types fail
/// @endcode
Result<ControllerState> decodeControllerState(const RecordedRecord& record);

/// The frames of one RecordType::DaqBlock record.
struct RecordedDaqBlock {
  std::uint32_t channelCount = 0;   ///< 1..16; values beyond it are 0
  std::uint64_t overrunFrames = 0;  ///< frames lost just before frames[0]
  std::vector<DaqFrame> frames;     ///< ≥ 1, indices increasing, times not decreasing
};
/// The DAQ frames in a RecordType::DaqBlock record. Parse error naming the
/// record index and byte offset (and the payload byte) when the type, the
/// channel or frame count, the size, the index or time order or a sample
/// (NaN/Inf) is wrong. O(payload).
Result<RecordedDaqBlock> decodeDaqBlock(const RecordedRecord& record);

/// The sensor reading in a RecordType::SensorReading record. Parse error
/// naming the record index and byte offset when the type or size, the
/// reading type (not 0..3) or a value (NaN/Inf) is wrong.
Result<SensorReading> decodeSensorReading(const RecordedRecord& record);

}  // namespace dm
