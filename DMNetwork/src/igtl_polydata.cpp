// OpenIGTLink POLYDATA ⇄ dm::Mesh.
//
// Wire layout (big-endian): npoints, nvertices, size_vertices, nlines,
// size_lines, npolygons, size_polygons, ntriangle_strips,
// size_triangle_strips, nattributes (u32 each); points float32[3·npoints]
// (mm); then the vertex, line, polygon and strip cell arrays, each a run of
// (n, i1 .. in) u32 words of the stated byte size; then the attributes.
#include <cmath>

#include "igtl_wire.hpp"

namespace dm::igtl {

using namespace wire;

namespace {

constexpr std::size_t kPolyHeaderBytes = 40;

// Walks `cells` cells in `words` u32 words at content offset `off`, calling
// onCell(first word pointer, n) per cell after checking its indices.
template <class OnCell>
Status walkCells(const MessageView& m, std::size_t off, std::size_t bytes, std::uint32_t cells,
                 std::uint32_t npoints, const char* kind, OnCell&& onCell) {
  const std::byte* p = m.content.data() + off;
  const std::size_t words = bytes / 4;
  std::size_t w = 0;
  for (std::uint32_t c = 0; c < cells; ++c) {
    if (w >= words)
      return bad(m, off + 4 * w, ErrorCode::Parse,
                 formatString("POLYDATA %s: cell %u starts past the %zu-byte cell array", kind, c, bytes));
    const std::size_t n = getBe32(p + 4 * w);
    if (n > words - w - 1)
      return bad(m, off + 4 * w, ErrorCode::Parse,
                 formatString("POLYDATA %s: cell %u claims %zu indices, %zu words remain", kind, c, n,
                              words - w - 1));
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint32_t idx = getBe32(p + 4 * (w + 1 + i));
      if (idx >= npoints)
        return bad(
            m, off + 4 * (w + 1 + i), ErrorCode::Parse,
            formatString("POLYDATA %s: cell %u index %u is out of range (%u points)", kind, c, idx, npoints));
    }
    if (auto s = onCell(p + 4 * (w + 1), n, off + 4 * w, c); !s) return s;
    w += n + 1;
  }
  if (w != words)
    return bad(m, off + 4 * w, ErrorCode::Parse,
               formatString("POLYDATA %s: %u cells use %zu of the %zu words the size field states", kind,
                            cells, w, words));
  return ok();
}

}  // namespace

Result<Mesh> decodePolyData(const MessageView& m) {
  if (auto s = expectType(m, "POLYDATA"); !s) return std::move(s).error();
  const std::size_t size = m.content.size();
  if (size < kPolyHeaderBytes)
    return bad(m, 0, ErrorCode::Parse,
               formatString("POLYDATA content is %zu bytes, the header needs 40", size));
  const std::byte* p = m.content.data();
  std::uint32_t f[10];
  for (int i = 0; i < 10; ++i) f[i] = getBe32(p + 4 * i);
  const std::uint32_t npoints = f[0];
  static constexpr const char* kSizeNames[] = {"size_vertices", "size_lines", "size_polygons",
                                               "size_triangle_strips"};
  for (int k = 0; k < 4; ++k)
    if (f[2 + 2 * k] % 4 != 0)
      return bad(m, 8 + 8 * static_cast<std::size_t>(k), ErrorCode::Parse,
                 formatString("POLYDATA %s is %u, not a multiple of 4", kSizeNames[k], f[2 + 2 * k]));
  const std::uint64_t need = kPolyHeaderBytes + 12ull * npoints + std::uint64_t{f[2]} + f[4] + f[6] + f[8];
  if (need > size)
    return bad(m, 0, ErrorCode::Parse,
               formatString("POLYDATA header describes %llu bytes of points and cells, the content has %zu",
                            static_cast<unsigned long long>(need), size));
  if (f[1] != 0 || f[3] != 0)
    return bad(
        m, f[1] != 0 ? 4 : 12, ErrorCode::Unsupported,
        formatString("POLYDATA has %u vertex and %u line cells; a Mesh holds only surfaces", f[1], f[3]),
        "send polygons or triangle strips only");
  Mesh mesh;
  mesh.name = m.header.deviceName;
  mesh.positions.reserve(npoints);
  for (std::uint32_t i = 0; i < npoints; ++i) {
    const std::byte* q = p + kPolyHeaderBytes + 12 * static_cast<std::size_t>(i);
    const Vec3 v(getF32(q), getF32(q + 4), getF32(q + 8));
    if (!v.allFinite())
      return bad(m, kPolyHeaderBytes + 12 * static_cast<std::size_t>(i), ErrorCode::Parse,
                 formatString("POLYDATA point %u is not finite", i));
    mesh.positions.push_back(v * kMetresPerMm);
  }
  const std::size_t polyOff = kPolyHeaderBytes + 12 * static_cast<std::size_t>(npoints) + f[2] + f[4];
  // Each cell word yields at most one triangle: bounds the reservation by the body.
  mesh.triangles.reserve((f[6] + f[8]) / 4);
  auto polys =
      walkCells(m, polyOff, f[6], f[5], npoints, "polygons",
                [&](const std::byte* idx, std::size_t n, std::size_t at, std::uint32_t c) -> Status {
                  if (n < 3)
                    return bad(m, at, ErrorCode::Parse,
                               formatString("POLYDATA polygon %u has %zu points, at least 3 needed", c, n));
                  const std::uint32_t a = getBe32(idx);
                  for (std::size_t k = 1; k + 1 < n; ++k)
                    mesh.triangles.push_back({a, getBe32(idx + 4 * k), getBe32(idx + 4 * (k + 1))});
                  return ok();
                });
  if (!polys) return std::move(polys).error();
  auto strips =
      walkCells(m, polyOff + f[6], f[8], f[7], npoints, "triangle strips",
                [&](const std::byte* idx, std::size_t n, std::size_t at, std::uint32_t c) -> Status {
                  if (n < 3)
                    return bad(m, at, ErrorCode::Parse,
                               formatString("POLYDATA strip %u has %zu points, at least 3 needed", c, n));
                  for (std::size_t k = 0; k + 2 < n; ++k) {
                    std::uint32_t a = getBe32(idx + 4 * k), b = getBe32(idx + 4 * (k + 1));
                    const std::uint32_t d = getBe32(idx + 4 * (k + 2));
                    if (k % 2 == 1) std::swap(a, b);
                    if (a == b || b == d || a == d) continue;  // degenerate joint of a strip
                    mesh.triangles.push_back({a, b, d});
                  }
                  return ok();
                });
  if (!strips) return std::move(strips).error();
  return mesh;
}

Result<std::vector<std::byte>> encodePolyData(const Envelope& env, const Mesh& mesh) {
  if (auto s = mesh.validate(); !s) return s.error().within("OpenIGTLink POLYDATA encoder");
  if (mesh.positions.size() > 0xFFFFFFFFull / 12 || mesh.triangles.size() > 0xFFFFFFFFull / 16)
    return fail(ErrorCode::InvalidArgument, "mesh too large for POLYDATA's 32-bit sizes",
                "OpenIGTLink encoder");
  std::vector<std::byte> c;
  c.reserve(kPolyHeaderBytes + 12 * mesh.positions.size() + 16 * mesh.triangles.size());
  const auto np = static_cast<std::uint32_t>(mesh.positions.size());
  const auto nt = static_cast<std::uint32_t>(mesh.triangles.size());
  const std::uint32_t header[10] = {np, 0, 0, 0, 0, nt, nt * 16, 0, 0, 0};
  for (std::uint32_t v : header) putBe32(c, v);
  for (const Vec3& v : mesh.positions)
    for (int i = 0; i < 3; ++i) putF32(c, v(i) * kMmPerMetre);
  for (const auto& t : mesh.triangles) {
    putBe32(c, 3);
    for (std::uint32_t i : t) putBe32(c, i);
  }
  return encodeRaw(env, "POLYDATA", c);
}

}  // namespace dm::igtl
