// libFuzzer target: the sim-haptic driver's CSV path reader (a file a scene
// names, so untrusted). Any input must open a device or fail with an error
// that names the file; an opened device must give finite, unit-orientation
// samples along the whole path.
#include <dm/io/drivers.hpp>
#include <dm/io/haptic_device.hpp>

#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static dm::FactoryRegistry registry;
  static dm::PluginLinker linker(registry);
  static const bool registered = dm::registerBuiltinDrivers(linker).ok();
  static const std::string file = "/tmp/dm_fuzz_sim_haptic_" + std::to_string(::getpid()) + ".csv";
  if (!registered) std::abort();
  std::FILE* f = std::fopen(file.c_str(), "wb");
  if (!f) std::abort();
  if (size > 0 && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  auto d = dm::HapticDevice::open(registry, "sim-haptic", {{"path", "csv"}, {"file", file}, {"loop", "0"}});
  if (!d) {
    if (d.error().message().find(file) == std::string::npos) std::abort();
    return 0;
  }
  for (std::int64_t ms = 0; ms <= 2000; ms += 250) {
    if ((*d)->servo(ms * 1'000'000) != dm::DeviceStatus::Ok) std::abort();
    const dm::HapticState& s = (*d)->state();
    if (!s.position.allFinite() || !s.angularVelocity.allFinite() || !s.linearVelocity.allFinite())
      std::abort();
    if (std::abs(s.orientation.norm() - 1.0) > 1e-9) std::abort();
  }
  return 0;
}
