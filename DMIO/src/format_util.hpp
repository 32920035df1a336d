// Private to DMIO: small helpers shared by the file-format readers and
// writers (NIfTI, MetaImage, NRRD, mesh import, volume_io), so that they
// parse text, check geometry and print numbers the same way.
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>

#include <cctype>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>
#include <utility>

namespace dm::detail {

/// A header is text; anything longer than this (without the line that ends
/// it) is not one.
inline constexpr std::size_t kMaxHeaderBytes = std::size_t{1} << 20;

/// ASCII lower case.
inline std::string lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

/// `s` without leading and trailing white space.
inline std::string_view trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

/// True when `s` ends with `suffix`.
inline bool endsWith(const std::string& s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

/// Shows at most 60 characters of untrusted text, non-printables escaped.
inline std::string shown(std::string_view s) { return shownText(s); }

/// `v` with 17 significant digits (reads back exactly); no "-0".
inline std::string fmt17(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v == 0 ? 0.0 : v);
  return buf;
}

/// A 3x3 block is unusable when its determinant is tiny relative to the
/// product of its column lengths (scale-free test for collinear columns).
inline bool isSingular(const Mat3& m) {
  const double scale = m.col(0).norm() * m.col(1).norm() * m.col(2).norm();
  return !(scale > 0) || !(std::abs(m.determinant()) > 1e-10 * scale);
}

/// The refusal of a volume whose declared size is over its reader's byte
/// budget, before anything is allocated: "<declared> needs <bytes> bytes,
/// more than the budget of <limit> bytes (<option>)", e.g. declared =
/// "DimSize 512x512x300 of MET_SHORT". Every volume reader words it so.
inline Error volumeOverBudget(const std::string& declared, std::uint64_t bytes, std::size_t limit,
                              std::string where, const std::string& option) {
  return fail(ErrorCode::InvalidArgument,
              declared + " needs " + std::to_string(bytes) + " bytes, more than the budget of " +
                  std::to_string(limit) + " bytes (" + option + ")",
              std::move(where),
              "raise " + option + " if the memory is there, or crop or downsample the volume");
}

/// Millimetre geometry written with %.17g must read back as a usable affine.
inline Status checkWritable(const Volume& v, const std::string& where) {
  if (v.empty())
    return fail(ErrorCode::InvalidArgument, "the volume is empty", where, "create it with Volume::create");
  const Mat3 lin = v.indexToWorld().linear() * 1e3;
  const Vec3 spacing = lin.colwise().norm().transpose();
  if (!lin.allFinite() || !(v.indexToWorld().translation() * 1e3).allFinite() || !spacing.allFinite() ||
      !(spacing.array() > 0).all())
    return fail(ErrorCode::InvalidArgument, "the index-to-world affine overflows in millimetres", where);
  return ok();
}

}  // namespace dm::detail
