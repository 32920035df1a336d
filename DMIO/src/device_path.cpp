// Device path CSV reader and writer (dm/io/device_path.hpp).
#include <dm/core/filesystem.hpp>
#include <dm/io/device_path.hpp>

#include <algorithm>
#include <array>
#include <charconv>
#include <cctype>
#include <cmath>
#include <cstdio>

namespace dm {
namespace {

constexpr std::array<std::string_view, 8> kColumns = {"t", "x", "y", "z", "qw", "qx", "qy", "qz"};

std::string_view trimBlanks(std::string_view s) noexcept {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

bool equalsIgnoreCase(std::string_view a, std::string_view b) noexcept {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           const auto lower = [](char c) {
             return c >= 'A' && c <= 'Z' ? static_cast<char>(c - 'A' + 'a') : c;
           };
           return lower(x) == lower(y);
         });
}

// Splits a line at commas into at most 9 fields (one more than the widest
// row, so that too many fields are detected); returns the count.
int splitFields(std::string_view line, std::array<std::string_view, 9>& fields,
                std::array<std::size_t, 9>& columns) noexcept {
  int n = 0;
  std::size_t start = 0;
  while (n < 9) {
    const std::size_t comma = line.find(',', start);
    const std::size_t end = comma == std::string_view::npos ? line.size() : comma;
    columns[n] = start + 1;
    fields[n++] = trimBlanks(line.substr(start, end - start));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return n;
}

}  // namespace

Pose DevicePath::at(double t) const noexcept {
  if (samples.empty()) return {};
  if (!(t > samples.front().t)) return {samples.front().position, samples.front().orientation};
  if (t >= samples.back().t) return {samples.back().position, samples.back().orientation};
  const auto hi = std::upper_bound(samples.begin(), samples.end(), t,
                                   [](double value, const DevicePathSample& s) { return value < s.t; });
  const DevicePathSample& b = *hi;
  const DevicePathSample& a = *(hi - 1);
  const double u = (t - a.t) / (b.t - a.t);
  return Pose::interpolate({a.position, a.orientation}, {b.position, b.orientation}, u);
}

Result<DevicePath> parseDevicePathCsv(std::string_view text, std::string_view source,
                                      const DevicePathReadOptions& options) {
  DevicePath path;
  int width = 0;  // fields per row, 4 or 8, fixed by the header or the first row
  std::size_t lineNo = 0;
  std::array<std::string_view, 9> fields;
  std::array<std::size_t, 9> columns{};
  const std::string src(source);
  const auto where = [&](std::size_t column) {
    return formatString("%s:%zu:%zu", src.c_str(), lineNo, column);
  };
  const std::string hint = "each row is t,x,y,z or t,x,y,z,qw,qx,qy,qz in SI units (s, m)";

  std::size_t pos = 0;
  while (pos < text.size()) {
    const std::size_t nl = text.find('\n', pos);
    const std::size_t end = nl == std::string_view::npos ? text.size() : nl;
    const std::string_view line = trimBlanks(text.substr(pos, end - pos));
    pos = end + 1;
    ++lineNo;
    if (line.empty() || line.front() == '#') continue;
    const int n = splitFields(line, fields, columns);

    // A header is allowed once, before any data row.
    const bool numeric =
        !fields[0].empty() && (std::isdigit(static_cast<unsigned char>(fields[0][0])) ||
                               fields[0][0] == '-' || fields[0][0] == '+' || fields[0][0] == '.');
    if (!numeric && width == 0 && path.samples.empty()) {
      if (n != 4 && n != 8)
        return fail(ErrorCode::Parse,
                    formatString("header has %d column%s; expected 4 or 8", n, n > 8 ? "s or more" : "s"),
                    where(1), hint);
      for (int i = 0; i < n; ++i)
        if (!equalsIgnoreCase(fields[i], kColumns[i]))
          return fail(
              ErrorCode::Parse,
              formatString("header column %d is '%.*s'; expected '%.*s'", i + 1,
                           static_cast<int>(std::min<std::size_t>(fields[i].size(), 32)), fields[i].data(),
                           static_cast<int>(kColumns[i].size()), kColumns[i].data()),
              where(columns[i]), hint);
      width = n;
      continue;
    }
    if (width == 0) {
      if (n != 4 && n != 8)
        return fail(ErrorCode::Parse,
                    formatString("row has %d field%s; expected 4 or 8", n, n > 8 ? "s or more" : "s"),
                    where(1), hint);
      width = n;
    } else if (n != width) {
      return fail(
          ErrorCode::Parse,
          formatString("row has %d field%s; the path has %d columns", n, n > 8 ? "s or more" : "s", width),
          where(1), hint);
    }
    if (path.samples.size() >= options.maxSamples)
      return fail(ErrorCode::InvalidArgument, formatString("more than %zu samples", options.maxSamples),
                  where(1), "raise DevicePathReadOptions::maxSamples or shorten the path");

    double v[8] = {0, 0, 0, 0, 1, 0, 0, 0};
    for (int i = 0; i < n; ++i) {
      const std::string_view f = fields[i];
      const char* first = f.data();
      const char* last = f.data() + f.size();
      if (!f.empty() && *first == '+') ++first;
      const auto [ptr, ec] = std::from_chars(first, last, v[i]);
      if (f.empty() || ec != std::errc() || ptr != last || !std::isfinite(v[i]))
        return fail(
            ErrorCode::Parse,
            formatString("field '%.*s' is '%.*s', not a finite number", static_cast<int>(kColumns[i].size()),
                         kColumns[i].data(), static_cast<int>(std::min<std::size_t>(f.size(), 32)), f.data()),
            where(columns[i]), hint);
    }
    DevicePathSample s;
    s.t = v[0];
    s.position = Vec3(v[1], v[2], v[3]);
    if (!path.samples.empty() && !(s.t > path.samples.back().t))
      return fail(
          ErrorCode::Parse,
          formatString("time %.17g s does not increase (previous row: %.17g s)", s.t, path.samples.back().t),
          where(columns[0]), "sort the rows by time and remove duplicates");
    if (width == 8) {
      Quat q(v[4], v[5], v[6], v[7]);
      const double norm = q.norm();
      if (!(norm > 1e-12) || !std::isfinite(norm))
        return fail(ErrorCode::Parse, "quaternion qw,qx,qy,qz has zero length", where(columns[4]), hint);
      q.coeffs() /= norm;
      s.orientation = q;
    }
    path.samples.push_back(s);
  }
  if (path.samples.empty()) return fail(ErrorCode::Parse, "no samples", src, hint);
  path.hasOrientation = width == 8;
  return path;
}

Result<DevicePath> readDevicePathCsv(const std::filesystem::path& file,
                                     const DevicePathReadOptions& options) {
  // 200 bytes a row is generous for 8 numbers in %.17g; bound the read by it.
  const std::size_t maxBytes = std::min<std::size_t>(options.maxSamples, std::size_t{1} << 40) * 200 + 4096;
  auto bytes = readFile(file, maxBytes);
  if (!bytes) return bytes.error();
  const std::string_view text(reinterpret_cast<const char*>(bytes->data()), bytes->size());
  return parseDevicePathCsv(text, file.string(), options);
}

std::string formatDevicePathCsv(const DevicePath& path) {
  std::string out = path.hasOrientation ? "t,x,y,z,qw,qx,qy,qz\n" : "t,x,y,z\n";
  char buf[256];
  for (const DevicePathSample& s : path.samples) {
    int n = std::snprintf(buf, sizeof buf, "%.17g,%.17g,%.17g,%.17g", s.t, s.position.x(), s.position.y(),
                          s.position.z());
    out.append(buf, static_cast<std::size_t>(n));
    if (path.hasOrientation) {
      n = std::snprintf(buf, sizeof buf, ",%.17g,%.17g,%.17g,%.17g", s.orientation.w(), s.orientation.x(),
                        s.orientation.y(), s.orientation.z());
      out.append(buf, static_cast<std::size_t>(n));
    }
    out += '\n';
  }
  return out;
}

}  // namespace dm
