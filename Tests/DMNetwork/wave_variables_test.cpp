// Wave variables: the transformation's power identity and inverses, the
// energy-bounded receiver's budget under arbitrary arrival orders, and a
// 1 kHz master–slave system with a stiff virtual wall behind a delayed,
// jittery, lossy link: plain velocity/force exchange generates energy and
// goes unstable, wave variables keep the channel passive and the slave
// settles. Energies are integrated from the port power variables.
//
// The link is simulated in simulated time (same model as dm::LinkEmulator:
// fixed delay + uniform jitter, independent loss, reordering by jitter) so a
// 20 s experiment runs in milliseconds and is deterministic for its seed.
#include <dm/network/wave_variables.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <random>
#include <vector>

namespace {

using dm::Vec3;

TEST(WaveVariables, PowerIdentityAndInverses) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> d(-5.0, 5.0);
  for (int i = 0; i < 200; ++i) {
    const double b = 0.1 + std::abs(d(rng)) * 10.0;
    const Vec3 xdot(d(rng), d(rng), d(rng));
    const Vec3 f(d(rng), d(rng), d(rng));
    const Vec3 u = dm::waveForward(xdot, f, b);
    const Vec3 v = dm::waveBackward(xdot, f, b);
    // Power into the port equals the wave power difference.
    EXPECT_NEAR(f.dot(xdot), 0.5 * (u.squaredNorm() - v.squaredNorm()), 1e-9);
    // Master port: given ẋ and v, the force and u it computes reproduce (ẋ, F).
    EXPECT_LT((dm::waveMasterForce(xdot, v, b) - f).norm(), 1e-9);
    EXPECT_LT((dm::waveMasterOut(xdot, v, b) - u).norm(), 1e-9);
    // Slave port: given u and F, the velocity and v it computes reproduce (ẋ, v).
    EXPECT_LT((dm::waveSlaveVelocity(u, f, b) - xdot).norm(), 1e-9);
    EXPECT_LT((dm::waveSlaveOut(u, f, b) - v).norm(), 1e-9);
  }
}

TEST(WaveVariables, ConstantDelayPassesWavesUnchanged) {
  const double dt = 1e-3;
  dm::WaveSender tx(dt);
  dm::WaveReceiver rx({.dt = dt});
  std::deque<dm::WaveSample> line;
  for (int k = 0; k < 1000; ++k) {
    const Vec3 w(std::sin(0.01 * k), 0.5, -std::cos(0.02 * k));
    line.push_back(tx.send(w));
    if (line.size() > 20) {  // 20-tick delay, in order, no loss
      const dm::WaveSample s = line.front();
      line.pop_front();
      rx.receive(s);
      EXPECT_LT((rx.next() - s.wave).norm(), 1e-12) << "tick " << k;
    }
  }
  EXPECT_EQ(rx.stats().limited, 0u);
  EXPECT_NEAR(rx.energyOut(), rx.energyIn(), 1e-12);
}

TEST(WaveVariables, ReceiverNeverCreatesEnergy) {
  // Adversarial arrivals: duplicates, reordering, bursts and long gaps with
  // Hold, which without the budget would replay a large wave for ever.
  for (dm::WaveLossPolicy policy : {dm::WaveLossPolicy::Hold, dm::WaveLossPolicy::Zero}) {
    const double dt = 1e-3;
    dm::WaveSender tx(dt);
    dm::WaveReceiver rx({.dt = dt, .policy = policy});
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> d(-3.0, 3.0);
    std::vector<dm::WaveSample> pending;
    double outIntegral = 0.0;
    for (int k = 0; k < 5000; ++k) {
      pending.push_back(tx.send(Vec3(d(rng), d(rng), d(rng))));
      if (rng() % 7 == 0) {  // deliver a burst in random order, some twice
        std::shuffle(pending.begin(), pending.end(), rng);
        for (const auto& s : pending) {
          rx.receive(s);
          if (rng() % 3 == 0) rx.receive(s);
        }
        pending.clear();
      }
      const Vec3 w = rx.next();
      outIntegral += 0.5 * w.squaredNorm() * dt;
      ASSERT_LE(outIntegral, rx.energyIn() + 1e-12) << "tick " << k;
      ASSERT_LE(rx.energyIn(), tx.energy() + 1e-12);
    }
    EXPECT_NEAR(outIntegral, rx.energyOut(), 1e-9);
    EXPECT_GT(rx.stats().stale, 0u);
    EXPECT_GT(rx.stats().held, 0u);
    // The budget is used, not wasted: most of the sent energy comes out.
    if (policy == dm::WaveLossPolicy::Hold) {
      EXPECT_GT(outIntegral, 0.5 * tx.energy());
    } else {
      EXPECT_GT(outIntegral, 0.0);
    }
  }
}

TEST(WaveVariables, NonFiniteSamplesIgnored) {
  dm::WaveReceiver rx({.dt = 1e-3});
  rx.receive({.wave = Vec3(NAN, 0, 0), .sequence = 1, .energy = 1.0});
  rx.receive({.wave = Vec3(1, 0, 0), .sequence = 2, .energy = INFINITY});
  EXPECT_EQ(rx.energyIn(), 0.0);
  EXPECT_EQ(rx.next(), Vec3::Zero());
  EXPECT_EQ(rx.stats().received, 0u);
}

// ---- closed-loop experiment -------------------------------------------------

/// A simulated unreliable link in simulated time: each sample arrives after
/// delay + U[0, jitter] ticks or is lost; arrivals are returned in arrival
/// order (so jitter reorders).
template <class T>
class SimLink {
 public:
  SimLink(int delayTicks, int jitterTicks, double loss, std::uint64_t seed)
      : delay_(delayTicks), jitter_(jitterTicks), loss_(loss), rng_(seed) {}
  void submit(long now, const T& item) {
    ++submitted_;
    if (std::uniform_real_distribution<double>(0.0, 1.0)(rng_) < loss_) {
      ++lost_;
      return;
    }
    const long at = now + delay_ + std::uniform_int_distribution<int>(0, jitter_)(rng_);
    queue_.push_back({at, order_++, item});
  }
  template <class F>
  void deliver(long now, F&& f) {
    std::vector<Entry> due;
    for (auto it = queue_.begin(); it != queue_.end();) {
      if (it->at <= now) {
        due.push_back(*it);
        it = queue_.erase(it);
      } else {
        ++it;
      }
    }
    std::sort(due.begin(), due.end(),
              [](const Entry& a, const Entry& b) { return a.at != b.at ? a.at < b.at : a.order < b.order; });
    for (const auto& e : due) f(e.item);
  }
  double lossRate() const { return static_cast<double>(lost_) / static_cast<double>(submitted_); }

 private:
  struct Entry {
    long at;
    long order;
    T item;
  };
  int delay_, jitter_;
  double loss_;
  std::mt19937_64 rng_;
  std::vector<Entry> queue_;
  long order_ = 0;
  long submitted_ = 0, lost_ = 0;
};

struct Plant {
  // Master: mass held by the operator's hand, a spring-damper pulling
  // towards a target behind the wall.
  double mm = 0.5, xm = 0.0, vm = 0.0;
  double kHand = 200.0, bHand = 4.0, xHand = 0.05;
  // Slave: mass driven by its controller, stiff wall at xWall.
  double ms = 1.0, xs = 0.0, vs = 0.0;
  double kWall = 10000.0, bWall = 2.0, xWall = 0.02;

  double handForce() const { return kHand * (xHand - xm) - bHand * vm; }
  double wallForce() const { return xs > xWall ? kWall * (xs - xWall) + bWall * vs : 0.0; }
  void step(double dt, double masterFeedback, double slaveControl) {
    vm += dt * (handForce() - masterFeedback) / mm;
    xm += dt * vm;
    vs += dt * (slaveControl - wallForce()) / ms;
    xs += dt * vs;
  }
};

struct Outcome {
  double generated = 0.0;      ///< Σ(P_slave_port − P_master_port)·dt, J
  double peakGenerated = 0.0;  ///< max over time of the running value, J
  std::vector<double> swing;   ///< peak-to-peak slave position per 1 s window, m
  double lateSpeed = 0.0;      ///< max |slave velocity| in the last 2 s, m/s
  double finalX = 0.0;
  double lossRate = 0.0;
  bool diverged = false;   ///< |slave position| passed 1 m
  double handForce = 0.0;  ///< operator force on the master at the end, N
  double wallForce = 0.0;  ///< wall force on the slave at the end, N
};

constexpr double kDt = 1e-3;
constexpr int kDelayTicks = 100;  // 100 ms one way
constexpr int kJitterTicks = 20;  // + U[0, 20] ms
constexpr double kLoss = 0.05;
constexpr long kTicks = 20000;  // 20 s

/// Records one tick; returns false once the slave has diverged.
bool track(Outcome& o, long k, const Plant& p, double window[2]) {
  o.peakGenerated = std::max(o.peakGenerated, o.generated);
  window[0] = std::min(window[0], p.xs);
  window[1] = std::max(window[1], p.xs);
  if ((k + 1) % 1000 == 0) {
    o.swing.push_back(window[1] - window[0]);
    window[0] = 1e9;
    window[1] = -1e9;
  }
  if (k >= kTicks - 2000) o.lateSpeed = std::max(o.lateSpeed, std::abs(p.vs));
  o.finalX = p.xs;
  o.handForce = p.handForce();
  o.wallForce = p.wallForce();
  if (!std::isfinite(p.xs) || std::abs(p.xs) > 1.0) o.diverged = true;
  return !o.diverged;
}

/// Plain exchange: master position/velocity forward, slave controller force
/// back, both held at their latest value over losses.
Outcome runPlain(int delayTicks, int jitterTicks, double loss) {
  struct Fwd {
    long seq;
    double x, v;
  };
  struct Bwd {
    long seq;
    double f;
  };
  SimLink<Fwd> fwd(delayTicks, jitterTicks, loss, 21);
  SimLink<Bwd> bwd(delayTicks, jitterTicks, loss, 22);
  Plant p;
  const double kc = 2000.0, bc = 60.0;
  Fwd cmd{-1, 0.0, 0.0};
  Bwd fb{-1, 0.0};
  Outcome o;
  double window[2] = {1e9, -1e9};
  for (long k = 0; k < kTicks; ++k) {
    fwd.deliver(k, [&](const Fwd& m) {
      if (m.seq > cmd.seq) cmd = m;
    });
    bwd.deliver(k, [&](const Bwd& m) {
      if (m.seq > fb.seq) fb = m;
    });
    const double fs = kc * (cmd.x - p.xs) + bc * (cmd.v - p.vs);
    const double fm = fb.f;
    // Port powers: the channel takes F·ẋ from the master and gives F·ẋ_cmd to the slave.
    o.generated += (fs * cmd.v - fm * p.vm) * kDt;
    fwd.submit(k, {k, p.xm, p.vm});
    bwd.submit(k, {k, fs});
    p.step(kDt, fm, fs);
    if (!track(o, k, p, window)) break;
  }
  o.lossRate = fwd.lossRate();
  return o;
}

/// Wave variables: master sends u, slave sends v, both through WaveSender /
/// WaveReceiver; the slave's controller tracks the wave-commanded velocity.
Outcome runWave(dm::WaveLossPolicy policy, double* waveBalance = nullptr) {
  const double b = 40.0;  // N·s/m
  SimLink<dm::WaveSample> fwd(kDelayTicks, kJitterTicks, kLoss, 31);
  SimLink<dm::WaveSample> bwd(kDelayTicks, kJitterTicks, kLoss, 32);
  dm::WaveSender txM(kDt), txS(kDt);
  dm::WaveReceiver rxM({.dt = kDt, .policy = policy}), rxS({.dt = kDt, .policy = policy});
  Plant p;
  // Slave controller: F = bc·(ẋcmd − ẋs) + kc·(xcmd − xs), where xcmd
  // integrates the wave-commanded velocity (so contact force is held).
  const double bc = 300.0, kc = 3000.0;  // N·s/m, N/m
  double xcmd = 0.0;
  Outcome o;
  double window[2] = {1e9, -1e9};
  double waveIn = 0.0, waveOut = 0.0;
  for (long k = 0; k < kTicks; ++k) {
    fwd.deliver(k, [&](const dm::WaveSample& s) { rxS.receive(s); });
    bwd.deliver(k, [&](const dm::WaveSample& s) { rxM.receive(s); });
    // Master port.
    const Vec3 vm(p.vm, 0, 0);
    const Vec3 vIn = rxM.next();
    const Vec3 fm = dm::waveMasterForce(vm, vIn, b);
    const Vec3 uOut = dm::waveMasterOut(vm, vIn, b);
    // Slave port: F and ẋcmd = (√(2b)u − F)/b solved together (linear in F).
    const Vec3 uIn = rxS.next();
    const double g = bc + kc * kDt;
    const double fs = (g * std::sqrt(2.0 * b) * uIn.x() / b - bc * p.vs + kc * (xcmd - p.xs)) / (1.0 + g / b);
    const Vec3 fsV(fs, 0, 0);
    const Vec3 cmdV = dm::waveSlaveVelocity(uIn, fsV, b);
    xcmd += cmdV.x() * kDt;
    const Vec3 vOut = dm::waveSlaveOut(uIn, fsV, b);
    o.generated += (fsV.dot(cmdV) - fm.dot(vm)) * kDt;
    waveIn += 0.5 * (uOut.squaredNorm() + vOut.squaredNorm()) * kDt;
    waveOut += 0.5 * (uIn.squaredNorm() + vIn.squaredNorm()) * kDt;
    fwd.submit(k, txM.send(uOut));
    bwd.submit(k, txS.send(vOut));
    p.step(kDt, fm.x(), fs);
    if (!track(o, k, p, window)) break;
  }
  if (waveBalance) *waveBalance = waveIn - waveOut;
  o.lossRate = fwd.lossRate();
  return o;
}

TEST(WaveVariables, PlainExchangeUnstableAgainstStiffWall) {
  // Control: without delay the same controllers hold the contact stably.
  const Outcome direct = runPlain(0, 0, 0.0);
  ASSERT_FALSE(direct.diverged);
  EXPECT_LT(direct.swing.back(), 1e-4) << "m";
  EXPECT_NEAR(direct.wallForce, direct.handForce, 0.05 * direct.handForce);
  // With 100-120 ms each way and 5 % loss the channel generates energy and
  // the contact oscillation grows until the slave leaves the workspace.
  const Outcome o = runPlain(kDelayTicks, kJitterTicks, kLoss);
  EXPECT_GT(o.generated, 1.0) << "J";
  EXPECT_TRUE(o.diverged);
}

TEST(WaveVariables, WaveChannelPassiveAndSlaveSettles) {
  for (dm::WaveLossPolicy policy : {dm::WaveLossPolicy::Hold, dm::WaveLossPolicy::Zero}) {
    double waveBalance = 0.0;
    const Outcome o = runWave(policy, &waveBalance);
    SCOPED_TRACE(policy == dm::WaveLossPolicy::Hold ? "Hold" : "Zero");
    // The link really is lossy (binomial: 20000 draws at 5 %, σ ≈ 0.15 %).
    EXPECT_NEAR(o.lossRate, kLoss, 0.01);
    ASSERT_FALSE(o.diverged);
    ASSERT_EQ(o.swing.size(), static_cast<std::size_t>(kTicks / 1000));
    // Passivity: energy delivered by the channel at its ports never exceeds
    // the energy put in, at any instant; the wave-energy balance agrees.
    EXPECT_LE(o.peakGenerated, 1e-9) << "J";
    EXPECT_GE(waveBalance, -1e-9);
    EXPECT_NEAR(-o.generated, waveBalance, 1e-6 * (1.0 + waveBalance));
    // The slave reaches the wall and comes to rest against it.
    EXPECT_GT(o.finalX, 0.02 - 1e-3);
    EXPECT_LT(o.finalX, 0.02 + 5e-3);
    // At rest the wall's force reaches the operator: the hand balances it.
    // Zero drains the standing wave at every lost sample, so the contact
    // force leaks away (passive but transparent only with Hold).
    if (policy == dm::WaveLossPolicy::Hold) {
      EXPECT_GT(o.wallForce, 1.0) << "N";
      EXPECT_NEAR(o.wallForce, o.handForce, 0.05 * o.handForce);
    }
    EXPECT_LT(o.swing.back(), 1e-4) << "m";
    EXPECT_LT(o.lateSpeed, 1e-3) << "m/s";
  }
}

// ---- the ports, as a tele-operation stream runs them -----------------------
//
// The order of operations is the stream's, as HapticDevice::servo runs
// both ends (read the state, then write the last command): the operator's
// device (a hand of 0.5 kg on a 200 N/m spring, lightly damped, pulling
// 1 cm into the wall) gets the force computed from the velocity of its last
// servo, clamped to 20 N, for the next period; the simulator (net-haptic)
// reads the tool position at its servo, renders the environment there (a
// 2 kN/m wall rising under the tool to z = 0 over the first second), and
// that force moves the tool at the next servo's write — one period stale,
// held over the period (zero-order hold).

struct PortOutcome {
  bool diverged = false;
  double maxAbsTool = 0.0;       ///< m
  double swing = 0.0;            ///< peak-to-peak of the 100 ms means of the wall force, last second, N
  double wallForce = 0.0;        ///< mean over the last second, N
  double operatorForce = 0.0;    ///< displayed force, mean over the last second, N
  double handForce = 0.0;        ///< the hand's push into the wall at the end, N
  bool receiversBounded = true;  ///< energy out ≤ energy in at both receivers, every tick
};

/// `matched`: the library's WaveSlavePort; otherwise the textbook slave port
/// without the matched damper (ẋs and v from the same Fs), for contrast.
PortOutcome runPorts(int delayTicks, int jitterTicks, double loss, long ticks, bool matched) {
  const dm::WavePortOptions opt{.impedance = 40.0, .dt = kDt};
  SimLink<dm::WaveSample> fwd(delayTicks, jitterTicks, loss, 41);
  SimLink<dm::WaveSample> bwd(delayTicks, jitterTicks, loss, 42);
  dm::WaveMasterPort master(opt);
  dm::WaveSlavePort slave(opt);
  dm::WaveSender txPlain(kDt);
  dm::WaveReceiver rxPlain({.dt = kDt});
  const double mass = 0.5, kHand = 200.0, bHand = 4.0, xHand = -0.01, wall = 2000.0, maxForce = 20.0;
  double x = 0.0, v = 0.0;         // the hand and stylus
  double stateV = 0.0;             // velocity read at the last servo
  double displayed = 0.0;          // force acting on the hand now
  double command = 0.0;            // the simulator's last command: the wall force at the reported tool
  double toolPlain = 0.0;          // the unmatched slave's tool position
  PortOutcome o;
  double windowSum = 0.0, wMin = 1e9, wMax = -1e9, opSum = 0.0, wallSum = 0.0;
  slave.reset(Vec3::Zero());
  for (long k = 0; k < ticks; ++k) {
    fwd.deliver(k, [&](const dm::WaveSample& s) { matched ? slave.receive(s) : rxPlain.receive(s); });
    bwd.deliver(k, [&](const dm::WaveSample& s) { master.receive(s); });
    // Master: the force from the last servo's velocity, then the servo
    // (the hand moves under the previous force, 10 substeps), then the write.
    const double masterForce = master.step(Vec3(0, 0, stateV)).z();
    for (int i = 0; i < 10; ++i) {
      const double h = kDt / 10;
      v += h * (kHand * (xHand - x) - bHand * v + displayed) / mass;
      x += h * v;
    }
    stateV = v;
    displayed = std::clamp(masterForce, -maxForce, maxForce);
    fwd.submit(k, master.outgoing());
    // Slave servo: read (this period's wave; report the tool), then write
    // the last command (the move); then the simulator renders at the report.
    double tool = 0.0;
    if (matched) {
      slave.begin();
      tool = slave.position().z();
      bwd.submit(k, slave.apply(Vec3(0, 0, command)));
    } else {
      const Vec3 u = rxPlain.next();
      tool = toolPlain;
      const Vec3 fs(0, 0, -command);
      toolPlain += dm::waveSlaveVelocity(u, fs, opt.impedance).z() * kDt;
      bwd.submit(k, txPlain.send(dm::waveSlaveOut(u, fs, opt.impedance)));
    }
    const double surface = -0.05 * std::max(0.0, 1.0 - static_cast<double>(k) / 1000.0);
    command = tool < surface ? wall * (surface - tool) : 0.0;
    o.maxAbsTool = std::max(o.maxAbsTool, std::abs(tool));
    if (master.receiver().energyOut() > master.receiver().energyIn() + 1e-12 ||
        slave.receiver().energyOut() > slave.receiver().energyIn() + 1e-12)
      o.receiversBounded = false;
    if (!std::isfinite(tool) || std::abs(tool) > 1.0) {
      o.diverged = true;
      return o;
    }
    if (k >= ticks - 1000) {
      windowSum += command;
      wallSum += command;
      opSum += displayed;
      if ((k + 1) % 100 == 0) {
        wMin = std::min(wMin, windowSum / 100);
        wMax = std::max(wMax, windowSum / 100);
        windowSum = 0.0;
      }
    }
  }
  o.swing = wMax - wMin;
  o.wallForce = wallSum / 1000;
  o.operatorForce = opSum / 1000;
  o.handForce = kHand * (x - xHand);  // the hand pushing the stylus into the wall
  return o;
}

TEST(WavePorts, TextbookSlavePortRingsUpAgainstAStiffWall) {
  // Control for the next test: without the matched damper the same loop
  // diverges with one period of delay each way.
  const PortOutcome o = runPorts(1, 0, 0.0, 3000, false);
  EXPECT_TRUE(o.diverged);
}

TEST(WavePorts, MatchedPortsHoldAStiffContactUnderDelayJitterAndLoss) {
  struct Case {
    int delay, jitter;
    double loss;
    long ticks;
  };
  // One-way delays from one period to 100 ms; the long ones need longer to settle.
  for (const Case c : {Case{1, 0, 0.0, 3000}, Case{5, 2, 0.02, 3000}, Case{20, 5, 0.05, 5000},
                       Case{100, 20, 0.05, 20000}}) {
    SCOPED_TRACE(testing::Message() << "delay " << c.delay << " ms, jitter " << c.jitter << " ms, loss " << c.loss);
    const PortOutcome o = runPorts(c.delay, c.jitter, c.loss, c.ticks, true);
    ASSERT_FALSE(o.diverged);
    EXPECT_TRUE(o.receiversBounded);
    EXPECT_LT(o.maxAbsTool, 0.05) << "m";  // never pushed far through the wall
    EXPECT_GT(o.wallForce, 0.5) << "N";     // in contact
    EXPECT_LT(o.swing, 0.02) << "N";        // settled
    // At rest the operator feels the rendered force, and holds it with the hand.
    EXPECT_NEAR(o.operatorForce, o.wallForce, 0.02 * o.wallForce);
    EXPECT_NEAR(o.handForce, o.wallForce, 0.05 * o.wallForce);
  }
}

TEST(WavePorts, FreeMotionSlaveTracksTheMasterVelocity) {
  // Matched termination: with no environment force the slave absorbs the
  // forward wave, so v = 0 and ẋs = ẋm exactly; the master feels b·ẋm.
  const double b = 40.0;
  dm::WaveMasterPort master({.impedance = b, .dt = kDt});
  dm::WaveSlavePort slave({.impedance = b, .dt = kDt});
  slave.reset(Vec3(0.1, 0, 0));
  for (int k = 0; k < 100; ++k) {
    const Vec3 velocity(0.02 * std::sin(0.05 * k), 0.01, -0.03);
    const Vec3 force = master.step(velocity);
    EXPECT_LT((force + b * velocity).norm(), 1e-12);
    slave.receive(master.outgoing());
    slave.begin();
    const dm::WaveSample back = slave.apply(Vec3::Zero());
    EXPECT_LT(back.wave.norm(), 1e-12);
    EXPECT_LT((slave.velocity() - velocity).norm(), 1e-12);
    master.receive(back);
  }
}

}  // namespace
