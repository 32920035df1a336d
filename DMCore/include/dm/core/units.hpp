// dm/core/units.hpp — SI units and conversions.
//
// Every quantity in the SDK API is SI: metres, kilograms, seconds, newtons,
// newton-metres, radians. File formats in other units (NIfTI and DICOM in
// millimetres, STL often in millimetres) are converted by their importers
// with these factors. Multiply a value in the named unit to get SI:
//   double d = 12.5 * dm::units::mm;   // 0.0125 m
#pragma once

#include <numbers>

namespace dm::units {
inline constexpr double m = 1.0;
inline constexpr double cm = 1e-2;
inline constexpr double mm = 1e-3;
inline constexpr double um = 1e-6;
inline constexpr double inch = 0.0254;
inline constexpr double kg = 1.0;
inline constexpr double g = 1e-3;
inline constexpr double s = 1.0;
inline constexpr double ms = 1e-3;
inline constexpr double us = 1e-6;
inline constexpr double ns = 1e-9;
inline constexpr double N = 1.0;
inline constexpr double Nmm = 1e-3;  ///< newton-millimetre, in N·m
inline constexpr double Pa = 1.0;
inline constexpr double kPa = 1e3;
inline constexpr double rad = 1.0;
inline constexpr double deg = std::numbers::pi / 180.0;
inline constexpr double Hz = 1.0;
inline constexpr double kHz = 1e3;
/// Standard gravity, m/s².
inline constexpr double g0 = 9.80665;
}  // namespace dm::units
