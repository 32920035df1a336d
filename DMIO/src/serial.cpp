// SerialLine: a "serial" driver with errors that name the line, and
// loss/reconnection events (see dm/io/serial.hpp).
#include <dm/io/serial.hpp>

#include <algorithm>
#include <climits>

#include "device_open.hpp"

namespace dm {

namespace {

std::int64_t monotonicNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

SerialConfig fromC(const DmSerialConfig& c) {
  return {c.baud, c.data_bits, static_cast<SerialParity>(c.parity), c.stop_bits,
          static_cast<SerialFlowControl>(c.flow_control)};
}

Status readInfo(const DmSerialVTable* vt, DmDevice* dev, SerialInfo& info, const std::string& where) {
  DmSerialInfo ci{};
  if (vt->get_info(dev, &ci) != DM_DEVICE_OK)
    return fail(ErrorCode::Device, "get_info failed", where, "check the device connection");
  info = {toDeviceIdentity(ci.identity), ci.capabilities, detail::fixedString(ci.path, sizeof ci.path),
          fromC(ci.config)};
  return ok();
}

}  // namespace

Result<std::unique_ptr<SerialLine>> SerialLine::open(const FactoryRegistry& registry, std::string_view driver,
                                                     const DeviceParams& params) {
  auto found = detail::findDeviceVTable<DmSerialVTable>(registry, DM_SERIAL_KIND, DM_SERIAL_KIND_ABI_VERSION,
                                                        "serial line", driver);
  if (!found) return std::move(found).error();
  const DmSerialVTable* vt = found->vt;
  if (!vt || !vt->open || !vt->close || !vt->get_info || !vt->configure || !vt->read || !vt->write)
    return detail::nullFunctionError(found->where, "open, close, get_info, configure, read and write");
  auto dev = detail::openDeviceInstance(vt->open, params, found->where);
  if (!dev) return std::move(dev).error();
  std::unique_ptr<SerialLine> s(new SerialLine());
  s->vt_ = vt;
  s->device_ = *dev;
  s->keepAlive_ = found->keepAlive;
  if (auto st = readInfo(vt, *dev, s->info_, found->where); !st) return std::move(st).error();
  s->where_ = found->where + " " + s->info_.path;
  return s;
}

SerialLine::~SerialLine() {
  if (vt_ && device_) vt_->close(device_);
}

Status SerialLine::configure(const SerialConfig& config) {
  const DmSerialConfig c{config.baud, config.dataBits, static_cast<std::uint32_t>(config.parity),
                         config.stopBits, static_cast<std::uint32_t>(config.flowControl)};
  char error[512] = {0};
  const int rc = vt_->configure(device_, &c, error, sizeof error);
  if (rc == DM_DEVICE_ERROR_LOST) {
    link_.lost(monotonicNs());
    return fail(ErrorCode::Device, "serial line lost", where_,
                "plug the device back in and call reconnect()");
  }
  if (rc != DM_DEVICE_OK)
    return fail(rc == DM_DEVICE_ERROR_INVALID_ARGUMENT ? ErrorCode::InvalidArgument : ErrorCode::Device,
                error[0] ? detail::fixedString(error, sizeof error) : "configure failed", where_,
                "use settings the line supports");
  return readInfo(vt_, device_, info_, where_);
}

Result<int> SerialLine::beginTransfer(std::chrono::milliseconds timeout) {
  if (timeout.count() < 0)
    return fail(ErrorCode::InvalidArgument, "negative timeout", where_, "use a timeout ≥ 0 ms");
  if (!link_.connectedForPoll())
    return fail(ErrorCode::Device, "serial line lost", where_, "call reconnect() once the device is back");
  return static_cast<int>(std::min<std::int64_t>(timeout.count(), INT_MAX));
}

Result<std::size_t> SerialLine::endTransfer(int rc, std::size_t done, std::size_t size, const char* what) {
  if (rc == DM_DEVICE_ERROR_LOST) {
    link_.lost(monotonicNs());
    return fail(ErrorCode::Device, "serial line lost (device removed or peer hung up)", where_,
                "plug the device back in and call reconnect()");
  }
  if (rc != DM_DEVICE_OK || done > size) {
    link_.ioError();
    return fail(ErrorCode::Io, std::string(what) + " failed", where_,
                "check the cable and the line settings");
  }
  return done;
}

Result<std::size_t> SerialLine::read(std::span<std::byte> out, std::chrono::milliseconds timeout) {
  auto ms = beginTransfer(timeout);
  if (!ms) return std::move(ms).error();
  std::size_t done = 0;
  const int rc = vt_->read(device_, out.data(), out.size(), *ms, &done);
  return endTransfer(rc, done, out.size(), "read");
}

Result<std::size_t> SerialLine::write(std::span<const std::byte> data, std::chrono::milliseconds timeout) {
  auto ms = beginTransfer(timeout);
  if (!ms) return std::move(ms).error();
  std::size_t done = 0;
  const int rc = vt_->write(device_, data.data(), data.size(), *ms, &done);
  return endTransfer(rc, done, data.size(), "write");
}

Status SerialLine::reconnect() {
  if (link_.connected()) return ok();
  if (!vt_->reconnect)
    return fail(ErrorCode::Unsupported, "the driver cannot reconnect", where_,
                "close and open the line again");
  if (vt_->reconnect(device_) != DM_DEVICE_OK)
    return fail(ErrorCode::Device, "serial line still away", where_, "plug the device back in and retry");
  link_.reconnected(monotonicNs());
  return ok();
}

}  // namespace dm
