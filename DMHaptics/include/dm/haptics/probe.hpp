// dm/haptics/probe.hpp — replaying a scripted device path through a haptic
// renderer in lockstep: force regression tests and `dmtool probe`.
//
// The path (dm/io/device_path.hpp) is sampled at the tick rate from its first
// to its last time; each tick the renderer gets the interpolated device pose
// and the velocity over the tick (finite difference of consecutive poses),
// and its answer is kept as a ProbeSample. Nothing runs on a thread or a
// clock: the same renderer, path and rate give the same samples.
//
// @code
//   auto path = dm::readDevicePathCsv("press.csv");
//   auto samples = dm::replayDevicePath(*renderer, *path, 1000.0);
//   dm::writeFileAtomic("forces.csv", dm::formatProbeCsv(*samples));
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/haptics/renderer.hpp>
#include <dm/io/device_path.hpp>

#include <cstddef>
#include <span>
#include <string>
#include <vector>

namespace dm {

/// One tick of a replay.
struct ProbeSample {
  double t = 0.0;                                ///< s, path time of the tick
  Isometry3 devicePose = Isometry3::Identity();  ///< what the renderer was given
  HapticResponse response;                       ///< what it answered
};

/// Replays `path` through `renderer` at `rateHz` (ticks at start, start + 1/rate,
/// ... up to the end time inclusive; at least one tick). The renderer is
/// reset to the first pose first. Fails with InvalidArgument for a rate that
/// is not finite or ≤ 0, an empty path, or more than `maxTicks` ticks.
/// Allocates the result once; the renderer runs allocation-free.
Result<std::vector<ProbeSample>> replayDevicePath(HapticRenderer& renderer, const DevicePath& path,
                                                  double rateHz, std::size_t maxTicks = 100'000'000);

/// CSV with a header: t,fx,fy,fz,tx,ty,tz,px,py,pz,qw,qx,qy,qz,contacts,penetration
/// (force N and torque N·m on the hand, proxy pose), values in %.17g.
std::string formatProbeCsv(std::span<const ProbeSample> samples);

}  // namespace dm
