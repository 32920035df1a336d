// SerialLine and the serial-posix driver over a pseudo-terminal pair: the
// driver opens the slave side, the test plays the device on the master
// side. Bytes cross both ways, timeouts return (checked against generous
// bounds only), settings reach the terminal, bad settings and paths give
// errors naming them, and a closed peer is reported as a loss.
#include <dm/io/serial.hpp>

#include <gtest/gtest.h>

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <numeric>
#include <string>
#include <vector>

#include "driver_test_support.hpp"

namespace {

using namespace std::chrono_literals;

// A pseudo-terminal: master fd for the test, slave path for the driver.
class Pty {
 public:
  Pty() {
    master_ = posix_openpt(O_RDWR | O_NOCTTY);
    if (master_ < 0 || grantpt(master_) != 0 || unlockpt(master_) != 0) return;
    char name[128] = "";
    if (ptsname_r(master_, name, sizeof name) == 0) slave_ = name;
  }
  ~Pty() { closeMaster(); }
  Pty(const Pty&) = delete;
  Pty& operator=(const Pty&) = delete;
  bool ok() const { return master_ >= 0 && !slave_.empty(); }
  int master() const { return master_; }
  const std::string& slave() const { return slave_; }
  void closeMaster() {
    if (master_ >= 0) ::close(master_);
    master_ = -1;
  }
  // Reads exactly n bytes from the master side (waiting up to 5 s in all).
  std::string readMaster(std::size_t n) {
    std::string out;
    const auto until = std::chrono::steady_clock::now() + 5s;
    while (out.size() < n && std::chrono::steady_clock::now() < until) {
      pollfd p{master_, POLLIN, 0};
      if (::poll(&p, 1, 100) <= 0) continue;
      char buf[4096];
      const ssize_t got = ::read(master_, buf, std::min(sizeof buf, n - out.size()));
      if (got > 0) out.append(buf, static_cast<std::size_t>(got));
    }
    return out;
  }

 private:
  int master_ = -1;
  std::string slave_;
};

std::span<const std::byte> bytes(const std::string& s) {
  return std::as_bytes(std::span(s.data(), s.size()));
}

// Reads exactly n bytes from the line (each call waits up to 1 s).
std::string readLine(dm::SerialLine& line, std::size_t n) {
  std::string out;
  std::vector<std::byte> buf(n);
  for (int tries = 0; tries < 50 && out.size() < n; ++tries) {
    auto got = line.read(std::span(buf.data(), n - out.size()), 1000ms);
    if (!got.ok()) {
      ADD_FAILURE() << got.error().message();
      break;
    }
    out.append(reinterpret_cast<const char*>(buf.data()), *got);
  }
  return out;
}

std::string pattern(std::size_t n, unsigned seed) {
  std::string s(n, '\0');
  for (std::size_t i = 0; i < n; ++i) s[i] = static_cast<char>((i * 131 + seed * 7 + (i >> 8)) & 0xff);
  return s;
}

TEST(SerialPosix, BytesCrossAPseudoTerminalBothWays) {
  Pty pty;
  ASSERT_TRUE(pty.ok()) << "posix_openpt failed";
  dm::test::PluginDriver plugin("serial_posix", "serial-posix");
  ASSERT_TRUE(plugin.loaded);
  auto line = dm::SerialLine::open(plugin.registry, "serial-posix",
                                   {{"path", pty.slave()}, {"baud", "9600"}, {"parity", "none"}});
  ASSERT_TRUE(line.ok()) << line.error().message();
  dm::SerialLine& l = **line;
  EXPECT_EQ(l.info().identity.driver, "serial-posix");
  EXPECT_EQ(l.info().path, pty.slave());
  EXPECT_EQ(l.info().config.baud, 9600u);
  EXPECT_EQ(l.info().config.dataBits, 8u);

  // Device → host: every byte value, raw (no translation of \r, \n, ^C, ^S ...).
  const std::string in = pattern(1000, 1);
  ASSERT_EQ(::write(pty.master(), in.data(), in.size()), static_cast<ssize_t>(in.size()));
  EXPECT_EQ(readLine(l, in.size()), in);

  // Host → device.
  const std::string out = pattern(2000, 2);
  auto sent = l.write(bytes(out), 1000ms);
  ASSERT_TRUE(sent.ok()) << sent.error().message();
  EXPECT_EQ(*sent, out.size());
  EXPECT_EQ(pty.readMaster(out.size()), out);
  EXPECT_EQ(l.counters().ioErrors, 0u);
}

TEST(SerialPosix, TimeoutsReturn) {
  Pty pty;
  ASSERT_TRUE(pty.ok());
  dm::test::BuiltinDrivers b;
  auto line = dm::SerialLine::open(b.registry, "serial-posix", {{"path", pty.slave()}});
  ASSERT_TRUE(line.ok()) << line.error().message();
  std::array<std::byte, 16> buf{};

  auto start = std::chrono::steady_clock::now();
  auto got = (*line)->read(buf, 50ms);  // nothing comes
  auto took = std::chrono::steady_clock::now() - start;
  ASSERT_TRUE(got.ok()) << got.error().message();
  EXPECT_EQ(*got, 0u);
  EXPECT_GE(took, 45ms);
  EXPECT_LT(took, 5s);

  got = (*line)->read(buf, 0ms);  // a poll
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(*got, 0u);

  // Nobody reads the master: the terminal's buffer fills and write stops at its timeout.
  const std::string big(4 << 20, 'x');
  start = std::chrono::steady_clock::now();
  auto sent = (*line)->write(bytes(big), 100ms);
  took = std::chrono::steady_clock::now() - start;
  ASSERT_TRUE(sent.ok()) << sent.error().message();
  EXPECT_LT(*sent, big.size());
  EXPECT_GT(*sent, 0u);
  EXPECT_LT(took, 5s);

  auto negative = (*line)->read(buf, -1ms);
  ASSERT_FALSE(negative.ok());
  EXPECT_EQ(negative.error().code, dm::ErrorCode::InvalidArgument);
}

TEST(SerialPosix, SettingsReachTheTerminal) {
  Pty pty;
  ASSERT_TRUE(pty.ok());
  dm::test::BuiltinDrivers b;
  auto line = dm::SerialLine::open(b.registry, "serial-posix",
                                   {{"path", pty.slave()},
                                    {"baud", "57600"},
                                    {"data_bits", "7"},
                                    {"parity", "even"},
                                    {"stop_bits", "2"},
                                    {"flow_control", "xonxoff"}});
  ASSERT_TRUE(line.ok()) << line.error().message();
  auto termiosOfSlave = [&] {
    termios t{};
    const int fd = ::open(pty.slave().c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK);
    EXPECT_GE(fd, 0);
    EXPECT_EQ(tcgetattr(fd, &t), 0);
    ::close(fd);
    return t;
  };
  // Linux pseudo-terminals force CS8 without parity (pty_set_termios), so
  // data bits and parity are checked in the settings the driver reports.
  termios t = termiosOfSlave();
  EXPECT_TRUE(t.c_cflag & CSTOPB);
  EXPECT_TRUE(t.c_iflag & IXON);
  EXPECT_FALSE(t.c_cflag & CRTSCTS);
  EXPECT_EQ(cfgetospeed(&t), static_cast<speed_t>(B57600));
  EXPECT_FALSE(t.c_lflag & (ICANON | ECHO));  // raw

  dm::SerialConfig c = (*line)->info().config;
  EXPECT_EQ(c.parity, dm::SerialParity::Even);
  EXPECT_EQ(c.flowControl, dm::SerialFlowControl::XonXoff);
  EXPECT_EQ(c.dataBits, 7u);
  EXPECT_EQ(c.stopBits, 2u);
  c = {.baud = 230400,
       .dataBits = 5,
       .parity = dm::SerialParity::Odd,
       .stopBits = 1,
       .flowControl = dm::SerialFlowControl::RtsCts};
  ASSERT_TRUE((*line)->configure(c).ok());
  t = termiosOfSlave();
  EXPECT_FALSE(t.c_cflag & CSTOPB);
  EXPECT_FALSE(t.c_iflag & IXON);
  EXPECT_TRUE(t.c_cflag & CRTSCTS);
  EXPECT_EQ((*line)->info().config.dataBits, 5u);
  EXPECT_EQ((*line)->info().config.parity, dm::SerialParity::Odd);
  EXPECT_EQ(cfgetospeed(&t), static_cast<speed_t>(B230400));
  EXPECT_EQ((*line)->info().config.baud, 230400u);

  // Unsupported settings name themselves and change nothing.
  const std::vector<std::pair<dm::SerialConfig, std::string>> bad = {
      {{.baud = 12345}, "'baud'"},
      {{.dataBits = 9}, "'data_bits'"},
      {{.stopBits = 3}, "'stop_bits'"},
      {{.parity = static_cast<dm::SerialParity>(7)}, "'parity'"},
      {{.flowControl = static_cast<dm::SerialFlowControl>(5)}, "'flow_control'"}};
  for (const auto& [config, needle] : bad) {
    const dm::Status s = (*line)->configure(config);
    ASSERT_FALSE(s.ok()) << needle;
    EXPECT_EQ(s.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(s.error().message().find(needle), std::string::npos) << s.error().message();
    EXPECT_NE(s.error().message().find(pty.slave()), std::string::npos) << s.error().message();
  }
  EXPECT_EQ((*line)->info().config.baud, 230400u);
  EXPECT_EQ(cfgetospeed(&t), static_cast<speed_t>(B230400));
}

TEST(SerialPosix, BadParametersAndPathsAreNamed) {
  Pty pty;
  ASSERT_TRUE(pty.ok());
  dm::test::BuiltinDrivers b;
  const std::vector<std::pair<dm::DeviceParams, std::string>> cases = {
      {{{"path", pty.slave()}, {"baud", "12345"}}, "'baud'"},
      {{{"path", pty.slave()}, {"baud", "-9600"}}, "'baud'"},
      {{{"path", pty.slave()}, {"baud", "fast"}}, "'baud'"},
      {{{"path", pty.slave()}, {"data_bits", "9"}}, "'data_bits'"},
      {{{"path", pty.slave()}, {"parity", "mark"}}, "'parity'"},
      {{{"path", pty.slave()}, {"stop_bits", "1.5"}}, "'stop_bits'"},
      {{{"path", pty.slave()}, {"flow_control", "dtrdsr"}}, "'flow_control'"},
      {{{"path", "/nonexistent/ttyUSB9"}}, "/nonexistent/ttyUSB9"},
      {{{"path", "/dev/null"}}, "'/dev/null' is not a terminal"},
      {{{"baud", "9600"}}, "'path'"},
      {{{"path", pty.slave()}, {"speed", "9600"}}, "'speed'"},
  };
  for (const auto& [params, needle] : cases) {
    auto line = dm::SerialLine::open(b.registry, "serial-posix", params);
    ASSERT_FALSE(line.ok()) << needle;
    EXPECT_EQ(line.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(line.error().message().find(needle), std::string::npos) << line.error().message();
  }
}

TEST(SerialPosix, AClosedPeerIsALoss) {
  Pty pty;
  ASSERT_TRUE(pty.ok());
  dm::test::BuiltinDrivers b;
  auto line = dm::SerialLine::open(b.registry, "serial-posix", {{"path", pty.slave()}});
  ASSERT_TRUE(line.ok()) << line.error().message();
  dm::SerialLine& l = **line;
  ASSERT_EQ(::write(pty.master(), "ab", 2), 2);
  EXPECT_EQ(readLine(l, 2), "ab");
  pty.closeMaster();  // the device goes away

  std::array<std::byte, 8> buf{};
  const auto start = std::chrono::steady_clock::now();
  auto got = l.read(buf, 2000ms);
  EXPECT_LT(std::chrono::steady_clock::now() - start, 1900ms);  // reported, not waited out
  ASSERT_FALSE(got.ok());
  EXPECT_EQ(got.error().code, dm::ErrorCode::Device);
  EXPECT_NE(got.error().message().find(pty.slave()), std::string::npos) << got.error().message();
  EXPECT_FALSE(l.connected());
  auto sent = l.write(bytes("x"), 100ms);  // fails fast while lost
  ASSERT_FALSE(sent.ok());
  EXPECT_EQ(sent.error().code, dm::ErrorCode::Device);
  const dm::Status again = l.reconnect();  // the pseudo-terminal is gone for good
  EXPECT_FALSE(again.ok());
  EXPECT_FALSE(l.connected());
  dm::DeviceEvent e;
  ASSERT_TRUE(l.pollEvent(e));
  EXPECT_EQ(e.type, dm::DeviceEventType::Lost);
  EXPECT_FALSE(l.pollEvent(e));
  EXPECT_EQ(l.counters().losses, 1u);
}

}  // namespace
