// Controller and its drivers: sim-controller loaded as a plugin and built in,
// its axes and buttons against their formulas, loss and reconnection as
// events, the wrapper's validation against a misbehaving driver, and
// evdev-controller against bad paths and (where /dev/uinput is available) a
// virtual input device created through uinput.
#include <dm/io/controller.hpp>

#include <gtest/gtest.h>

#include <fcntl.h>
#include <linux/input.h>
#include <linux/uinput.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <numbers>
#include <string>
#include <thread>
#include <vector>

#include "driver_test_support.hpp"

namespace {

using dm::test::kMs;

std::unique_ptr<dm::Controller> openOrFail(const dm::FactoryRegistry& reg, const char* driver,
                                           const dm::DeviceParams& params,
                                           const dm::ControllerOptions& o = {}) {
  auto c = dm::Controller::open(reg, driver, params, o);
  EXPECT_TRUE(c.ok()) << (c.ok() ? "" : c.error().message());
  return c.ok() ? std::move(*c) : nullptr;
}

using dm::test::frac;

TEST(SimController, PluginAndBuiltInGiveIdenticalStates) {
  dm::test::PluginDriver plugin("sim_controller", "sim-controller");
  ASSERT_TRUE(plugin.loaded);
  dm::test::BuiltinDrivers builtin;
  const dm::DeviceParams params = {
      {"axis0", "sine,0.5,3"}, {"noise", "0.05"}, {"seed", "9"}, {"buttons", "40"}};
  auto p = openOrFail(plugin.registry, "sim-controller", params);
  auto b = openOrFail(builtin.registry, "sim-controller", params);
  ASSERT_TRUE(p && b);
  EXPECT_EQ(p->info().identity.driver, "sim-controller");
  EXPECT_EQ(p->info().identity.serial, "sim-9");
  EXPECT_EQ(p->info().axisCount, 6u);
  EXPECT_EQ(p->info().buttonCount, 40u);
  EXPECT_EQ(p->info().pollRateHz, 250.0);
  for (std::int64_t k = 0; k < 300; ++k) {
    ASSERT_EQ(p->poll(k * 4 * kMs), dm::DeviceStatus::Ok);
    ASSERT_EQ(b->poll(k * 4 * kMs), dm::DeviceStatus::Ok);
    ASSERT_EQ(p->state().axes, b->state().axes) << k;
    ASSERT_EQ(p->state().buttons, b->state().buttons) << k;
  }
}

TEST(SimController, AxesFollowTheirFormulas) {
  dm::test::BuiltinDrivers b;
  auto c = openOrFail(b.registry, "sim-controller",
                      {{"axis0", "sine,0.8,2,0.1"},
                       {"axis1", "square,0.5,1"},
                       {"axis2", "ramp,1,0.5"},
                       {"axis3", "constant,1,1,-0.25"},
                       {"axis4", "sine,3,1"},  // clipped to [-1, 1]
                       {"axes", "5"}});
  ASSERT_TRUE(c);
  EXPECT_EQ(c->info().axisCount, 5u);
  const double pi = std::numbers::pi;
  for (std::int64_t k = 0; k < 2000; k += 7) {
    ASSERT_EQ(c->poll(k * kMs), dm::DeviceStatus::Ok);
    const dm::ControllerState& s = c->state();
    const double t = 1e-9 * static_cast<double>(k * kMs);
    EXPECT_EQ(s.timeNs, k * kMs);
    EXPECT_NEAR(s.axes[0], 0.1 + 0.8 * std::sin(2 * pi * 2 * t), 1e-12) << t;
    EXPECT_EQ(s.axes[1], frac(t) < 0.5 ? 0.5 : -0.5) << t;
    EXPECT_NEAR(s.axes[2], 2 * frac(0.5 * t) - 1, 1e-12) << t;
    EXPECT_EQ(s.axes[3], -0.25);
    EXPECT_NEAR(s.axes[4], std::clamp(3 * std::sin(2 * pi * t), -1.0, 1.0), 1e-12) << t;
    EXPECT_EQ(s.axes[5], 0.0);  // not reported as moving
  }
}

TEST(SimController, ButtonsCountInBinary) {
  dm::test::BuiltinDrivers b;
  auto c = openOrFail(b.registry, "sim-controller", {{"buttons", "128"}, {"button_rate", "10"}});
  auto few = openOrFail(b.registry, "sim-controller", {{"buttons", "3"}, {"button_rate", "10"}});
  ASSERT_TRUE(c && few);
  for (std::int64_t k = 0; k < 5000; k += 13) {
    c->poll(k * kMs);
    few->poll(k * kMs);
    const auto counter = static_cast<std::uint64_t>(std::floor(10 * 1e-9 * static_cast<double>(k * kMs)));
    for (std::size_t i = 0; i < 128; ++i) {
      ASSERT_EQ(c->state().pressed(i), ((counter >> (i % 64)) & 1u) != 0) << k << " " << i;
      ASSERT_EQ(few->state().pressed(i), i < 3 && ((counter >> i) & 1u) != 0) << k << " " << i;
    }
  }
  EXPECT_FALSE(c->state().pressed(128));  // out of range is never pressed
}

TEST(SimController, LossAndReconnectionAreEvents) {
  dm::test::BuiltinDrivers b;
  auto c = openOrFail(b.registry, "sim-controller",
                      {{"axis0", "ramp,1,1"}, {"drop_at", "0.1"}, {"reconnect_at", "0.25"}});
  ASSERT_TRUE(c);
  std::vector<dm::DeviceEvent> events;
  for (std::int64_t k = 0; k < 400; ++k) {
    const dm::DeviceStatus s = c->poll(k * kMs);
    const bool away = k >= 100 && k < 300;  // reconnect tried every 0.1 s: at 0.2 (too early), 0.3
    EXPECT_EQ(s == dm::DeviceStatus::Lost, away) << k;
    EXPECT_EQ(c->connected(), !away) << k;
    EXPECT_EQ(c->state().timeNs, away ? 99 * kMs : k * kMs) << k;  // the last sample stays
    dm::DeviceEvent e;
    while (c->pollEvent(e)) events.push_back(e);
  }
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].type, dm::DeviceEventType::Lost);
  EXPECT_EQ(events[0].timeNs, 100 * kMs);
  EXPECT_EQ(events[1].type, dm::DeviceEventType::Reconnected);
  EXPECT_EQ(events[1].timeNs, 300 * kMs);
  EXPECT_EQ(c->counters().losses, 1u);
  EXPECT_EQ(c->counters().reconnects, 1u);
  EXPECT_EQ(c->counters().polls, 400u);
}

TEST(SimController, BadParametersNameTheKey) {
  dm::test::BuiltinDrivers b;
  const std::vector<std::pair<dm::DeviceParams, std::string>> cases = {
      {{{"axis0", "zigzag"}}, "'axis0'"},       {{{"axis1", "sine,x"}}, "'axis1'"},
      {{{"axis2", "sine,1,-3"}}, "'axis2'"},    {{{"axes", "7"}}, "'axes'"},
      {{{"buttons", "2.5"}}, "'buttons'"},      {{{"buttons", "129"}}, "'buttons'"},
      {{{"poll_rate", "0"}}, "'poll_rate'"},    {{{"colour", "red"}}, "'colour'"},
      {{{"axis3", "sine,1,1,0,9"}}, "'axis3'"},
  };
  for (const auto& [params, needle] : cases) {
    auto c = dm::Controller::open(b.registry, "sim-controller", params);
    ASSERT_FALSE(c.ok()) << needle;
    EXPECT_EQ(c.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(c.error().message().find(needle), std::string::npos) << c.error().message();
  }
  auto missing = dm::Controller::open(b.registry, "space-mouse-pro");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, dm::ErrorCode::NotFound);
  EXPECT_NE(missing.error().message().find("sim-controller"), std::string::npos) << missing.error().message();
}

// A driver whose info and samples can be made nonsensical.
struct Faulty {
  std::uint32_t axisCount = 2;
  double axis0 = 0.0;
};
Faulty gFaulty;
const DmControllerVTable kFaultyVt = {
    [](const DmDeviceParam*, size_t, char*, size_t) { return reinterpret_cast<DmDevice*>(&gFaulty); },
    [](DmDevice*) {},
    [](DmDevice* d, DmControllerInfo* info) {
      *info = DmControllerInfo{};
      info->axis_count = reinterpret_cast<Faulty*>(d)->axisCount;
      info->button_count = 4;
      info->poll_rate_hz = 100;
      return DM_DEVICE_OK;
    },
    [](DmDevice* d, int64_t now, DmControllerState* s) {
      *s = DmControllerState{};
      s->time_ns = now;
      s->axes[0] = reinterpret_cast<Faulty*>(d)->axis0;
      s->buttons[0] = ~std::uint64_t{0};  // more buttons than the 4 reported
      return DM_DEVICE_OK;
    },
    nullptr,
};

TEST(Controller, RejectsNonsensicalInfoAndSamples) {
  dm::FactoryRegistry reg;
  ASSERT_TRUE(reg.add(DM_CONTROLLER_KIND, "faulty", DM_CONTROLLER_KIND_ABI_VERSION, &kFaultyVt).ok());
  gFaulty = Faulty{};
  gFaulty.axisCount = 9;
  auto bad = dm::Controller::open(reg, "faulty");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, dm::ErrorCode::Device);
  EXPECT_NE(bad.error().message().find("faulty"), std::string::npos) << bad.error().message();

  gFaulty.axisCount = 2;
  auto c = openOrFail(reg, "faulty", {});
  ASSERT_TRUE(c);
  gFaulty.axis0 = 0.5;
  EXPECT_EQ(c->poll(0), dm::DeviceStatus::Ok);
  EXPECT_EQ(c->state().buttons.count(), 4u);  // bits beyond buttonCount are ignored
  for (double badAxis : {std::nan(""), 1.5, -HUGE_VAL}) {
    gFaulty.axis0 = badAxis;
    EXPECT_EQ(c->poll(kMs), dm::DeviceStatus::IoError);
    EXPECT_EQ(c->state().axes[0], 0.5);  // the bad sample was dropped
  }
  EXPECT_EQ(c->counters().ioErrors, 3u);
  EXPECT_FALSE(dm::Controller::open(reg, "faulty", {}, {.reconnectIntervalSeconds = -1}).ok());

  // A driver built against another layout of the controller vtable is refused.
  ASSERT_TRUE(reg.add(DM_CONTROLLER_KIND, "future", DM_CONTROLLER_KIND_ABI_VERSION + 1, &kFaultyVt).ok());
  auto future = dm::Controller::open(reg, "future");
  ASSERT_FALSE(future.ok());
  EXPECT_EQ(future.error().code, dm::ErrorCode::Version);
}

// ------------------------------------------------------------ evdev ---

TEST(EvdevController, BadPathsAndNamesAreReported) {
  dm::test::PluginDriver b("evdev_controller", "evdev-controller");
  ASSERT_TRUE(b.loaded);
  const std::vector<std::pair<dm::DeviceParams, std::string>> cases = {
      {{{"path", "/nonexistent/event7"}}, "/nonexistent/event7"},
      {{{"path", "/dev/null"}}, "'/dev/null' is not an evdev input device"},
      {{{"name", "no such controller 51e2"}}, "'name'"},
      {{}, "'path'"},
      {{{"path", "/dev/null"}, {"name", "x"}}, "exactly one"},
      {{{"path", "/dev/null"}, {"poll_rate", "fast"}}, "'poll_rate'"},
  };
  for (const auto& [params, needle] : cases) {
    auto c = dm::Controller::open(b.registry, "evdev-controller", params);
    ASSERT_FALSE(c.ok()) << needle;
    EXPECT_EQ(c.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(c.error().message().find(needle), std::string::npos) << c.error().message();
  }
}

// A virtual input device: two centred axes (−512..511), a throttle
// (0..255) and four buttons.
class VirtualPad {
 public:
  static constexpr int kMin = -512, kMax = 511;
  explicit VirtualPad(std::string name) : name_(std::move(name)) {}
  ~VirtualPad() { destroy(); }
  VirtualPad(const VirtualPad&) = delete;
  VirtualPad& operator=(const VirtualPad&) = delete;

  // Empty on success, else why not.
  std::string create() {
    fd_ = ::open("/dev/uinput", O_WRONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd_ < 0) return std::string("/dev/uinput cannot be opened: ") + std::strerror(errno);
    bool ok = ioctl(fd_, UI_SET_EVBIT, EV_KEY) == 0 && ioctl(fd_, UI_SET_EVBIT, EV_ABS) == 0;
    for (int b = BTN_0; b <= BTN_3; ++b) ok = ok && ioctl(fd_, UI_SET_KEYBIT, b) == 0;
    for (int a : {ABS_X, ABS_Y, ABS_THROTTLE}) ok = ok && ioctl(fd_, UI_SET_ABSBIT, a) == 0;
    uinput_user_dev u{};
    std::snprintf(u.name, UINPUT_MAX_NAME_SIZE, "%s", name_.c_str());
    u.id.bustype = BUS_VIRTUAL;
    u.id.vendor = 0x1d50;
    u.id.product = 0x6d6d;
    u.absmin[ABS_X] = u.absmin[ABS_Y] = kMin;
    u.absmax[ABS_X] = u.absmax[ABS_Y] = kMax;
    u.absmin[ABS_THROTTLE] = 0;
    u.absmax[ABS_THROTTLE] = 255;
    ok = ok && ::write(fd_, &u, sizeof u) == static_cast<ssize_t>(sizeof u) && ioctl(fd_, UI_DEV_CREATE) == 0;
    if (!ok) {
      const std::string why = std::string("uinput refused the virtual device: ") + std::strerror(errno);
      ::close(fd_);
      fd_ = -1;
      return why;
    }
    return {};
  }
  void destroy() {
    if (fd_ < 0) return;
    ioctl(fd_, UI_DEV_DESTROY);
    ::close(fd_);
    fd_ = -1;
  }
  void emit(int type, int code, int value) {
    input_event e{};
    e.type = static_cast<unsigned short>(type);
    e.code = static_cast<unsigned short>(code);
    e.value = value;
    ASSERT_EQ(::write(fd_, &e, sizeof e), static_cast<ssize_t>(sizeof e));
  }

 private:
  std::string name_;
  int fd_ = -1;
};

// Polls `c` until `done` holds or 3 s pass (real time: the kernel delivers
// events asynchronously). Returns whether `done` held.
template <class Done>
bool pollUntil(dm::Controller& c, std::int64_t& t, Done done) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  while (std::chrono::steady_clock::now() < until) {
    c.poll(t += kMs);
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return false;
}

TEST(EvdevController, ReadsAVirtualUinputDevice) {
  const std::string name = "dm-test-pad-" + std::to_string(::getpid());
  VirtualPad pad(name);
  if (const std::string why = pad.create(); !why.empty())
    GTEST_SKIP() << why << " — no permission or no uinput module here, so the evdev driver cannot be "
                 << "driven by a virtual device (run as a user with access to /dev/uinput to test it)";
  dm::test::PluginDriver plugin("evdev_controller", "evdev-controller");
  ASSERT_TRUE(plugin.loaded);
  std::unique_ptr<dm::Controller> c;
  for (int tries = 0; tries < 300 && !c; ++tries) {  // the node appears asynchronously
    auto o = dm::Controller::open(plugin.registry, "evdev-controller", {{"name", name}},
                                  {.reconnectIntervalSeconds = 0});
    if (o.ok())
      c = std::move(*o);
    else
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  if (!c)
    GTEST_SKIP() << "uinput created '" << name
                 << "' but no /dev/input/event node appeared (no devtmpfs/udev)";
  EXPECT_EQ(c->info().axisCount, 3u);
  EXPECT_EQ(c->info().buttonCount, 4u);
  EXPECT_EQ(c->info().identity.model, name);
  EXPECT_EQ(c->info().identity.vendor, "1d50:6d6d");  // vendor:product ids

  auto normalised = [](double v, double lo, double hi) { return 2 * (v - lo) / (hi - lo) - 1; };
  pad.emit(EV_ABS, ABS_X, 255);
  pad.emit(EV_ABS, ABS_Y, VirtualPad::kMin);
  pad.emit(EV_ABS, ABS_THROTTLE, 200);
  pad.emit(EV_KEY, BTN_2, 1);
  pad.emit(EV_SYN, SYN_REPORT, 0);
  std::int64_t t = 0;
  ASSERT_TRUE(pollUntil(*c, t, [&] { return c->state().pressed(2); }));
  const dm::ControllerState& s = c->state();
  EXPECT_NEAR(s.axes[0], normalised(255, VirtualPad::kMin, VirtualPad::kMax), 1e-12);
  EXPECT_EQ(s.axes[1], -1.0);
  EXPECT_NEAR(s.axes[2], normalised(200, 0, 255), 1e-12);
  EXPECT_FALSE(s.pressed(0) || s.pressed(1) || s.pressed(3));

  pad.emit(EV_KEY, BTN_2, 0);
  pad.emit(EV_KEY, BTN_0, 1);
  pad.emit(EV_SYN, SYN_REPORT, 0);
  ASSERT_TRUE(pollUntil(*c, t, [&] { return c->state().pressed(0) && !c->state().pressed(2); }));

  pad.destroy();  // unplugged
  ASSERT_TRUE(pollUntil(*c, t, [&] { return !c->connected(); }));
  ASSERT_EQ(pad.create(), "");  // plugged back in (maybe as another eventN)
  ASSERT_TRUE(pollUntil(*c, t, [&] { return c->connected(); }));
  std::vector<dm::DeviceEventType> types;
  dm::DeviceEvent e;
  while (c->pollEvent(e)) types.push_back(e.type);
  EXPECT_EQ(types, (std::vector{dm::DeviceEventType::Lost, dm::DeviceEventType::Reconnected}));
}

}  // namespace
