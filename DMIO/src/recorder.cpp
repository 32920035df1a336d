// DeviceRecorder (queue + writer thread + whole-record writes) and the
// recording reader; the byte format is DMIO/drivers/record_format.hpp.
#include <dm/core/filesystem.hpp>
#include <dm/io/recorder.hpp>

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>

#include "../drivers/record_format.hpp"

namespace dm {

namespace {

std::string errnoText() { return std::strerror(errno); }

void encodeHapticState(const HapticState& s, unsigned char* out) noexcept {
  const double v[13] = {s.position.x(),       s.position.y(),        s.position.z(),
                        s.orientation.w(),    s.orientation.x(),     s.orientation.y(),
                        s.orientation.z(),    s.linearVelocity.x(),  s.linearVelocity.y(),
                        s.linearVelocity.z(), s.angularVelocity.x(), s.angularVelocity.y(),
                        s.angularVelocity.z()};
  record::encodeDoubles(out, v, 13);
  record::putU32(out + 8 * 13, s.buttons);
}

// A Parse error for record r: what is wrong, where (record index, byte).
Error recordError(const RecordedRecord& r, const std::string& why) {
  return fail(ErrorCode::Parse, why, record::recordPlace(r.index, r.offset),
              "the recording is damaged or was not written by DeviceRecorder");
}

// The payload of r after checking its type and size (wantSize 0: any).
Result<const unsigned char*> checkedPayload(const RecordedRecord& r, record::Type type,
                                            std::uint32_t wantSize, const char* what) {
  const std::string why = record::checkTypeAndSize(r.type, r.payload.size(), type, wantSize, what);
  if (!why.empty()) return recordError(r, why);
  return reinterpret_cast<const unsigned char*>(r.payload.data());
}

}  // namespace

Result<std::unique_ptr<DeviceRecorder>> DeviceRecorder::create(const std::filesystem::path& file,
                                                               const RecorderOptions& options) {
  if (options.metadata.size() > record::kMaxMetadata)
    return fail(ErrorCode::InvalidArgument,
                "metadata is " + std::to_string(options.metadata.size()) + " bytes", file.string(),
                "keep recording metadata under 1 MiB");
  const int flags = O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC | (options.overwrite ? O_TRUNC : O_EXCL);
  const int fd = ::open(file.c_str(), flags, 0644);
  if (fd < 0)
    return fail(
        ErrorCode::Io, "cannot create: " + errnoText(), file.string(),
        errno == EEXIST ? "choose another name or set overwrite" : "check the directory and permissions");
  std::unique_ptr<DeviceRecorder> r(new DeviceRecorder());
  r->path_ = file;
  r->fd_ = fd;
  std::vector<unsigned char> header(12 + options.metadata.size());
  std::memcpy(header.data(), record::kMagic, 8);
  record::putU32(header.data() + 8, static_cast<std::uint32_t>(options.metadata.size()));
  std::memcpy(header.data() + 12, options.metadata.data(), options.metadata.size());
  if (!r->writeAll(header.data(), header.size())) {
    const std::string why = r->writeError_;
    return fail(ErrorCode::Io, "cannot write the header: " + why, file.string());
  }
  r->slots_.reset(new Slot[kQueueCapacity]);
  r->writer_ = std::thread([p = r.get()] { p->writerLoop(); });
  return r;
}

DeviceRecorder::~DeviceRecorder() { (void)close(); }

bool DeviceRecorder::push(std::uint16_t type, std::int64_t timeNs,
                          std::span<const std::byte> payload) noexcept {
  const std::size_t tail = tail_.load(std::memory_order_relaxed);
  if (payload.size() > kMaxQueuedPayload || closed_.load(std::memory_order_relaxed) ||
      tail - head_.load(std::memory_order_acquire) >= kQueueCapacity) {
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  Slot& s = slots_[tail % kQueueCapacity];
  s.type = type;
  s.timeNs = timeNs;
  s.size = static_cast<std::uint32_t>(payload.size());
  if (!payload.empty()) std::memcpy(s.payload, payload.data(), payload.size());
  tail_.store(tail + 1, std::memory_order_release);
  return true;
}

bool DeviceRecorder::hasRoom() const noexcept {
  // A closed or failed recorder never drains again: no use waiting (push()
  // drops and counts, close() reports the write error).
  if (closed_.load(std::memory_order_relaxed) || failed_.load(std::memory_order_acquire)) return true;
  return tail_.load(std::memory_order_relaxed) - head_.load(std::memory_order_acquire) < kQueueCapacity;
}

bool DeviceRecorder::pushHapticState(const HapticState& state) noexcept {
  unsigned char bytes[record::kHapticStateBytes];
  encodeHapticState(state, bytes);
  return push(static_cast<std::uint16_t>(RecordType::HapticState), state.timeNs,
              std::as_bytes(std::span<const unsigned char>(bytes)));
}

bool DeviceRecorder::pushControllerState(const ControllerState& state) noexcept {
  std::uint64_t buttons[2] = {0, 0};
  for (std::size_t i = 0; i < kControllerButtons; ++i)
    if (state.buttons.test(i)) buttons[i / 64] |= std::uint64_t(1) << (i % 64);
  unsigned char bytes[record::kControllerStateBytes];
  record::encodeControllerState(bytes, state.axes.data(), buttons);
  return push(record::kControllerState, state.timeNs, std::as_bytes(std::span<const unsigned char>(bytes)));
}

std::size_t DeviceRecorder::pushDaqFrames(std::span<const DaqFrame> frames, std::uint32_t channelCount,
                                          std::uint64_t overrunFrames) noexcept {
  if (channelCount < 1 || channelCount > kDaqMaxChannels) {
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return 0;
  }
  const std::uint32_t frameBytes = record::daqFrameBytes(channelCount);
  const std::size_t perRecord = (kMaxQueuedPayload - record::kDaqBlockHeaderBytes) / frameBytes;
  unsigned char bytes[kMaxQueuedPayload];
  std::size_t done = 0;
  while (done < frames.size()) {
    const std::size_t n = std::min(perRecord, frames.size() - done);
    record::encodeDaqBlockHeader(bytes, channelCount, static_cast<std::uint32_t>(n),
                                 done == 0 ? overrunFrames : 0);
    for (std::size_t f = 0; f < n; ++f) {
      const DaqFrame& fr = frames[done + f];
      record::encodeDaqFrame(bytes + record::kDaqBlockHeaderBytes + f * frameBytes, fr.timeNs, fr.index,
                             fr.values.data(), channelCount);
    }
    const std::size_t size = record::kDaqBlockHeaderBytes + n * frameBytes;
    if (!push(record::kDaqBlock, frames[done].timeNs,
              std::as_bytes(std::span<const unsigned char>(bytes, size))))
      break;
    done += n;
  }
  return done;
}

bool DeviceRecorder::pushSensorReading(const SensorReading& reading) noexcept {
  unsigned char bytes[record::kSensorReadingBytes];
  record::encodeSensorReading(bytes, static_cast<std::uint32_t>(reading.type), reading.values.data());
  return push(record::kSensorReading, reading.timeNs, std::as_bytes(std::span<const unsigned char>(bytes)));
}

bool DeviceRecorder::writeAll(const unsigned char* data, std::size_t n) {
  while (n > 0) {
    const ssize_t w = ::write(fd_, data, n);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) {
      writeError_ = w < 0 ? errnoText() : "write returned 0";
      return false;
    }
    data += w;
    n -= static_cast<std::size_t>(w);
  }
  return true;
}

// Writes every queued record, in batches of whole records up to ~64 KiB.
bool DeviceRecorder::drain(std::vector<unsigned char>& buffer) {
  const std::size_t tail = tail_.load(std::memory_order_acquire);
  std::size_t head = head_.load(std::memory_order_relaxed);
  while (head != tail) {
    buffer.clear();
    std::size_t batch = 0;
    for (; head != tail && buffer.size() < (1u << 16); ++head, ++batch) {
      const Slot& s = slots_[head % kQueueCapacity];
      const std::size_t at = buffer.size();
      buffer.resize(at + record::kRecordHeaderBytes + s.size);
      std::memcpy(buffer.data() + at + record::kRecordHeaderBytes, s.payload, s.size);
      record::encodeRecordHeader(buffer.data() + at, s.type, s.timeNs, s.payload, s.size);
    }
    head_.store(head, std::memory_order_release);  // copied: the producer may reuse the slots
    if (!writeAll(buffer.data(), buffer.size())) return false;
    written_.fetch_add(batch, std::memory_order_relaxed);
  }
  return true;
}

void DeviceRecorder::writerLoop() {
  std::vector<unsigned char> buffer;
  buffer.reserve((1u << 16) + record::kRecordHeaderBytes + kMaxQueuedPayload);
  while (true) {
    const bool stopping = stop_.load(std::memory_order_acquire);
    if (!drain(buffer)) {
      failed_.store(true, std::memory_order_release);
      return;
    }
    if (stopping) return;  // drained after seeing stop: nothing is left behind
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
}

Status DeviceRecorder::append(std::uint16_t type, std::int64_t timeNs, std::span<const std::byte> payload) {
  if (payload.size() > record::kMaxRecordPayload)
    return fail(ErrorCode::InvalidArgument, "record payload of " + std::to_string(payload.size()) + " bytes",
                path_.string(), "split records larger than 1 MiB");
  if (closed_.load()) return fail(ErrorCode::Io, "recorder is closed", path_.string());
  std::vector<unsigned char> bytes(record::kRecordHeaderBytes + payload.size());
  if (!payload.empty())
    std::memcpy(bytes.data() + record::kRecordHeaderBytes, payload.data(), payload.size());
  record::encodeRecordHeader(bytes.data(), type, timeNs, bytes.data() + record::kRecordHeaderBytes,
                             static_cast<std::uint32_t>(payload.size()));
  // One write(2) of the whole record on an O_APPEND descriptor: it lands
  // after, never inside, the writer thread's batches.
  const ssize_t w = ::write(fd_, bytes.data(), bytes.size());
  if (w != static_cast<ssize_t>(bytes.size()))
    return fail(ErrorCode::Io, "write failed: " + (w < 0 ? errnoText() : std::string("short write")),
                path_.string());
  written_.fetch_add(1, std::memory_order_relaxed);
  return ok();
}

Status DeviceRecorder::close() {
  if (closed_.exchange(true)) return ok();
  stop_.store(true, std::memory_order_release);
  if (writer_.joinable()) writer_.join();
  Status result = ok();
  if (failed_.load(std::memory_order_acquire))
    result = fail(ErrorCode::Io, "write failed: " + writeError_, path_.string(), "check free disk space");
  if (fd_ >= 0) {
    if (::fsync(fd_) != 0 && result.ok())
      result = fail(ErrorCode::Io, "fsync failed: " + errnoText(), path_.string());
    ::close(fd_);
    fd_ = -1;
  }
  return result;
}

Result<Recording> parseRecording(std::span<const std::uint8_t> bytes, std::string_view name) {
  Recording rec;
  const record::ScanResult scan = record::scan(bytes.data(), bytes.size(), [&](const record::RecordView& v) {
    RecordedRecord r;
    r.type = v.type;
    r.timeNs = v.timeNs;
    r.index = v.index;
    r.offset = v.offset;
    r.payload.resize(v.size);
    if (v.size) std::memcpy(r.payload.data(), v.payload, v.size);
    rec.records.push_back(std::move(r));
  });
  if (!scan.headerOk)
    return fail(ErrorCode::Parse, scan.error, std::string(name),
                "is this a DMPlatform device recording (.dmrec)?");
  rec.metadata = scan.metadata;
  rec.validBytes = scan.validBytes;
  rec.tail = scan.tail;
  return rec;
}

Result<Recording> readRecording(const std::filesystem::path& file, std::size_t maxBytes) {
  auto bytes = readFile(file, maxBytes);
  if (!bytes) return std::move(bytes).error();
  return parseRecording(
      std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(bytes->data()), bytes->size()),
      file.string());
}

Result<HapticState> decodeHapticState(const RecordedRecord& r) {
  auto p = checkedPayload(r, record::kHapticState, record::kHapticStateBytes, "haptic-state");
  if (!p) return std::move(p).error();
  double v[13];
  record::decodeDoubles(*p, v, 13);
  HapticState s;
  s.timeNs = r.timeNs;
  s.position = Vec3(v[0], v[1], v[2]);
  s.orientation = Quat(v[3], v[4], v[5], v[6]);
  s.linearVelocity = Vec3(v[7], v[8], v[9]);
  s.angularVelocity = Vec3(v[10], v[11], v[12]);
  s.buttons = record::getU32(*p + 8 * 13);
  return s;
}

Result<ControllerState> decodeControllerState(const RecordedRecord& r) {
  auto p = checkedPayload(r, record::kControllerState, record::kControllerStateBytes, "controller-state");
  if (!p) return std::move(p).error();
  if (std::string why = record::checkControllerState(*p); !why.empty()) return recordError(r, why);
  ControllerState s;
  s.timeNs = r.timeNs;
  std::uint64_t buttons[2];
  record::decodeControllerState(*p, s.axes.data(), buttons);
  for (std::size_t i = 0; i < kControllerButtons; ++i) s.buttons[i] = (buttons[i / 64] >> (i % 64)) & 1u;
  return s;
}

Result<RecordedDaqBlock> decodeDaqBlock(const RecordedRecord& r) {
  auto p = checkedPayload(r, record::kDaqBlock, 0, "DAQ-block");
  if (!p) return std::move(p).error();
  record::DaqBlockView view;
  if (std::string why = record::parseDaqBlock(*p, r.payload.size(), view); !why.empty())
    return recordError(r, why);
  RecordedDaqBlock b;
  b.channelCount = view.channels;
  b.overrunFrames = view.overrun;
  b.frames.resize(view.frames);
  for (std::uint32_t f = 0; f < view.frames; ++f) {
    b.frames[f].timeNs = view.time(f);
    b.frames[f].index = view.index(f);
    view.values(f, b.frames[f].values.data());
  }
  return b;
}

Result<SensorReading> decodeSensorReading(const RecordedRecord& r) {
  auto p = checkedPayload(r, record::kSensorReading, record::kSensorReadingBytes, "sensor-reading");
  if (!p) return std::move(p).error();
  if (std::string why = record::checkSensorReading(*p); !why.empty()) return recordError(r, why);
  SensorReading s;
  s.timeNs = r.timeNs;
  std::uint32_t type = 0;
  record::decodeSensorReading(*p, type, s.values.data());
  s.type = static_cast<SensorReadingType>(type);
  return s;
}

}  // namespace dm
