// Mesh export: STL, PLY and OBJ writers of our own (see dm/io/mesh_io.hpp).
//
// Written by hand rather than through Assimp's exporters so that the output
// is simple and exact: ASCII numbers use the shortest decimal that reads
// back to the same double (std::to_chars), binary PLY stores double
// positions, and nothing is reordered, merged or renamed on the way out.
#include <dm/core/filesystem.hpp>
#include <dm/io/mesh_io.hpp>

#include <algorithm>
#include <bit>
#include <cctype>
#include <charconv>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>

namespace dm {

namespace {

using Bytes = std::vector<std::byte>;

enum class MeshFormat { Stl, Ply, Obj };

class Writer {
 public:
  explicit Writer(std::size_t reserve) { out_.reserve(reserve); }

  void text(std::string_view s) {
    const auto* p = reinterpret_cast<const std::byte*>(s.data());
    out_.insert(out_.end(), p, p + s.size());
  }
  void number(double v) {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    text(std::string_view(buf, static_cast<std::size_t>(r.ptr - buf)));
  }
  void number(float v) {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    text(std::string_view(buf, static_cast<std::size_t>(r.ptr - buf)));
  }
  void integer(std::uint64_t v) {
    char buf[24];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    text(std::string_view(buf, static_cast<std::size_t>(r.ptr - buf)));
  }
  template <class... T>
  void numbers(const T&... v) {
    bool first = true;
    ((first ? void() : text(" "), number(v), first = false), ...);
  }

  // Little-endian binary scalars.
  template <class T>
  void binary(T v) {
    static_assert(std::is_arithmetic_v<T>);
    std::byte b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if constexpr (std::endian::native == std::endian::big) std::reverse(b, b + sizeof(T));
    out_.insert(out_.end(), b, b + sizeof(T));
  }

  Bytes take() { return std::move(out_); }

 private:
  Bytes out_;
};

// Solid/element names must be one token on one line.
std::string safeName(const std::string& name) {
  std::string s = name.empty() ? std::string("mesh") : name;
  for (char& c : s)
    if (std::isspace(static_cast<unsigned char>(c)) || !std::isprint(static_cast<unsigned char>(c))) c = '_';
  return s;
}

Bytes stlBinary(const Mesh& m) {
  Writer w(84 + 50 * m.triangles.size());
  char header[80] = {};
  // Must not start with "solid", which readers take for ASCII STL.
  const std::string h = "binary STL written by DMPlatform: " + safeName(m.name);
  std::memcpy(header, h.data(), std::min(h.size(), sizeof header));
  w.text(std::string_view(header, sizeof header));
  w.binary(static_cast<std::uint32_t>(m.triangles.size()));
  for (std::size_t t = 0; t < m.triangles.size(); ++t) {
    const Vec3 n = m.faceNormal(t);
    for (int i = 0; i < 3; ++i) w.binary(static_cast<float>(n[i]));
    for (std::uint32_t v : m.triangles[t])
      for (int i = 0; i < 3; ++i) w.binary(static_cast<float>(m.positions[v][i]));
    w.binary(std::uint16_t{0});
  }
  return w.take();
}

Bytes stlAscii(const Mesh& m) {
  Writer w(256 * m.triangles.size() + 64);
  const std::string name = safeName(m.name);
  w.text("solid " + name + "\n");
  for (std::size_t t = 0; t < m.triangles.size(); ++t) {
    const Vec3 n = m.faceNormal(t);
    w.text("  facet normal ");
    w.numbers(n.x(), n.y(), n.z());
    w.text("\n    outer loop\n");
    for (std::uint32_t v : m.triangles[t]) {
      const Vec3& p = m.positions[v];
      w.text("      vertex ");
      w.numbers(p.x(), p.y(), p.z());
      w.text("\n");
    }
    w.text("    endloop\n  endfacet\n");
  }
  w.text("endsolid " + name + "\n");
  return w.take();
}

Bytes ply(const Mesh& m, bool binary) {
  const bool hasN = !m.normals.empty(), hasUv = !m.uvs.empty(), hasC = !m.colors.empty();
  Writer w(64 * m.positions.size() + 16 * m.triangles.size() + 512);
  w.text(binary ? "ply\nformat binary_little_endian 1.0\n" : "ply\nformat ascii 1.0\n");
  w.text("comment written by DMPlatform, positions in metres\n");
  w.text("obj_info " + safeName(m.name) + "\n");
  w.text("element vertex ");
  w.integer(m.positions.size());
  w.text("\nproperty double x\nproperty double y\nproperty double z\n");
  if (hasN) w.text("property float nx\nproperty float ny\nproperty float nz\n");
  if (hasUv) w.text("property float s\nproperty float t\n");
  if (hasC) w.text("property float red\nproperty float green\nproperty float blue\nproperty float alpha\n");
  w.text("element face ");
  w.integer(m.triangles.size());
  w.text("\nproperty list uchar int vertex_indices\nend_header\n");
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    const Vec3& p = m.positions[i];
    if (binary) {
      for (int k = 0; k < 3; ++k) w.binary(p[k]);
      if (hasN)
        for (int k = 0; k < 3; ++k) w.binary(static_cast<float>(m.normals[i][k]));
      if (hasUv)
        for (int k = 0; k < 2; ++k) w.binary(m.uvs[i][k]);
      if (hasC)
        for (int k = 0; k < 4; ++k) w.binary(m.colors[i][k]);
    } else {
      w.numbers(p.x(), p.y(), p.z());
      if (hasN) {
        w.text(" ");
        w.numbers(static_cast<float>(m.normals[i].x()), static_cast<float>(m.normals[i].y()),
                  static_cast<float>(m.normals[i].z()));
      }
      if (hasUv) {
        w.text(" ");
        w.numbers(m.uvs[i].x(), m.uvs[i].y());
      }
      if (hasC) {
        w.text(" ");
        w.numbers(m.colors[i][0], m.colors[i][1], m.colors[i][2], m.colors[i][3]);
      }
      w.text("\n");
    }
  }
  for (const Triangle& t : m.triangles) {
    if (binary) {
      w.binary(std::uint8_t{3});
      for (std::uint32_t v : t) w.binary(static_cast<std::int32_t>(v));
    } else {
      w.text("3 ");
      w.integer(t[0]);
      w.text(" ");
      w.integer(t[1]);
      w.text(" ");
      w.integer(t[2]);
      w.text("\n");
    }
  }
  return w.take();
}

Bytes obj(const Mesh& m) {
  const bool hasN = !m.normals.empty(), hasUv = !m.uvs.empty(), hasC = !m.colors.empty();
  Writer w(80 * m.positions.size() + 40 * m.triangles.size() + 128);
  w.text("# written by DMPlatform, positions in metres\no " + safeName(m.name) + "\n");
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    const Vec3& p = m.positions[i];
    w.text("v ");
    w.numbers(p.x(), p.y(), p.z());
    if (hasC) {
      w.text(" ");
      w.numbers(m.colors[i][0], m.colors[i][1], m.colors[i][2]);
    }
    w.text("\n");
  }
  if (hasN)
    for (const Vec3& n : m.normals) {
      w.text("vn ");
      w.numbers(n.x(), n.y(), n.z());
      w.text("\n");
    }
  if (hasUv)
    for (const Vec2f& uv : m.uvs) {
      w.text("vt ");
      w.numbers(uv.x(), uv.y());
      w.text("\n");
    }
  for (const Triangle& t : m.triangles) {
    w.text("f");
    for (std::uint32_t v : t) {
      const std::uint64_t i = std::uint64_t{v} + 1;  // OBJ counts from 1
      w.text(" ");
      w.integer(i);
      if (hasUv || hasN) {
        w.text("/");
        if (hasUv) w.integer(i);
        if (hasN) {
          w.text("/");
          w.integer(i);
        }
      }
    }
    w.text("\n");
  }
  return w.take();
}

Result<MeshFormat> meshFormatOf(std::string_view extension, const std::string& where) {
  std::string e(extension);
  for (char& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (!e.empty() && e.front() == '.') e.erase(0, 1);
  if (e == "stl") return MeshFormat::Stl;
  if (e == "ply") return MeshFormat::Ply;
  if (e == "obj") return MeshFormat::Obj;
  return fail(ErrorCode::Unsupported, "cannot write meshes with extension '" + std::string(extension) + "'",
              where, "use .stl, .ply or .obj");
}

Result<Bytes> encode(const Mesh& mesh, MeshFormat format, const MeshExportOptions& options) {
  if (auto s = mesh.validate(); !s) return s.error();
  const std::string where = mesh.name.empty() ? std::string("mesh") : "mesh '" + mesh.name + "'";
  if (mesh.triangles.empty())
    return fail(ErrorCode::InvalidArgument, "has no triangles; nothing to write", where,
                "readers of the SDK reject meshes without triangles");
  if (format == MeshFormat::Stl && mesh.triangles.size() > std::numeric_limits<std::uint32_t>::max())
    return fail(ErrorCode::Unsupported, "has more triangles than binary STL can count (2^32 - 1)", where,
                "write PLY or OBJ");
  if (format == MeshFormat::Ply &&
      mesh.positions.size() > std::size_t{std::numeric_limits<std::int32_t>::max()})
    return fail(ErrorCode::Unsupported, "has more vertices than PLY int indices can address (2^31 - 1)",
                where, "split the mesh");
  switch (format) {
    case MeshFormat::Stl:
      return options.binary ? stlBinary(mesh) : stlAscii(mesh);
    case MeshFormat::Ply:
      return ply(mesh, options.binary);
    case MeshFormat::Obj:
      return obj(mesh);
  }
  return fail(ErrorCode::Internal, "unhandled mesh format", where);
}

}  // namespace

Result<std::vector<std::byte>> encodeMesh(const Mesh& mesh, std::string_view extension,
                                          const MeshExportOptions& options) {
  auto format = meshFormatOf(extension, "encodeMesh");
  if (!format) return format.error();
  return encode(mesh, *format, options);
}

Status writeMesh(const Mesh& mesh, const std::filesystem::path& file, const MeshExportOptions& options) {
  const std::string where = file.string();
  auto format = meshFormatOf(file.extension().string(), where);
  if (!format) return format.error();
  auto bytes = encode(mesh, *format, options);
  if (!bytes) return bytes.error().within(where);
  return writeFileAtomic(file, bytes->data(), bytes->size());
}

}  // namespace dm
