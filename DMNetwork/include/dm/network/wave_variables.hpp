// dm/network/wave_variables.hpp — wave-variable tele-operation (Niemeyer &
// Slotine) with an energy-bounded receiver that keeps the communication
// channel passive under any delay, jitter, loss, duplication or reordering.
//
// Per axis, with wave impedance b > 0 (N·s/m), velocity ẋ (m/s) and force F
// (N) at a channel port:
//   u = (b·ẋ + F) / √(2b)   (master → slave wave)
//   v = (b·ẋ − F) / √(2b)   (slave → master wave)
// and the power flowing into the channel is F·ẋ = (u² − v²)/2 (W). The master
// port measures ẋm, receives v and outputs Fm = b·ẋm − √(2b)·v and
// u = √(2b)·ẋm − v. The slave port receives u, measures the force Fs its
// controller applies, commands ẋs = (√(2b)·u − Fs)/b and sends
// v = u − √(2/b)·Fs.
//
// Signs: Fm is the force the operator applies to the master port, so a
// haptic device displays −Fm (pushes back on the hand); Fs is the force the
// slave applies to its environment, so with a simulated environment that
// pushes the tool with F_render, Fs = −F_render. At rest Fm = Fs: the hand
// feels exactly F_render.
//
// With a constant delay this channel is passive; with variable delay, loss
// or holding it is not by itself. WaveSender therefore stamps every wave
// sample with the cumulative wave energy sent so far, Σ|w|²/2·dt (J), and
// WaveReceiver never outputs more wave energy than it has been told was sent:
// each tick it outputs the newest sample (Hold) or zero when no new sample
// arrived (Zero), scaled down when needed so that its own cumulative output
// Σ|w_out|²/2·dt stays ≤ the largest cumulative energy received. Both wave
// directions bounded that way make the energy the channel delivers at its
// ports ≤ the energy put in, exactly, in discrete time.
//
// On top of these sit the two ports a tele-operation loop runs once per
// servo period (WaveMasterPort on the operator's device, WaveSlavePort
// where the environment is rendered). The slave port terminates the line
// with a matched damper β = b between the port and the environment: in free
// motion it absorbs the arriving wave instead of reflecting it (the slave
// then moves exactly at the master's velocity), so no wave circulates
// between two nearly lossless ends. Without it the discrete-time loop is
// not passive: a stiff rendered wall sampled once per period (zero-order
// hold) adds ½·k·Δx² per period, and with a stiff hand at the master (which
// reflects every wave) nothing takes it out again — the loop rings up even
// at 1 ms of delay. At rest the damper carries no force, so a steady
// contact force still reaches the operator unchanged.
//
// @code
//   dm::WaveSender tx(1e-3);  dm::WaveReceiver rx({.dt = 1e-3});
//   rx.receive(tx.send(dm::waveMasterOut(velocity, vIn, b)));
//   dm::Vec3 u = rx.next();
// @endcode
#pragma once

#include <dm/core/types.hpp>

#include <cstdint>

namespace dm {

/// u = (b·ẋ + F)/√(2b) per axis. b > 0 in N·s/m (DM_ASSERT). O(1).
Vec3 waveForward(const Vec3& velocity, const Vec3& force, double impedance);
/// v = (b·ẋ − F)/√(2b) per axis. b > 0 in N·s/m (DM_ASSERT). O(1).
Vec3 waveBackward(const Vec3& velocity, const Vec3& force, double impedance);

/// Master port: Fm = b·ẋm − √(2b)·v (N), the force the operator applies to
/// the port, from the measured master velocity (m/s) and the received
/// backward wave v; the device displays −Fm. O(1).
Vec3 waveMasterForce(const Vec3& velocity, const Vec3& vIn, double impedance);
/// Master port: the forward wave to send, u = √(2b)·ẋm − v. O(1).
Vec3 waveMasterOut(const Vec3& velocity, const Vec3& vIn, double impedance);
/// Slave port: the commanded slave velocity ẋs = (√(2b)·u − Fs)/b (m/s) from
/// the received forward wave u and the force Fs (N) the slave applies. O(1).
Vec3 waveSlaveVelocity(const Vec3& uIn, const Vec3& force, double impedance);
/// Slave port: the backward wave to send, v = u − √(2/b)·Fs. O(1).
Vec3 waveSlaveOut(const Vec3& uIn, const Vec3& force, double impedance);

/// One wave sample on the wire: the wave, the sender's counter and the
/// sender's cumulative wave energy including this sample (J).
struct WaveSample {
  Vec3 wave = Vec3::Zero();
  std::uint64_t sequence = 0;
  double energy = 0.0;
};

/// Stamps outgoing waves with a sequence number and the cumulative wave
/// energy Σ|w|²/2·dt. Real-time safe (no allocation); not thread-safe.
class WaveSender {
 public:
  /// `dt` is the sample period in seconds (> 0, DM_DEMAND).
  explicit WaveSender(double dt);
  /// Accounts `wave` for one period and returns the sample to transmit. O(1).
  WaveSample send(const Vec3& wave);
  /// Cumulative wave energy sent (J).
  double energy() const { return energy_; }

 private:
  double dt_;
  double energy_ = 0.0;
  std::uint64_t sequence_ = 0;
};

/// What a WaveReceiver outputs on a tick when no newer sample has arrived.
enum class WaveLossPolicy : std::uint8_t {
  Hold,  ///< repeat the newest sample (within the energy budget)
  Zero,  ///< output zero (no energy)
};

/// Settings of a WaveReceiver.
struct WaveReceiverOptions {
  double dt = 1e-3;                              ///< output period, s (> 0)
  WaveLossPolicy policy = WaveLossPolicy::Hold;  ///< treatment of missing samples
};

/// Counters of a WaveReceiver.
struct WaveReceiverStats {
  std::uint64_t received = 0;  ///< samples accepted as newest
  std::uint64_t stale = 0;     ///< duplicates or older than the newest (energy still used)
  std::uint64_t limited = 0;   ///< ticks whose output was scaled down by the energy budget
  std::uint64_t held = 0;      ///< ticks without a new sample
};

/// Reconstructs a wave stream after an unreliable link without creating
/// energy: Σ|output|²/2·dt never exceeds the largest cumulative energy
/// received. Real-time safe (no allocation); not thread-safe.
class WaveReceiver {
 public:
  /// `options.dt` must be > 0 (DM_DEMAND).
  explicit WaveReceiver(WaveReceiverOptions options = {});
  /// Takes one arrived sample, in any order, duplicates allowed; a sample
  /// with a non-finite wave or energy is ignored. O(1).
  void receive(const WaveSample& sample);
  /// The wave to use for the coming period, energy-bounded. O(1).
  Vec3 next();
  /// Largest cumulative energy received (J).
  double energyIn() const { return energyIn_; }
  /// Cumulative wave energy output by next() (J); ≤ energyIn().
  double energyOut() const { return energyOut_; }
  WaveReceiverStats stats() const { return stats_; }

 private:
  WaveReceiverOptions options_;
  Vec3 latest_ = Vec3::Zero();
  std::uint64_t latestSequence_ = 0;
  bool haveSample_ = false;
  bool fresh_ = false;
  double energyIn_ = 0.0;
  double energyOut_ = 0.0;
  WaveReceiverStats stats_;
};

/// Settings of a WaveMasterPort or WaveSlavePort.
struct WavePortOptions {
  double impedance = 40.0;                       ///< wave impedance b, N·s/m (> 0); same at both ports
  double dt = 1e-3;                              ///< servo period, s (> 0): the wave sample period
  WaveLossPolicy policy = WaveLossPolicy::Hold;  ///< the port's WaveReceiver policy
};

/// What both ports share: the settings, the sender of the outgoing wave and
/// the energy-bounded receiver of the incoming one.
class WavePort {
 public:
  /// Takes one arrived sample of the incoming wave (any order). O(1).
  void receive(const WaveSample& sample) { rx_.receive(sample); }
  /// The outgoing sample produced by the last period.
  const WaveSample& outgoing() const { return out_; }
  const WaveReceiver& receiver() const { return rx_; }

 protected:
  /// `options.impedance` and `options.dt` must be > 0 (DM_DEMAND).
  explicit WavePort(WavePortOptions options);
  WavePortOptions options_;
  WaveSender tx_;
  WaveReceiver rx_;
  WaveSample out_;
};

/// The master port: the operator's device. Each servo period, from the
/// device's measured velocity ẋm and the received backward wave v, it
/// gives the force to display, −Fm = −(b·ẋm − √(2b)·v), and the forward
/// wave to send, u = √(2b)·ẋm − v. Real-time safe; not thread-safe.
class WaveMasterPort : public WavePort {
 public:
  explicit WaveMasterPort(WavePortOptions options) : WavePort(options) {}
  /// One period: the force (N) the device should display for the measured
  /// velocity (m/s); the forward-wave sample to send is then outgoing(). O(1).
  Vec3 step(const Vec3& velocity);
};

/// The slave port: a virtual tool point the environment is rendered
/// against, moved by the forward wave. Each period, begin() takes the
/// received wave u; then apply(F) takes the force F (N) the environment
/// exerts on the tool at its current position, moves the tool for one
/// period with ẋs = (√(2b)·u + F)/(b + β) (matched damper β = b) and
/// returns the backward wave v = u − √(2/b)·(βẋs − F). Real-time safe; not
/// thread-safe.
class WaveSlavePort : public WavePort {
 public:
  explicit WaveSlavePort(WavePortOptions options) : WavePort(options) {}
  /// Places the tool (the master's position when the link starts).
  void reset(const Vec3& position);
  /// Starts a period: takes the wave u to use for it. O(1).
  void begin() { u_ = rx_.next(); }
  /// Ends the period with the environment's force on the tool (N): moves
  /// the tool and returns the backward-wave sample to send. O(1).
  const WaveSample& apply(const Vec3& environmentForce);
  /// Tool position (m) and its velocity over the last period (m/s).
  const Vec3& position() const { return x_; }
  const Vec3& velocity() const { return xDot_; }

 private:
  Vec3 u_ = Vec3::Zero();
  Vec3 x_ = Vec3::Zero();
  Vec3 xDot_ = Vec3::Zero();
};

}  // namespace dm
