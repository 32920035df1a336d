// Daq and the sim-daq driver: the plugin against the built-in, samples
// against the signal formulas, timestamps 1/rate apart, the device FIFO and
// the ring overflowing with exact overrun counts, noise statistics, loss and
// reconnection, and parameter errors.
#include <dm/io/daq.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "driver_test_support.hpp"

namespace {

using dm::test::kMs;
using Frames = std::vector<dm::DaqFrame>;

std::unique_ptr<dm::Daq> openDaqOrFail(const dm::FactoryRegistry& reg, const dm::DeviceParams& params) {
  auto d = dm::Daq::open(reg, "sim-daq", params);
  EXPECT_TRUE(d.ok()) << (d.ok() ? "" : d.error().message());
  return d.ok() ? std::move(*d) : nullptr;
}

// Reads everything queued; adds the overrun reported to *overrun.
Frames drain(dm::Daq& d, std::uint64_t* overrun = nullptr) {
  Frames all, chunk(1000);
  for (;;) {
    const dm::DaqReadResult r = d.read(chunk);
    if (overrun) *overrun += r.overrunFrames;
    all.insert(all.end(), chunk.begin(), chunk.begin() + static_cast<std::ptrdiff_t>(r.frames));
    if (r.frames < chunk.size()) return all;
  }
}

using dm::test::frac;

TEST(SimDaq, PluginAndBuiltInGiveIdenticalFrames) {
  dm::test::PluginDriver plugin("sim_daq", "sim-daq");
  ASSERT_TRUE(plugin.loaded);
  dm::test::BuiltinDrivers builtin;
  const dm::DeviceParams params = {{"channels", "3"}, {"noise", "0.1"}, {"seed", "5"}, {"rate", "2000"}};
  auto p = dm::Daq::open(plugin.registry, "sim-daq", params);
  auto b = dm::Daq::open(builtin.registry, "sim-daq", params);
  ASSERT_TRUE(p.ok() && b.ok());
  EXPECT_EQ((*p)->info().identity.driver, "sim-daq");
  EXPECT_EQ((*p)->info().identity.serial, "sim-5");
  EXPECT_EQ((*p)->info().channelCount, 3u);
  EXPECT_EQ((*p)->info().sampleRateHz, 2000.0);
  EXPECT_EQ((*p)->info().rangeMin, -10.0);
  EXPECT_EQ((*p)->info().fifoFrames, 4096u);
  for (std::int64_t k = 0; k <= 100; ++k) {
    ASSERT_EQ((*p)->acquire(k * 5 * kMs), dm::DeviceStatus::Ok);
    ASSERT_EQ((*b)->acquire(k * 5 * kMs), dm::DeviceStatus::Ok);
  }
  const Frames fp = drain(**p), fb = drain(**b);
  ASSERT_EQ(fp.size(), 1001u);  // 0.5 s at 2 kHz, both ends included
  ASSERT_EQ(fb.size(), fp.size());
  for (std::size_t i = 0; i < fp.size(); ++i) {
    ASSERT_EQ(fp[i].values, fb[i].values) << i;
    ASSERT_EQ(fp[i].timeNs, fb[i].timeNs) << i;
  }
}

TEST(SimDaq, SamplesFollowTheSignalFormulas) {
  dm::test::BuiltinDrivers b;
  auto d = openDaqOrFail(b.registry, {{"channels", "5"},
                                      {"rate", "1000"},
                                      {"ch0", "sine,2,5,0.5"},
                                      {"ch1", "square,1,10"},
                                      {"ch2", "ramp,3,2,-1"},
                                      {"ch3", "constant,0,1,1.5"},
                                      {"ch4", "sine,20,1"},  // clipped to ±range
                                      {"range", "12"}});
  ASSERT_TRUE(d);
  for (std::int64_t k = 0; k <= 100; ++k) d->acquire(k * 10 * kMs);
  const Frames f = drain(*d);
  ASSERT_EQ(f.size(), 1001u);
  const double pi = std::numbers::pi;
  for (std::size_t k = 0; k < f.size(); ++k) {
    const double t = 1e-3 * static_cast<double>(k);
    ASSERT_EQ(f[k].index, k);
    ASSERT_EQ(f[k].timeNs, static_cast<std::int64_t>(k) * kMs);
    EXPECT_NEAR(f[k].values[0], 0.5 + 2 * std::sin(2 * pi * 5 * t), 1e-12) << t;
    if (std::abs(frac(10 * t) - 0.5) > 1e-9 && frac(10 * t) > 1e-9) {  // away from the edges
      EXPECT_EQ(f[k].values[1], frac(10 * t) < 0.5 ? 1.0 : -1.0) << t;
    }
    EXPECT_NEAR(f[k].values[2], -1 + 3 * (2 * frac(2 * t) - 1), 1e-9) << t;
    EXPECT_EQ(f[k].values[3], 1.5);
    EXPECT_NEAR(f[k].values[4], std::clamp(20 * std::sin(2 * pi * t), -12.0, 12.0), 1e-12) << t;
    EXPECT_EQ(f[k].values[5], 0.0);  // beyond channelCount
  }
}

TEST(SimDaq, TimestampsAreOneOverTheRateApart) {
  dm::test::BuiltinDrivers b;
  auto d = openDaqOrFail(b.registry, {{"channels", "1"}, {"rate", "3000"}});  // period 333 333.3 ns
  ASSERT_TRUE(d);
  const std::int64_t start = 500 * kMs + 123;  // acquisition starts at the first acquire()
  for (std::int64_t k = 0; k <= 50; ++k) d->acquire(start + k * 2 * kMs);
  const Frames f = drain(*d);
  ASSERT_FALSE(f.empty());
  // The first frame is the first at or after `start`: index ceil(start·rate).
  EXPECT_EQ(f.front().index, static_cast<std::uint64_t>(std::ceil(1e-9 * static_cast<double>(start) * 3000)));
  EXPECT_GE(f.front().timeNs, start);
  EXPECT_LE(f.back().timeNs, start + 100 * kMs);
  EXPECT_GT(f.back().timeNs + 333334, start + 100 * kMs);  // nothing acquired up to the last call is missing
  for (std::size_t i = 0; i < f.size(); ++i) {
    ASSERT_EQ(f[i].index, f.front().index + i);
    // Frame k at k/rate seconds, rounded to the nanosecond.
    ASSERT_NEAR(static_cast<double>(f[i].timeNs), static_cast<double>(f[i].index) * 1e9 / 3000, 0.5) << i;
    if (i) {
      const std::int64_t dt = f[i].timeNs - f[i - 1].timeNs;
      ASSERT_TRUE(dt == 333333 || dt == 333334) << dt;
    }
  }
}

TEST(SimDaq, DeviceFifoOverflowIsReportedWithItsCount) {
  dm::test::BuiltinDrivers b;
  auto d = openDaqOrFail(b.registry, {{"channels", "2"}, {"rate", "1000"}, {"fifo", "100"}});
  ASSERT_TRUE(d);
  d->acquire(0);           // frame 0
  d->acquire(1000 * kMs);  // frames 1..1000 are due, the FIFO kept the last 100
  std::uint64_t overrun = 0;
  const Frames f = drain(*d, &overrun);
  ASSERT_EQ(f.size(), 101u);
  EXPECT_EQ(f[0].index, 0u);
  EXPECT_EQ(f[1].index, 901u);  // the gap shows where
  EXPECT_EQ(f.back().index, 1000u);
  EXPECT_EQ(overrun, 900u);
  EXPECT_EQ(d->counters().deviceOverrunFrames, 900u);
  EXPECT_EQ(d->counters().ringOverrunFrames, 0u);
  Frames again(4);
  EXPECT_EQ(d->read(again).overrunFrames, 0u);  // reported once
}

TEST(SimDaq, ConsumerFallingBehindGetsRingOverrunCounts) {
  dm::test::BuiltinDrivers b;
  auto d = openDaqOrFail(b.registry, {{"channels", "1"}, {"rate", "10000"}, {"fifo", "1000000"}});
  ASSERT_TRUE(d);
  for (std::int64_t k = 0; k <= 200; ++k) d->acquire(k * 10 * kMs);  // 2 s: frames 0..20000, nothing read
  const std::uint64_t produced = 20001;
  EXPECT_EQ(d->counters().acquiredFrames, dm::kDaqRingFrames);
  EXPECT_EQ(d->counters().ringOverrunFrames, produced - dm::kDaqRingFrames);
  Frames few(10);  // reading fewer than were produced
  const dm::DaqReadResult r = d->read(few);
  EXPECT_EQ(r.frames, 10u);
  EXPECT_EQ(r.overrunFrames, produced - dm::kDaqRingFrames);
  EXPECT_EQ(few[9].index, 9u);
  std::uint64_t overrun = 0;
  Frames rest = drain(*d, &overrun);
  EXPECT_EQ(overrun, 0u);
  ASSERT_EQ(rest.size(), dm::kDaqRingFrames - 10);
  EXPECT_EQ(rest.back().index, dm::kDaqRingFrames - 1);  // the oldest were kept, the newest dropped
  d->acquire(2010 * kMs);
  rest = drain(*d, &overrun);
  ASSERT_FALSE(rest.empty());
  EXPECT_EQ(rest.front().index, produced);  // acquisition went on; the gap is the overrun
  EXPECT_EQ(d->counters().readFrames, dm::kDaqRingFrames + rest.size());
}

TEST(SimDaq, NoiseIsGaussianWithTheRequestedSpreadAndRepeats) {
  dm::test::BuiltinDrivers b;
  auto run = [&](const char* seed) {
    auto d = openDaqOrFail(b.registry, {{"channels", "1"},
                                        {"ch0", "constant,0,1,0.25"},
                                        {"noise", "0.01"},
                                        {"seed", seed},
                                        {"rate", "10000"},
                                        {"fifo", "100000"}});
    Frames all;
    for (std::int64_t k = 0; k <= 20; ++k) {
      d->acquire(k * 100 * kMs);
      const Frames f = drain(*d);
      all.insert(all.end(), f.begin(), f.end());
    }
    return all;
  };
  const Frames a = run("11"), again = run("11"), other = run("12");
  ASSERT_EQ(a.size(), 20001u);
  double sum = 0, sum2 = 0;
  for (const auto& f : a) {
    sum += f.values[0] - 0.25;
    sum2 += (f.values[0] - 0.25) * (f.values[0] - 0.25);
  }
  const double n = static_cast<double>(a.size()), mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(sd, 0.01, 0.0003);  // 20001 samples: the estimate's sd is 0.5 %
  EXPECT_NEAR(mean, 0.0, 0.0003);
  ASSERT_EQ(again.size(), a.size());
  for (std::size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a[i].values[0], again[i].values[0]);
  EXPECT_NE(a[0].values[0], other[0].values[0]);
}

TEST(SimDaq, LossIsAnEventAndTheMissedFramesAreCounted) {
  dm::test::BuiltinDrivers b;
  auto d = openDaqOrFail(b.registry,
                         {{"channels", "1"}, {"rate", "1000"}, {"drop_at", "0.1"}, {"reconnect_at", "0.25"}});
  ASSERT_TRUE(d);
  Frames all;
  std::uint64_t overrun = 0;
  std::vector<dm::DeviceEvent> events;
  for (std::int64_t k = 0; k <= 400; ++k) {
    const dm::DeviceStatus s = d->acquire(k * kMs);
    EXPECT_EQ(s == dm::DeviceStatus::Lost, k >= 100 && k < 300) << k;
    const Frames f = drain(*d, &overrun);
    all.insert(all.end(), f.begin(), f.end());
    dm::DeviceEvent e;
    while (d->pollEvent(e)) events.push_back(e);
  }
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].type, dm::DeviceEventType::Lost);
  EXPECT_EQ(events[0].timeNs, 100 * kMs);
  EXPECT_EQ(events[1].type, dm::DeviceEventType::Reconnected);
  EXPECT_EQ(events[1].timeNs, 300 * kMs);
  ASSERT_EQ(all.size(), 100u + 101u);  // 0..99, then 300..400
  EXPECT_EQ(all[99].index, 99u);
  EXPECT_EQ(all[100].index, 300u);
  EXPECT_EQ(overrun, 200u);  // frames 100..299 were never acquired
  EXPECT_EQ(d->counters().device.losses, 1u);
}

TEST(SimDaq, BadParametersNameTheKey) {
  dm::test::BuiltinDrivers b;
  const std::vector<std::pair<dm::DeviceParams, std::string>> cases = {
      {{{"channels", "0"}}, "'channels'"},  {{{"channels", "17"}}, "'channels'"},
      {{{"rate", "-5"}}, "'rate'"},         {{{"rate", "fast"}}, "'rate'"},
      {{{"ch0", "triangle,1,1"}}, "'ch0'"}, {{{"channels", "2"}, {"ch5", "sine"}}, "'ch5'"},
      {{{"fifo", "0"}}, "'fifo'"},          {{{"noise", "-1"}}, "'noise'"},
      {{{"colour", "red"}}, "'colour'"},
  };
  for (const auto& [params, needle] : cases) {
    auto d = dm::Daq::open(b.registry, "sim-daq", params);
    ASSERT_FALSE(d.ok()) << needle;
    EXPECT_EQ(d.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_NE(d.error().message().find(needle), std::string::npos) << d.error().message();
  }
}

}  // namespace
