// Private helpers of the device wrappers (controller, daq, sensor, serial):
// find a driver's vtable in a registry and open an instance, with the
// errors every wrapper reports the same way.
#pragma once

#include <dm/core/plugin.hpp>
#include <dm/core/result.hpp>
#include <dm/io/device.hpp>

#include <cstring>
#include <memory>
#include <string>
#include <string_view>

namespace dm::detail {

/// A driver's vtable plus what keeps its library loaded.
template <class VTable>
struct DriverVTable {
  const VTable* vt = nullptr;
  std::shared_ptr<const void> keepAlive;
  std::string where;  ///< "<label> '<driver>' (<provider>)", for messages
};

/// The C `open` signature shared by every device kind.
using DeviceOpenFn = DmDevice* (*)(const DmDeviceParam*, size_t, char*, size_t);

/// Calls `open` with `params`; InvalidArgument with the driver's message
/// (which names the parameter) on failure.
Result<DmDevice*> openDeviceInstance(DeviceOpenFn open, const DeviceParams& params, const std::string& where);

/// Device error for a vtable missing a required function.
Error nullFunctionError(const std::string& where, const char* required);

/// A fixed C char field as a string (stops at NUL or capacity).
inline std::string fixedString(const char* s, std::size_t capacity) {
  return std::string(s, strnlen(s, capacity));
}

/// Finds (kind, driver) with kind ABI `abi`; "<label> '<driver>' (provider)"
/// becomes the where of later errors. Fails like FactoryRegistry::find.
template <class VTable>
Result<DriverVTable<VTable>> findDeviceVTable(const FactoryRegistry& registry, const char* kind,
                                              std::uint32_t abi, std::string_view label,
                                              std::string_view driver) {
  auto f = registry.find(kind, driver, abi);
  if (!f) return std::move(f).error();
  DriverVTable<VTable> d;
  d.vt = f->template as<VTable>();
  d.keepAlive = f->keepAlive;
  d.where = std::string(label) + " '" + std::string(driver) + "' (" + f->provider + ")";
  return d;
}

}  // namespace dm::detail
