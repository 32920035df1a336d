// evdev-controller — Linux input devices (kind "controller"): joysticks,
// foot pedals, 3-D mice, gamepads, through /dev/input/eventN.
//
// The device is opened non-blocking and read without waiting. The first six
// absolute axes it reports (in evdev code order: ABS_X, ABS_Y, ABS_Z,
// ABS_RX, …) become axes 0..5, normalised with the range the kernel reports
// (EVIOCGABS): 2·(v − min)/(max − min) − 1, and 0 within the axis' flat
// (dead) zone around the centre. Its keys and buttons (EV_KEY codes, in code
// order, at most 128) become buttons 0..127. Changes are applied a whole
// report (SYN_REPORT) at a time; after SYN_DROPPED the state is re-read
// from the kernel. An unplugged device (ENODEV) is lost; reconnect reopens
// it (by path, or by name so that a new event number is found).
//
// Parameters (one of path and name is required):
//   path       /dev/input/eventN
//   name       a substring of the device name (EVIOCGNAME); the first
//              match in /dev/input, lowest event number first
//   poll_rate  Hz suggested to the host                             (250)
//
// Built into DM::IO and, with DM_DRIVER_PLUGIN, as libdm_driver_evdev_controller.so.
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <dirent.h>
#include <fcntl.h>
#include <linux/input.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>
#include <string>
#include <vector>

#include "driver_params.hpp"

namespace {

using dm::driver::ParamReader;

constexpr std::size_t kLongBits = 8 * sizeof(unsigned long);
bool testBit(const unsigned long* bits, unsigned i) { return (bits[i / kLongBits] >> (i % kLongBits)) & 1ul; }

struct Report {
  int raw[DM_CONTROLLER_AXES] = {};
  std::uint64_t buttons[2] = {};
};

// One open device; DmDevice* is this type behind the C boundary.
struct Evdev {
  int fd = -1;
  char path[256] = "";       // device node in use
  char nameMatch[128] = "";  // non-empty: found by name
  double pollRate = 250.0;
  char name[64] = "", uniq[64] = "";
  unsigned short vendorId = 0, productId = 0;
  unsigned axisCount = 0, buttonCount = 0;
  unsigned axisCode[DM_CONTROLLER_AXES] = {};
  input_absinfo abs[DM_CONTROLLER_AXES] = {};
  unsigned short buttonCode[DM_CONTROLLER_MAX_BUTTONS] = {};
  Report pending, committed;
  bool dropping = false;  // after SYN_DROPPED, until the next SYN_REPORT
};

Evdev* asEvdev(DmDevice* d) { return reinterpret_cast<Evdev*>(d); }

int axisIndex(const Evdev& d, unsigned code) {
  for (unsigned i = 0; i < d.axisCount; ++i)
    if (d.axisCode[i] == code) return static_cast<int>(i);
  return -1;
}
int buttonIndex(const Evdev& d, unsigned code) {
  const unsigned short* end = d.buttonCode + d.buttonCount;
  const unsigned short* it = std::lower_bound(d.buttonCode, end, code);
  return it != end && *it == code ? static_cast<int>(it - d.buttonCode) : -1;
}

// Reads the current axes and keys from the kernel into both reports.
bool resync(Evdev& d) {
  for (unsigned i = 0; i < d.axisCount; ++i) {
    input_absinfo a{};
    if (ioctl(d.fd, EVIOCGABS(d.axisCode[i]), &a) < 0) return false;
    d.pending.raw[i] = a.value;
  }
  unsigned long keys[KEY_MAX / kLongBits + 1] = {};
  if (d.buttonCount && ioctl(d.fd, EVIOCGKEY(sizeof keys), keys) < 0) return false;
  d.pending.buttons[0] = d.pending.buttons[1] = 0;
  for (unsigned i = 0; i < d.buttonCount; ++i)
    if (testBit(keys, d.buttonCode[i])) d.pending.buttons[i / 64] |= std::uint64_t{1} << (i % 64);
  d.committed = d.pending;
  return true;
}

// Learns the device's axes and buttons; false with a message if it is not a controller.
bool setup(Evdev& d, char* error, std::size_t errorSize) {
  auto fail = [&](const char* what) {
    if (error && errorSize)
      std::snprintf(error, errorSize, "parameter '%s': '%s' %s", d.nameMatch[0] ? "name" : "path", d.path,
                    what);
    return false;
  };
  unsigned long evBits[EV_MAX / kLongBits + 1] = {};
  if (ioctl(d.fd, EVIOCGBIT(0, sizeof evBits), evBits) < 0) return fail("is not an evdev input device");
  unsigned long absBits[ABS_MAX / kLongBits + 1] = {};
  unsigned long keyBits[KEY_MAX / kLongBits + 1] = {};
  if (testBit(evBits, EV_ABS)) ioctl(d.fd, EVIOCGBIT(EV_ABS, sizeof absBits), absBits);
  if (testBit(evBits, EV_KEY)) ioctl(d.fd, EVIOCGBIT(EV_KEY, sizeof keyBits), keyBits);
  d.axisCount = d.buttonCount = 0;
  for (unsigned code = 0; code <= ABS_MAX && d.axisCount < DM_CONTROLLER_AXES; ++code) {
    if (!testBit(absBits, code)) continue;
    input_absinfo a{};
    if (ioctl(d.fd, EVIOCGABS(code), &a) < 0 || a.maximum <= a.minimum) continue;
    d.axisCode[d.axisCount] = code;
    d.abs[d.axisCount++] = a;
  }
  for (unsigned code = 0; code <= KEY_MAX && d.buttonCount < DM_CONTROLLER_MAX_BUTTONS; ++code)
    if (testBit(keyBits, code)) d.buttonCode[d.buttonCount++] = static_cast<unsigned short>(code);
  if (d.axisCount == 0 && d.buttonCount == 0)
    return fail("has no absolute axes and no buttons (not a controller)");
  if (ioctl(d.fd, EVIOCGNAME(sizeof d.name), d.name) < 0) d.name[0] = '\0';
  d.name[sizeof d.name - 1] = '\0';
  if (ioctl(d.fd, EVIOCGUNIQ(sizeof d.uniq), d.uniq) < 0) d.uniq[0] = '\0';
  d.uniq[sizeof d.uniq - 1] = '\0';
  input_id id{};
  if (ioctl(d.fd, EVIOCGID, &id) == 0) {
    d.vendorId = id.vendor;
    d.productId = id.product;
  }
  d.dropping = false;
  if (!resync(d)) return fail("stopped answering while being set up");
  return true;
}

// Event nodes of /dev/input, by event number.
std::vector<std::string> eventNodes() {
  std::vector<std::pair<long, std::string>> nodes;
  if (DIR* dir = opendir("/dev/input")) {
    while (const dirent* e = readdir(dir))
      if (std::strncmp(e->d_name, "event", 5) == 0)
        nodes.emplace_back(std::strtol(e->d_name + 5, nullptr, 10), std::string("/dev/input/") + e->d_name);
    closedir(dir);
  }
  std::sort(nodes.begin(), nodes.end());
  std::vector<std::string> out;
  for (auto& n : nodes) out.push_back(std::move(n.second));
  return out;
}

// Opens d.path, or finds d.nameMatch; fd ≥ 0 on success.
bool openDevice(Evdev& d, char* error, std::size_t errorSize) {
  if (d.nameMatch[0]) {
    std::string seen;
    for (const std::string& node : eventNodes()) {
      const int fd = ::open(node.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
      if (fd < 0) continue;
      char name[256] = "";
      if (ioctl(fd, EVIOCGNAME(sizeof name), name) >= 0 && std::strstr(name, d.nameMatch)) {
        d.fd = fd;
        dm::driver::copyField(d.path, node.c_str());
        if (setup(d, error, errorSize)) return true;
        ::close(d.fd);
        d.fd = -1;
        return false;
      }
      if (seen.size() < 300) seen += (seen.empty() ? "'" : ", '") + std::string(name) + "'";
      ::close(fd);
    }
    if (error && errorSize)
      std::snprintf(error, errorSize,
                    "parameter 'name': no readable input device in /dev/input has '%s' in its "
                    "name (found: %s)",
                    d.nameMatch, seen.empty() ? "none" : seen.c_str());
    return false;
  }
  d.fd = ::open(d.path, O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (d.fd < 0) {
    if (error && errorSize)
      std::snprintf(error, errorSize, "parameter 'path': cannot open '%s': %s", d.path, std::strerror(errno));
    return false;
  }
  if (setup(d, error, errorSize)) return true;
  ::close(d.fd);
  d.fd = -1;
  return false;
}

DmDevice* evOpen(const DmDeviceParam* params, size_t count, char* error, size_t errorSize) {
  ParamReader r(params, count, error, errorSize);
  r.onlyKnown({"path", "name", "poll_rate"});
  const char* path = r.find("path");
  const char* name = r.find("name");
  if (r.ok() && (!path) == (!name))
    r.failf("give exactly one of parameters 'path' (/dev/input/eventN) and 'name'");
  if (r.ok() && path && (!*path || std::strlen(path) >= sizeof(Evdev::path)))
    r.failf("parameter 'path': '%s' is empty or too long", path);
  if (r.ok() && name && (!*name || std::strlen(name) >= sizeof(Evdev::nameMatch)))
    r.failf("parameter 'name': '%s' is empty or too long", name);
  const double pollRate = r.number("poll_rate", 250.0, 1.0, 1e5);
  if (!r.ok()) return nullptr;
  Evdev* d = new (std::nothrow) Evdev();
  if (!d) {
    r.failf("out of memory");
    return nullptr;
  }
  if (path) dm::driver::copyField(d->path, path);
  if (name) dm::driver::copyField(d->nameMatch, name);
  d->pollRate = pollRate;
  if (!openDevice(*d, error, errorSize)) {
    delete d;
    return nullptr;
  }
  return reinterpret_cast<DmDevice*>(d);
}

void evClose(DmDevice* dev) {
  Evdev* d = asEvdev(dev);
  if (d->fd >= 0) ::close(d->fd);
  delete d;
}

int evInfo(DmDevice* dev, DmControllerInfo* info) {
  Evdev* d = asEvdev(dev);
  *info = DmControllerInfo{};
  dm::driver::copyField(info->identity.driver, "evdev-controller");
  std::snprintf(info->identity.vendor, sizeof info->identity.vendor, "%04x:%04x", d->vendorId, d->productId);
  dm::driver::copyField(info->identity.model, d->name);
  dm::driver::copyField(info->identity.serial, d->uniq[0] ? d->uniq : d->path);
  info->capabilities = DM_CONTROLLER_CAP_RECONNECT | (d->axisCount ? DM_CONTROLLER_CAP_AXES : 0u) |
                       (d->buttonCount ? DM_CONTROLLER_CAP_BUTTONS : 0u);
  info->axis_count = d->axisCount;
  info->button_count = d->buttonCount;
  info->poll_rate_hz = d->pollRate;
  return DM_DEVICE_OK;
}

void apply(Evdev& d, const input_event& e) {
  if (e.type == EV_SYN) {
    if (e.code == SYN_DROPPED) {
      d.dropping = true;
    } else if (e.code == SYN_REPORT) {
      if (d.dropping) {
        d.dropping = false;
        resync(d);  // a failure shows as ENODEV on the next read
      } else {
        d.committed = d.pending;
      }
    }
    return;
  }
  if (d.dropping) return;
  if (e.type == EV_ABS) {
    if (const int i = axisIndex(d, e.code); i >= 0) d.pending.raw[i] = e.value;
  } else if (e.type == EV_KEY) {
    if (const int i = buttonIndex(d, e.code); i >= 0) {
      const std::uint64_t bit = std::uint64_t{1} << (i % 64);
      if (e.value)
        d.pending.buttons[i / 64] |= bit;  // 1 press, 2 autorepeat
      else
        d.pending.buttons[i / 64] &= ~bit;
    }
  }
}

double normalise(const input_absinfo& a, int raw) {
  const double centre = 0.5 * (static_cast<double>(a.minimum) + a.maximum);
  if (a.flat > 0 && std::abs(raw - centre) <= a.flat) return 0.0;
  const double n =
      2.0 * (static_cast<double>(raw) - a.minimum) / (static_cast<double>(a.maximum) - a.minimum) - 1.0;
  return std::clamp(n, -1.0, 1.0);
}

int evRead(DmDevice* dev, int64_t now, DmControllerState* s) {
  Evdev* d = asEvdev(dev);
  if (d->fd < 0) return DM_DEVICE_ERROR_LOST;
  input_event events[64];
  for (;;) {
    const ssize_t n = ::read(d->fd, events, sizeof events);
    if (n < 0) {
      if (errno == EINTR) continue;
      if (errno == EAGAIN) break;
      if (errno == ENODEV || errno == EIO) {
        ::close(d->fd);
        d->fd = -1;
        return DM_DEVICE_ERROR_LOST;
      }
      return DM_DEVICE_ERROR_IO;
    }
    const std::size_t count = static_cast<std::size_t>(n) / sizeof(input_event);
    for (std::size_t i = 0; i < count; ++i) apply(*d, events[i]);
    if (count < sizeof events / sizeof events[0]) break;
  }
  *s = DmControllerState{};
  s->time_ns = now;
  for (unsigned i = 0; i < d->axisCount; ++i) s->axes[i] = normalise(d->abs[i], d->committed.raw[i]);
  s->buttons[0] = d->committed.buttons[0];
  s->buttons[1] = d->committed.buttons[1];
  return DM_DEVICE_OK;
}

int evReconnect(DmDevice* dev, int64_t) {
  Evdev* d = asEvdev(dev);
  if (d->fd >= 0) return DM_DEVICE_OK;
  return openDevice(*d, nullptr, 0) ? DM_DEVICE_OK : DM_DEVICE_ERROR_LOST;
}

const DmControllerVTable kEvdev = {evOpen, evClose, evInfo, evRead, evReconnect};

int evInit(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_CONTROLLER_KIND, "evdev-controller",
                                DM_CONTROLLER_KIND_ABI_VERSION, &kEvdev);
}

const DmPluginInfo kEvdevControllerInfo = {DM_PLUGIN_ABI_VERSION, "evdev-controller", "1.0", evInit, nullptr};

}  // namespace

#if defined(DM_DRIVER_PLUGIN)
DM_PLUGIN_ENTRY { return &kEvdevControllerInfo; }
#else
extern "C" const DmPluginInfo* dm_builtin_entry_evdev_controller(void) { return &kEvdevControllerInfo; }
#endif
