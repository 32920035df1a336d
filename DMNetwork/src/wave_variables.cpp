// Wave-variable transformation and the energy-bounded wave receiver.
#include <dm/core/assert.hpp>
#include <dm/network/wave_variables.hpp>

#include <cmath>

namespace dm {

Vec3 waveForward(const Vec3& velocity, const Vec3& force, double impedance) {
  DM_ASSERT(impedance > 0.0, "wave impedance b must be > 0 (N·s/m)");
  return (impedance * velocity + force) / std::sqrt(2.0 * impedance);
}

Vec3 waveBackward(const Vec3& velocity, const Vec3& force, double impedance) {
  DM_ASSERT(impedance > 0.0, "wave impedance b must be > 0 (N·s/m)");
  return (impedance * velocity - force) / std::sqrt(2.0 * impedance);
}

Vec3 waveMasterForce(const Vec3& velocity, const Vec3& vIn, double impedance) {
  DM_ASSERT(impedance > 0.0, "wave impedance b must be > 0 (N·s/m)");
  return impedance * velocity - std::sqrt(2.0 * impedance) * vIn;
}

Vec3 waveMasterOut(const Vec3& velocity, const Vec3& vIn, double impedance) {
  DM_ASSERT(impedance > 0.0, "wave impedance b must be > 0 (N·s/m)");
  return std::sqrt(2.0 * impedance) * velocity - vIn;
}

Vec3 waveSlaveVelocity(const Vec3& uIn, const Vec3& force, double impedance) {
  DM_ASSERT(impedance > 0.0, "wave impedance b must be > 0 (N·s/m)");
  return (std::sqrt(2.0 * impedance) * uIn - force) / impedance;
}

Vec3 waveSlaveOut(const Vec3& uIn, const Vec3& force, double impedance) {
  DM_ASSERT(impedance > 0.0, "wave impedance b must be > 0 (N·s/m)");
  return uIn - std::sqrt(2.0 / impedance) * force;
}

WaveSender::WaveSender(double dt) : dt_(dt) {
  DM_DEMAND(dt > 0.0, "WaveSender: sample period dt must be > 0 s");
}

WaveSample WaveSender::send(const Vec3& wave) {
  energy_ += 0.5 * wave.squaredNorm() * dt_;
  return {.wave = wave, .sequence = ++sequence_, .energy = energy_};
}

WaveReceiver::WaveReceiver(WaveReceiverOptions options) : options_(options) {
  DM_DEMAND(options.dt > 0.0, "WaveReceiver: options.dt must be > 0 s");
}

void WaveReceiver::receive(const WaveSample& sample) {
  if (!sample.wave.allFinite() || !std::isfinite(sample.energy)) return;
  // The cumulative energy is monotone at the sender, so any sample (even a
  // late one) proves that at least this much has been sent.
  if (sample.energy > energyIn_) energyIn_ = sample.energy;
  if (haveSample_ && sample.sequence <= latestSequence_) {
    ++stats_.stale;
    return;
  }
  latest_ = sample.wave;
  latestSequence_ = sample.sequence;
  haveSample_ = true;
  fresh_ = true;
  ++stats_.received;
}

Vec3 WaveReceiver::next() {
  Vec3 out = Vec3::Zero();
  if (fresh_ || (haveSample_ && options_.policy == WaveLossPolicy::Hold)) out = latest_;
  if (!fresh_) ++stats_.held;
  fresh_ = false;
  const double want = 0.5 * out.squaredNorm() * options_.dt;
  const double budget = energyIn_ - energyOut_;
  if (want > budget) {
    // Scale so the output uses exactly the remaining budget (never negative).
    const double scale = budget > 0.0 ? std::sqrt(budget / want) : 0.0;
    out *= scale;
    // Rounding alone (a budget equal to the wave's energy) is not a limit.
    if (scale < 1.0 - 1e-9) ++stats_.limited;
    energyOut_ = budget > 0.0 ? energyIn_ : energyOut_;
  } else {
    energyOut_ += want;
  }
  return out;
}

WavePort::WavePort(WavePortOptions options)
    : options_(options), tx_(options.dt), rx_({.dt = options.dt, .policy = options.policy}) {
  DM_DEMAND(options.impedance > 0.0, "WavePort: wave impedance b must be > 0 N·s/m");
}

Vec3 WaveMasterPort::step(const Vec3& velocity) {
  const Vec3 v = rx_.next();
  out_ = tx_.send(waveMasterOut(velocity, v, options_.impedance));
  return -waveMasterForce(velocity, v, options_.impedance);  // the reaction on the hand
}

void WaveSlavePort::reset(const Vec3& position) {
  x_ = position;
  xDot_.setZero();
}

const WaveSample& WaveSlavePort::apply(const Vec3& environmentForce) {
  const double b = options_.impedance;
  // The port force is the slave's push on the environment plus the matched
  // damper's: Fp = −F + b·ẋs. With ẋs = (√(2b)·u − Fp)/b that is linear in
  // ẋs; solved: ẋs = (√(2b)·u + F)/(2b).
  xDot_ = (std::sqrt(2.0 * b) * u_ + environmentForce) / (2.0 * b);
  const Vec3 portForce = b * xDot_ - environmentForce;
  x_ += xDot_ * options_.dt;
  out_ = tx_.send(waveSlaveOut(u_, portForce, b));
  return out_;
}

}  // namespace dm
