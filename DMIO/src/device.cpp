// Shared pieces of the device wrappers: identity conversion, the loss and
// reconnection link, and driver lookup/open (see dm/io/device.hpp).
#include <dm/io/device.hpp>

#include <vector>

#include "device_open.hpp"

namespace dm {

DeviceIdentity toDeviceIdentity(const DmDeviceIdentity& identity) {
  return {detail::fixedString(identity.driver, sizeof identity.driver),
          detail::fixedString(identity.vendor, sizeof identity.vendor),
          detail::fixedString(identity.model, sizeof identity.model),
          detail::fixedString(identity.serial, sizeof identity.serial)};
}

namespace detail {

bool DeviceLink::reconnectDue(std::int64_t nowNs) noexcept {
  if (nowNs - lastTryNs_ < intervalNs_) return false;
  lastTryNs_ = nowNs;
  return true;
}

void DeviceLink::lost(std::int64_t nowNs) noexcept {
  if (!connected_.load(std::memory_order_relaxed)) return;
  connected_.store(false, std::memory_order_release);
  lastTryNs_ = nowNs;
  losses_.fetch_add(1, std::memory_order_relaxed);
  (void)events_.tryPush(DeviceEvent{DeviceEventType::Lost, nowNs});  // full ring: counters still count
}

void DeviceLink::reconnected(std::int64_t nowNs) noexcept {
  if (connected_.load(std::memory_order_relaxed)) return;
  connected_.store(true, std::memory_order_release);
  reconnects_.fetch_add(1, std::memory_order_relaxed);
  (void)events_.tryPush(DeviceEvent{DeviceEventType::Reconnected, nowNs});
}

DeviceCounters DeviceLink::counters() const noexcept {
  DeviceCounters c;
  c.polls = polls_.load(std::memory_order_relaxed);
  c.losses = losses_.load(std::memory_order_relaxed);
  c.reconnects = reconnects_.load(std::memory_order_relaxed);
  c.ioErrors = ioErrors_.load(std::memory_order_relaxed);
  return c;
}

Result<DmDevice*> openDeviceInstance(DeviceOpenFn open, const DeviceParams& params,
                                     const std::string& where) {
  std::vector<DmDeviceParam> cParams;
  cParams.reserve(params.size());
  for (const auto& [k, v] : params) cParams.push_back({k.c_str(), v.c_str()});
  char error[512] = {0};
  DmDevice* dev = open(cParams.data(), cParams.size(), error, sizeof error);
  if (!dev)
    return fail(ErrorCode::InvalidArgument, error[0] ? fixedString(error, sizeof error) : "open failed",
                where, "fix the device parameters in the scene");
  return dev;
}

Error nullFunctionError(const std::string& where, const char* required) {
  return fail(ErrorCode::Device, "driver vtable has a null function", where,
              std::string("the driver must set ") + required);
}

}  // namespace detail
}  // namespace dm
