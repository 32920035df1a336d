// Lockstep replay of device paths through a renderer (dm/haptics/probe.hpp).
#include <dm/haptics/probe.hpp>

#include <cmath>
#include <cstdint>
#include <cstdio>

namespace dm {

Result<std::vector<ProbeSample>> replayDevicePath(HapticRenderer& renderer, const DevicePath& path,
                                                  double rateHz, std::size_t maxTicks) {
  if (!std::isfinite(rateHz) || rateHz <= 0.0)
    return fail(ErrorCode::InvalidArgument, formatString("tick rate is %g Hz", rateHz), "rate",
                "give a finite rate > 0, e.g. 1000");
  if (path.samples.empty()) return fail(ErrorCode::InvalidArgument, "the device path has no samples", "path");
  const double dt = 1.0 / rateHz;
  const double span = path.endTime() - path.startTime();
  const double ticksReal = std::floor(span * rateHz + 1e-9) + 1.0;
  if (!(ticksReal <= static_cast<double>(maxTicks)))
    return fail(ErrorCode::InvalidArgument,
                formatString("%.0f ticks (%.6g s at %g Hz) exceed the limit of %zu", ticksReal, span, rateHz,
                             maxTicks),
                "path", "lower the rate or shorten the path");
  const auto ticks = static_cast<std::size_t>(ticksReal);
  std::vector<ProbeSample> out(ticks);

  Pose previous = path.at(path.startTime());
  renderer.reset(previous.isometry());
  for (std::size_t i = 0; i < ticks; ++i) {
    const double t = path.startTime() + static_cast<double>(i) * dt;
    const Pose pose = path.at(t);
    HapticInput in;
    in.timeNs = static_cast<std::int64_t>(std::llround(t * 1e9));
    in.dt = dt;
    in.devicePose = pose.isometry();
    in.linearVelocity = (pose.p - previous.p) / dt;
    const AngleAxis turn(pose.q * previous.q.conjugate());
    in.angularVelocity = turn.axis() * (turn.angle() / dt);
    if (!in.angularVelocity.allFinite()) in.angularVelocity.setZero();
    out[i].t = t;
    out[i].devicePose = in.devicePose;
    out[i].response = renderer.tick(in);
    previous = pose;
  }
  return out;
}

std::string formatProbeCsv(std::span<const ProbeSample> samples) {
  std::string out = "t,fx,fy,fz,tx,ty,tz,px,py,pz,qw,qx,qy,qz,contacts,penetration\n";
  char buf[512];
  for (const ProbeSample& s : samples) {
    const HapticResponse& r = s.response;
    const Quat q(r.proxyPose.rotation());
    const Vec3 p = r.proxyPose.translation();
    const int n =
        std::snprintf(buf, sizeof buf,
                      "%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,"
                      "%d,%.17g\n",
                      s.t, r.force.x(), r.force.y(), r.force.z(), r.torque.x(), r.torque.y(), r.torque.z(),
                      p.x(), p.y(), p.z(), q.w(), q.x(), q.y(), q.z(), r.contacts, r.penetration);
    out.append(buf, static_cast<std::size_t>(n));
  }
  return out;
}

}  // namespace dm
