// dm/io/device_path.hpp — scripted device paths as CSV: the input of
// `dmtool probe` and of force regression tests that replay a motion through
// a haptic renderer in lockstep.
//
// Format (SI units, one sample per line):
//   t,x,y,z                     time (s) and device point (m), or
//   t,x,y,z,qw,qx,qy,qz         plus the handle orientation (unit quaternion)
// An optional header line naming exactly those columns may come first;
// blank lines and lines starting with '#' are skipped; CRLF line ends are
// accepted. Every row has the same number of fields, every value is finite,
// times strictly increase. Quaternions are normalised (any non-zero length
// is accepted; a zero one is an error). Errors name the source, the line,
// the column and the field.
//
// @code
//   auto path = dm::readDevicePathCsv("press.csv");
//   if (!path) return path.error();
//   dm::Pose p = path->at(0.25);   // interpolated device pose at t = 0.25 s
// @endcode
#pragma once

#include <dm/core/pose.hpp>
#include <dm/core/result.hpp>

#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace dm {

/// One row of a device path.
struct DevicePathSample {
  double t = 0.0;                       ///< s
  Vec3 position = Vec3::Zero();         ///< m
  Quat orientation = Quat::Identity();  ///< unit; identity when the file has no orientation columns
};

/// A device path: samples in strictly increasing time.
struct DevicePath {
  std::vector<DevicePathSample> samples;
  bool hasOrientation = false;  ///< the file had the qw,qx,qy,qz columns

  /// Time of the first and the last sample, s (0 for an empty path).
  double startTime() const noexcept { return samples.empty() ? 0.0 : samples.front().t; }
  double endTime() const noexcept { return samples.empty() ? 0.0 : samples.back().t; }
  /// Pose at time t: linear in position, slerp in orientation between the
  /// neighbouring samples; held at the ends. O(log n). Identity when empty.
  Pose at(double t) const noexcept;
};

/// Limits of the CSV reader.
struct DevicePathReadOptions {
  std::size_t maxSamples = 10'000'000;  ///< more rows than this is an error (bounded memory)
};

/// Parses CSV text (see the file comment). `source` names the text in
/// errors. Fails with Parse (bad number, wrong field count, bad header,
/// non-increasing time, zero quaternion, no samples: line, column and field
/// named) or InvalidArgument (more than options.maxSamples rows). O(bytes).
/// @code
///   auto path = dm::parseDevicePathCsv("t,x,y,z\n0,0,0,0.01\n0.001,0,0,0.0099\n", "inline");
///   if (!path) return path.error();
/// @endcode
Result<DevicePath> parseDevicePathCsv(std::string_view text, std::string_view source = "<memory>",
                                      const DevicePathReadOptions& options = {});

/// Reads and parses a CSV file; Io/NotFound errors name the file.
Result<DevicePath> readDevicePathCsv(const std::filesystem::path& file,
                                     const DevicePathReadOptions& options = {});

/// The path as CSV with a header line, values printed to round-trip exactly
/// (%.17g): parsing the text gives the same times and positions bit for bit
/// and the same orientations to within a rounding of the normalisation.
std::string formatDevicePathCsv(const DevicePath& path);

}  // namespace dm
