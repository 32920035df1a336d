// Controller: a "controller" driver behind validation, a triple buffer and
// loss/reconnection events (see dm/io/controller.hpp).
#include <dm/io/controller.hpp>

#include <algorithm>
#include <cmath>

#include "device_open.hpp"

namespace dm {

Result<std::unique_ptr<Controller>> Controller::open(const FactoryRegistry& registry, std::string_view driver,
                                                     const DeviceParams& params,
                                                     const ControllerOptions& options) {
  auto found = detail::findDeviceVTable<DmControllerVTable>(
      registry, DM_CONTROLLER_KIND, DM_CONTROLLER_KIND_ABI_VERSION, "controller", driver);
  if (!found) return std::move(found).error();
  const DmControllerVTable* vt = found->vt;
  if (!vt || !vt->open || !vt->close || !vt->get_info || !vt->read_state)
    return detail::nullFunctionError(found->where, "open, close, get_info and read_state");
  if (!(options.reconnectIntervalSeconds >= 0.0))
    return fail(ErrorCode::InvalidArgument, "reconnectIntervalSeconds is negative or NaN", found->where,
                "use a time ≥ 0 s");
  auto dev = detail::openDeviceInstance(vt->open, params, found->where);
  if (!dev) return std::move(dev).error();

  std::unique_ptr<Controller> c(new Controller());
  c->vt_ = vt;
  c->device_ = *dev;
  c->keepAlive_ = found->keepAlive;
  c->link_.setInterval(options.reconnectIntervalSeconds);
  DmControllerInfo ci{};
  if (vt->get_info(*dev, &ci) != DM_DEVICE_OK)
    return fail(ErrorCode::Device, "get_info failed", found->where, "check the device connection");
  if (ci.axis_count > kControllerAxes || ci.button_count > kControllerButtons || !(ci.poll_rate_hz > 0.0) ||
      !std::isfinite(ci.poll_rate_hz))
    return fail(ErrorCode::Device, "driver reports nonsensical info (axis or button count, poll rate)",
                found->where, "a driver reports ≤ 6 axes, ≤ 128 buttons and a positive poll rate");
  c->info_ = {toDeviceIdentity(ci.identity), ci.capabilities, ci.axis_count, ci.button_count,
              ci.poll_rate_hz};
  return c;
}

Controller::~Controller() {
  if (vt_ && device_) vt_->close(device_);
}

DeviceStatus Controller::poll(std::int64_t nowNs) noexcept {
  if (!link_.connectedForPoll()) {
    if (!vt_->reconnect || !link_.reconnectDue(nowNs) || vt_->reconnect(device_, nowNs) != DM_DEVICE_OK)
      return DeviceStatus::Lost;
    link_.reconnected(nowNs);
  }
  DmControllerState s{};
  const int rs = vt_->read_state(device_, nowNs, &s);
  if (rs == DM_DEVICE_ERROR_LOST) {
    link_.lost(nowNs);
    return DeviceStatus::Lost;
  }
  const bool valid = std::all_of(std::begin(s.axes), std::end(s.axes),
                                 [](double a) { return a >= -1.0 && a <= 1.0; });  // false for NaN
  if (rs != DM_DEVICE_OK || !valid) {
    link_.ioError();
    return DeviceStatus::IoError;
  }
  ControllerState& st = states_.writeBuffer();
  st.timeNs = s.time_ns;
  std::copy(std::begin(s.axes), std::end(s.axes), st.axes.begin());
  st.buttons.reset();
  for (std::size_t i = 0; i < info_.buttonCount; ++i)
    if ((s.buttons[i / 64] >> (i % 64)) & 1u) st.buttons.set(i);
  states_.publish();
  return DeviceStatus::Ok;
}

}  // namespace dm
