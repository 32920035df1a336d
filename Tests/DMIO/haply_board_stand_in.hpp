// A Haply board on a pseudo-terminal, for the haply-2diy driver's tests: it
// answers the hAPI 2 board protocol as Haply's firmware does (written from
// Haply's Java hAPI, Board.java and Device.java: reset, setup with port
// masks, directions, analog pins and encoder offsets and resolutions,
// updates answered with the sensor values and the encoders' angles), with
// encoder counts, analog values, a wrong id, silence and an unplugged cable
// set by the test. The driver opens `path()`, a link to the current
// pseudo-terminal; replug() makes a new one behind the same link, as a USB
// board that comes back under the same name.
#pragma once

#include <poll.h>
#include <pty.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <bit>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace dm::test {

class HaplyBoardStandIn {
 public:
  /// What the last setup said (empty before one).
  struct Setup {
    int resets = 0, setups = 0, updates = 0;
    std::uint8_t id = 0, actuatorMask = 0, encoderMask = 0;
    std::vector<std::uint8_t> actuatorDirections, encoderDirections, sensorPins, pwmPins;
    std::vector<float> offsets, resolutions;  // per encoder, port order
  };

  explicit HaplyBoardStandIn(std::filesystem::path link) : link_(std::move(link)) { plug(); }
  ~HaplyBoardStandIn() {
    unplug();
    std::error_code ec;
    std::filesystem::remove(link_, ec);
  }
  HaplyBoardStandIn(const HaplyBoardStandIn&) = delete;
  HaplyBoardStandIn& operator=(const HaplyBoardStandIn&) = delete;

  std::string path() const { return link_.string(); }

  /// Encoder counts since power-up on `port` (1..4).
  void setCounts(int port, std::int32_t counts) {
    std::lock_guard lock(mutex_);
    counts_[port - 1] = counts;
  }
  /// The counts that make the encoder on `port` read `degrees` with the
  /// setup's offset, resolution and direction (after a setup).
  std::int32_t countsFor(int port, double degrees) const {
    std::lock_guard lock(mutex_);
    const int k = encoderIndex(port);
    const double sign = setup_.encoderDirections.at(k) == 0 ? 1.0 : -1.0;
    return static_cast<std::int32_t>(
        std::lround((degrees - setup_.offsets.at(k)) * setup_.resolutions.at(k) / 360.0 * sign));
  }
  /// The value of analog pin `pin` (54 + n for An).
  void setSensor(int pin, float value) {
    std::lock_guard lock(mutex_);
    sensors_[pin] = value;
  }
  /// Answers with this id instead of the one it was set up with (-1: that).
  void setAnswerId(int id) { answerId_ = id; }
  /// Stops answering (the firmware hung, or no firmware).
  void setSilent(bool silent) { silent_ = silent; }
  Setup setup() const {
    std::lock_guard lock(mutex_);
    return setup_;
  }
  /// The torque last received per port (0 for a port without actuator).
  std::array<float, 4> torques() const {
    std::lock_guard lock(mutex_);
    return torques_;
  }

  /// The cable pulled: the pseudo-terminal goes away (the driver's line
  /// hangs up).
  void unplug() {
    if (!thread_.joinable()) return;
    stop_ = true;
    thread_.join();
    ::close(master_);
    ::close(slave_);
    master_ = slave_ = -1;
  }
  /// Plugged in again: a new pseudo-terminal behind the same link, a board
  /// that has to be set up again.
  void replug() {
    unplug();
    plug();
  }

 private:
  void plug() {
    if (::openpty(&master_, &slave_, nullptr, nullptr, nullptr) != 0)
      throw std::runtime_error("openpty failed");
    termios t{};
    ::tcgetattr(slave_, &t);
    ::cfmakeraw(&t);
    ::tcsetattr(slave_, TCSANOW, &t);
    std::error_code ec;
    std::filesystem::remove(link_, ec);
    std::filesystem::create_symlink(::ttyname(slave_), link_);
    {
      std::lock_guard lock(mutex_);
      const int resets = setup_.resets, setups = setup_.setups, updates = setup_.updates;
      setup_ = Setup{};  // a board powered again knows no setup
      setup_.resets = resets, setup_.setups = setups, setup_.updates = updates;
      configured_ = false;
      torques_ = {};
    }
    in_.clear();
    stop_ = false;
    thread_ = std::thread([this] { run(); });
  }

  int encoderIndex(int port) const {
    return std::popcount(static_cast<unsigned>(setup_.encoderMask & ((1u << (port - 1)) - 1)));
  }

  void run() {
    std::uint8_t buf[256];
    while (!stop_) {
      pollfd p{master_, POLLIN, 0};
      if (::poll(&p, 1, 5) <= 0 || !(p.revents & POLLIN)) continue;
      const ssize_t n = ::read(master_, buf, sizeof buf);
      if (n <= 0) continue;
      in_.insert(in_.end(), buf, buf + n);
      while (parseOne()) {
      }
    }
  }

  static float floatAt(const std::uint8_t* p) {
    std::uint32_t bits = 0;
    for (int i = 0; i < 4; ++i) bits |= static_cast<std::uint32_t>(p[i]) << (8 * i);
    float v;
    std::memcpy(&v, &bits, 4);
    return v;
  }

  // Takes one whole message off in_; false when it is not all there yet.
  bool parseOne() {
    if (in_.empty()) return false;
    const std::uint8_t type = in_[0];
    if (type == 0) {
      if (in_.size() < 2) return false;
      in_.erase(in_.begin(), in_.begin() + 2);
      std::lock_guard lock(mutex_);
      ++setup_.resets;
      configured_ = false;
      return true;
    }
    if (type == 1) return parseSetup();
    if (type == 2) return parseUpdate();
    in_.erase(in_.begin());  // not a message type: skipped, as the firmware does
    return true;
  }

  bool parseSetup() {
    std::size_t at = 2;
    auto need = [&](std::size_t n) { return in_.size() >= at + n; };
    if (!need(1)) return false;
    const std::uint8_t amask = in_[at++];
    const int actuators = std::popcount(static_cast<unsigned>(amask));
    if (!need(actuators + 1)) return false;
    std::vector<std::uint8_t> adirs(in_.begin() + at, in_.begin() + at + actuators);
    at += actuators;
    const std::uint8_t emask = in_[at++];
    const int encoders = std::popcount(static_cast<unsigned>(emask));
    if (!need(encoders + 1)) return false;
    std::vector<std::uint8_t> edirs(in_.begin() + at, in_.begin() + at + encoders);
    at += encoders;
    const std::uint8_t sensors = in_[at++];
    if (!need(sensors + 1u)) return false;
    std::vector<std::uint8_t> pins(in_.begin() + at, in_.begin() + at + sensors);
    at += sensors;
    const std::uint8_t pwms = in_[at++];
    if (!need(pwms + 8u * encoders)) return false;
    std::vector<std::uint8_t> pwmPins(in_.begin() + at, in_.begin() + at + pwms);
    at += pwms;
    Setup s;
    s.id = in_[1];
    s.actuatorMask = amask;
    s.encoderMask = emask;
    s.actuatorDirections = adirs;
    s.encoderDirections = edirs;
    s.sensorPins = pins;
    s.pwmPins = pwmPins;
    for (int k = 0; k < encoders; ++k, at += 8) {
      s.offsets.push_back(floatAt(&in_[at]));
      s.resolutions.push_back(floatAt(&in_[at + 4]));
    }
    in_.erase(in_.begin(), in_.begin() + static_cast<std::ptrdiff_t>(at));
    std::lock_guard lock(mutex_);
    s.resets = setup_.resets;
    s.setups = setup_.setups + 1;
    s.updates = setup_.updates;
    setup_ = s;
    configured_ = true;
    return true;
  }

  bool parseUpdate() {
    std::vector<std::uint8_t> answer;
    {
      std::lock_guard lock(mutex_);
      const std::size_t pwms = setup_.pwmPins.size();
      const int actuators = std::popcount(static_cast<unsigned>(setup_.actuatorMask));
      const std::size_t size = 2 + pwms + 4u * static_cast<std::size_t>(actuators);
      if (in_.size() < size) return false;
      std::size_t at = 2 + pwms;
      for (int port = 1; port <= 4; ++port)
        if (setup_.actuatorMask & (1u << (port - 1))) {
          torques_[port - 1] = floatAt(&in_[at]);
          at += 4;
        }
      in_.erase(in_.begin(), in_.begin() + static_cast<std::ptrdiff_t>(size));
      ++setup_.updates;
      if (!configured_ || silent_) return true;
      const int id = answerId_.load();
      answer.push_back(static_cast<std::uint8_t>(id >= 0 ? id : setup_.id));
      auto put = [&](float v) {
        std::uint32_t bits;
        std::memcpy(&bits, &v, 4);
        for (int i = 0; i < 4; ++i) answer.push_back(static_cast<std::uint8_t>(bits >> (8 * i)));
      };
      for (std::uint8_t pin : setup_.sensorPins) put(sensors_.count(pin) ? sensors_.at(pin) : 0.0f);
      for (int port = 1; port <= 4; ++port)
        if (setup_.encoderMask & (1u << (port - 1))) {
          const int k = encoderIndex(port);
          const double sign = setup_.encoderDirections[k] == 0 ? 1.0 : -1.0;
          put(static_cast<float>(setup_.offsets[k] +
                                 sign * counts_[port - 1] * 360.0 / setup_.resolutions[k]));
        }
    }
    const ssize_t w = ::write(master_, answer.data(), answer.size());
    (void)w;
    return true;
  }

  std::filesystem::path link_;
  int master_ = -1, slave_ = -1;
  std::thread thread_;
  std::atomic<bool> stop_{false}, silent_{false};
  std::atomic<int> answerId_{-1};
  std::vector<std::uint8_t> in_;  // the run thread's
  mutable std::mutex mutex_;
  Setup setup_;
  bool configured_ = false;
  std::array<std::int32_t, 4> counts_{};
  std::map<int, float> sensors_;
  std::array<float, 4> torques_{};
};

}  // namespace dm::test
