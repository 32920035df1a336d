// Mesh import through Assimp (see dm/io/mesh_io.hpp for the contract).
//
// Pipeline: Assimp reads the file without post-processing; we check the raw
// scene ourselves (non-finite coordinates would make Assimp's spatial sorts
// undefined, point clouds deserve a clearer message than "validation
// failed", empty sub-meshes of otherwise good files are pruned); then
// Assimp validates the scene and triangulates, joins identical vertices and
// splits meshes by primitive type. The scene graph is flattened here, with
// transforms in double precision, and the result is welded by position.
#include <dm/core/confine.hpp>
#include <dm/core/filesystem.hpp>
#include <dm/core/log.hpp>
#include <dm/core/units.hpp>
#include <dm/io/mesh_io.hpp>

#include <assimp/DefaultIOSystem.h>
#include <assimp/config.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <array>
#include <assimp/IOStream.hpp>
#include <assimp/IOSystem.hpp>
#include <assimp/Importer.hpp>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <fstream>
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "format_util.hpp"
#include "isolate.hpp"
#include "mesh_guards.hpp"

namespace dm {

using detail::ByteReader;
using detail::checkColladaIndexLists;
using detail::checkMeshHead;
using detail::FdWriter;
using detail::IsolateOptions;
using detail::kMeshHeadBytes;
using detail::looksLikeCollada;
using detail::lower;
using detail::runHelper;
using detail::runIsolated;

namespace {

namespace fs = std::filesystem;

// Steps run after our own checks of the raw scene. No optimisation steps
// (OptimizeMeshes, OptimizeGraph, ImproveCacheLocality): they cost time on
// large inputs and we flatten the graph ourselves.
constexpr unsigned kPostProcess =
    aiProcess_Triangulate | aiProcess_JoinIdenticalVertices | aiProcess_SortByPType;

// Deeper scene graphs than this are refused (Assimp rejects cycles, but a
// crafted file can still nest deeply).
constexpr std::size_t kMaxNodeDepth = 1024;

std::string squote(std::string_view s) { return "'" + std::string(s) + "'"; }

std::string meshLabel(const aiMesh& m, unsigned index) {
  const char* n = m.mName.C_Str();
  return (n[0] != '\0' ? squote(n) + " (mesh " : "(mesh ") + std::to_string(index) + ")";
}

// ---------------------------------------------------------------------------
// File access: every file an import opens besides the model itself (an OBJ's
// material library, a glTF's buffers and images) must lie in the model's
// folder or an allowed root (dm/core/confine.hpp: a model someone else made
// must not make us read any file on the machine); only regular files are
// opened (a crafted .mtl or glTF uri naming a FIFO or /dev/zero must not
// block or stream forever); all are checked against one byte budget.

struct ImportBudget {
  std::size_t maxBytes = 0;
  std::size_t usedBytes = 0;
  std::set<std::string> opened;  ///< canonical paths already counted
  std::string refusal;           ///< why the last refused open was refused
  // Confinement: the model (always allowed), its folder and the roots
  // (taken by the caller before any fork: confineToRoots takes no lock).
  std::filesystem::path model, folder;
  std::vector<std::filesystem::path> roots;
  std::optional<Error> denied;  ///< the first file refused for its place
};

// Whether the import may open `file`: the model, or a file in the roots.
bool confined(ImportBudget& b, const char* file) {
  std::error_code ec;
  const fs::path absolute = fs::absolute(file, ec);
  if (ec) return false;
  if (fs::weakly_canonical(absolute, ec) == b.model && !ec) return true;
  auto r = confineToRoots(b.roots, b.folder, absolute.string(), "a file the model refers to");
  if (r) return true;
  if (!b.denied) b.denied = r.error();
  b.refusal = r.error().message();
  return false;
}

class LimitedIOSystem final : public Assimp::DefaultIOSystem {
 public:
  explicit LimitedIOSystem(ImportBudget* budget) : budget_(budget) {}

  bool Exists(const char* file) const override {
    std::error_code ec;
    return file != nullptr && confined(*budget_, file) && fs::is_regular_file(file, ec);
  }

  Assimp::IOStream* Open(const char* file, const char* mode = "rb") override {
    if (file == nullptr) return nullptr;
    if (mode == nullptr || std::strpbrk(mode, "wa+") != nullptr) {
      budget_->refusal = std::string("the importer tried to write ") + file + ", which is not allowed";
      return nullptr;
    }
    if (!confined(*budget_, file)) return nullptr;
    std::error_code ec;
    const fs::file_status st = fs::status(file, ec);
    if (ec || !fs::exists(st)) return nullptr;  // a missing texture or .mtl: the reader decides
    if (!fs::is_regular_file(st)) {
      budget_->refusal = std::string("refers to ") + file + ", which is not a regular file";
      return nullptr;
    }
    const std::uintmax_t size = fs::file_size(file, ec);
    if (ec) return nullptr;
    const std::string key = fs::weakly_canonical(file, ec).string();
    if (!budget_->opened.contains(key)) {
      if (size > budget_->maxBytes - budget_->usedBytes) {
        budget_->refusal = std::string("reading ") + file + " (" + std::to_string(size) +
                           " bytes) would exceed " + "the import limit of " +
                           std::to_string(budget_->maxBytes) +
                           " bytes; raise MeshImportOptions::maxFileBytes";
        return nullptr;
      }
      budget_->usedBytes += static_cast<std::size_t>(size);
      budget_->opened.insert(key);
    }
    return DefaultIOSystem::Open(file, mode);
  }

 private:
  ImportBudget* budget_;
};

// For parseMesh: the only file is the memory buffer (Assimp's MemoryIOSystem
// serves it and forwards every other name here).
class NoFileIOSystem final : public Assimp::IOSystem {
 public:
  explicit NoFileIOSystem(ImportBudget* budget) : budget_(budget) {}
  bool Exists(const char* /*file*/) const override { return false; }
  char getOsSeparator() const override { return '/'; }
  Assimp::IOStream* Open(const char* file, const char* /*mode*/) override {
    budget_->refusal = std::string("refers to the external file ") + (file ? file : "?") +
                       ", which parseMesh() does not open; use readMesh() on a file";
    return nullptr;
  }
  void Close(Assimp::IOStream* stream) override { delete stream; }

 private:
  ImportBudget* budget_;
};

// ---------------------------------------------------------------------------
// Raw scene checks, before Assimp's post-processing touches the data.

// Counts polygon faces (3 or more indices); fails on a non-finite position.
Result<std::size_t> checkRawScene(const aiScene& scene, const std::string& where) {
  std::size_t polygons = 0, others = 0, loose = 0;
  if (scene.mMeshes == nullptr) return std::size_t{0};
  for (unsigned k = 0; k < scene.mNumMeshes; ++k) {
    const aiMesh* m = scene.mMeshes[k];
    if (m == nullptr) continue;
    if (m->mVertices != nullptr)
      for (unsigned v = 0; v < m->mNumVertices; ++v) {
        const aiVector3D& p = m->mVertices[v];
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
          char coords[96];
          std::snprintf(coords, sizeof coords, "(%g, %g, %g)", static_cast<double>(p.x),
                        static_cast<double>(p.y), static_cast<double>(p.z));
          return fail(ErrorCode::Parse,
                      "mesh " + meshLabel(*m, k) + ": vertex " + std::to_string(v) +
                          " has a non-finite coordinate " + coords,
                      where, "fix or remove the vertex");
        }
      }
    if (m->mFaces != nullptr && m->mNumFaces > 0)
      for (unsigned f = 0; f < m->mNumFaces; ++f) (m->mFaces[f].mNumIndices >= 3 ? polygons : others) += 1;
    else if (m->mVertices != nullptr)
      loose += m->mNumVertices;  // a point cloud without faces
  }
  if (polygons == 0 && (others > 0 || loose > 0))
    return fail(ErrorCode::Parse,
                "contains no triangles (only " +
                    (others > 0 ? std::to_string(others) + " points or line segments"
                                : std::to_string(loose) + " vertices without faces") +
                    ")",
                where,
                "a mesh needs triangles or polygons; export the surface, not the point cloud or wireframe");
  return polygons;
}

void pruneNodeReferences(aiNode* node, const std::vector<unsigned>& remap, std::size_t depth) {
  if (node == nullptr || depth > kMaxNodeDepth) return;
  if (node->mMeshes != nullptr) {
    unsigned kept = 0;
    for (unsigned i = 0; i < node->mNumMeshes; ++i) {
      const unsigned old = node->mMeshes[i];
      // Out-of-range references stay out of range for validation to report.
      if (old >= remap.size())
        node->mMeshes[kept++] = std::numeric_limits<unsigned>::max();
      else if (remap[old] != std::numeric_limits<unsigned>::max())
        node->mMeshes[kept++] = remap[old];
    }
    node->mNumMeshes = kept;
  }
  if (node->mChildren != nullptr)
    for (unsigned c = 0; c < node->mNumChildren; ++c)
      pruneNodeReferences(node->mChildren[c], remap, depth + 1);
}

// Removes meshes without vertices or faces (an empty "solid" in an STL, the
// point part of a PLY) so that validation does not reject the whole file.
void pruneEmptyMeshes(aiScene& scene) {
  if (scene.mMeshes == nullptr) return;
  std::vector<unsigned> remap(scene.mNumMeshes, std::numeric_limits<unsigned>::max());
  unsigned kept = 0;
  for (unsigned k = 0; k < scene.mNumMeshes; ++k) {
    aiMesh* m = scene.mMeshes[k];
    const bool useful = m != nullptr && m->mVertices != nullptr && m->mNumVertices > 0 &&
                        m->mFaces != nullptr && m->mNumFaces > 0;
    if (useful) {
      remap[k] = kept;
      scene.mMeshes[kept++] = m;
    } else {
      delete m;
    }
  }
  if (kept == scene.mNumMeshes) return;
  for (unsigned k = kept; k < scene.mNumMeshes; ++k) scene.mMeshes[k] = nullptr;
  scene.mNumMeshes = kept;
  pruneNodeReferences(scene.mRootNode, remap, 0);
}

// ---------------------------------------------------------------------------
// Scene flattening.

Affine3 toAffine(const aiMatrix4x4& m) {
  Mat4 a;
  a << m.a1, m.a2, m.a3, m.a4, m.b1, m.b2, m.b3, m.b4, m.c1, m.c2, m.c3, m.c4, m.d1, m.d2, m.d3, m.d4;
  Affine3 t;
  t.matrix() = a;
  return t;
}

std::size_t triangleCount(const aiMesh& m) {
  std::size_t n = 0;
  for (unsigned f = 0; f < m.mNumFaces; ++f) n += m.mFaces[f].mNumIndices == 3 ? 1 : 0;
  return n;
}

struct Part {
  std::string name;
  Affine3 toFile;  ///< node-to-file transform (file units)
  unsigned meshIndex = 0;
};

Result<std::vector<Part>> collectParts(const aiScene& scene, const std::string& where,
                                       const MeshImportOptions& options) {
  std::vector<std::size_t> triangles(scene.mNumMeshes);
  std::vector<std::size_t> vertices(scene.mNumMeshes);
  for (unsigned k = 0; k < scene.mNumMeshes; ++k) {
    triangles[k] = triangleCount(*scene.mMeshes[k]);
    vertices[k] = scene.mMeshes[k]->mNumVertices;
  }

  std::vector<Part> parts;
  std::size_t totalTriangles = 0, totalVertices = 0;
  struct Item {
    const aiNode* node;
    Affine3 parent;
    std::size_t depth;
  };
  std::vector<Item> stack{{scene.mRootNode, Affine3::Identity(), 0}};
  while (!stack.empty()) {
    const Item item = stack.back();
    stack.pop_back();
    if (item.depth > kMaxNodeDepth)
      return fail(ErrorCode::Unsupported,
                  "scene graph is deeper than " + std::to_string(kMaxNodeDepth) + " nodes", where);
    const aiNode& node = *item.node;
    const Affine3 toFile = item.parent * toAffine(node.mTransformation);
    if (!toFile.matrix().allFinite())
      return fail(ErrorCode::Parse, "node " + squote(node.mName.C_Str()) + " has a non-finite transform",
                  where);

    unsigned triangleMeshes = 0;
    for (unsigned i = 0; i < node.mNumMeshes; ++i) triangleMeshes += triangles[node.mMeshes[i]] > 0 ? 1 : 0;
    for (unsigned i = 0; i < node.mNumMeshes; ++i) {
      const unsigned k = node.mMeshes[i];
      if (triangles[k] == 0) continue;  // points or lines, split off by SortByPType
      std::string name = node.mName.C_Str();
      const std::string meshName = scene.mMeshes[k]->mName.C_Str();
      if (name.empty())
        name = meshName.empty() ? "part" + std::to_string(parts.size()) : meshName;
      else if (triangleMeshes > 1)
        name += "/" + (meshName.empty() ? std::to_string(i) : meshName);
      totalTriangles += triangles[k];
      totalVertices += vertices[k];
      if (totalTriangles > options.maxTriangles)
        return fail(ErrorCode::Unsupported,
                    "has more than " + std::to_string(options.maxTriangles) +
                        " triangles (over all parts and instances)",
                    where, "raise MeshImportOptions::maxTriangles or simplify the model");
      if (totalVertices >= std::numeric_limits<std::uint32_t>::max())
        return fail(ErrorCode::Unsupported, "has more than 2^32 - 1 vertices", where,
                    "split or simplify the model");
      parts.push_back(Part{std::move(name), toFile, k});
    }
    // Children pushed in reverse so parts come out in file (depth-first) order.
    for (unsigned c = node.mNumChildren; c-- > 0;)
      stack.push_back({node.mChildren[c], toFile, item.depth + 1});
  }
  return parts;
}

// A mesh being assembled, with the bookkeeping welding needs.
struct Builder {
  Mesh mesh;
  std::vector<std::uint8_t> hasNormal;  ///< per vertex: the file gave a usable normal
  bool anyUv = false;
  bool anyColor = false;
};

Status appendPart(Builder& b, const aiMesh& m, const Affine3& toMetres, const std::string& where) {
  const std::size_t base = b.mesh.positions.size();
  const Mat3 normalMatrix = toMetres.linear().inverse().transpose();
  const bool mirror = toMetres.linear().determinant() < 0;
  const bool hasUv = m.HasTextureCoords(0);
  const bool hasColor = m.HasVertexColors(0);
  b.anyUv = b.anyUv || hasUv;
  b.anyColor = b.anyColor || hasColor;
  for (unsigned v = 0; v < m.mNumVertices; ++v) {
    const aiVector3D& q = m.mVertices[v];
    const Vec3 p = toMetres * Vec3(q.x, q.y, q.z);
    if (!p.allFinite())
      return fail(ErrorCode::Parse,
                  "mesh " + squote(m.mName.C_Str()) + ": vertex " + std::to_string(v) +
                      " is not finite after the node transform and unit scaling",
                  where, "check the node transforms and MeshImportOptions::scale");
    b.mesh.positions.push_back(p);
    Vec3 n = Vec3::Zero();
    bool usable = false;
    if (m.mNormals != nullptr) {
      const aiVector3D& fn = m.mNormals[v];
      n = normalMatrix * Vec3(fn.x, fn.y, fn.z);
      const double len = n.norm();
      usable = std::isfinite(len) && len > 1e-12;
      n = usable ? Vec3(n / len) : Vec3::Zero();
    }
    b.mesh.normals.push_back(n);
    b.hasNormal.push_back(usable ? 1 : 0);
    b.mesh.uvs.push_back(hasUv ? Vec2f(m.mTextureCoords[0][v].x, m.mTextureCoords[0][v].y) : Vec2f::Zero());
    const aiColor4D white(1, 1, 1, 1);
    const aiColor4D& c = hasColor ? m.mColors[0][v] : white;
    b.mesh.colors.push_back(Vec4f(c.r, c.g, c.b, c.a));
  }
  for (unsigned f = 0; f < m.mNumFaces; ++f) {
    const aiFace& face = m.mFaces[f];
    if (face.mNumIndices != 3) continue;
    Triangle t;
    for (int c = 0; c < 3; ++c) {
      const unsigned idx = face.mIndices[c];
      if (idx >= m.mNumVertices)
        return fail(ErrorCode::Parse,
                    "mesh " + squote(m.mName.C_Str()) + ": face " + std::to_string(f) +
                        " references vertex " + std::to_string(idx) + " but there are only " +
                        std::to_string(m.mNumVertices),
                    where, "the file is corrupt; re-export it");
      t[static_cast<std::size_t>(c)] = static_cast<std::uint32_t>(base + idx);
    }
    // A mirroring transform turns counter-clockwise into clockwise.
    if (mirror) std::swap(t[1], t[2]);
    b.mesh.triangles.push_back(t);
  }
  return ok();
}

// ---------------------------------------------------------------------------
// Welding.

struct KeyHash {
  std::size_t operator()(const std::array<std::uint64_t, 3>& k) const noexcept {
    std::uint64_t h = 0x9E3779B97F4A7C15ull;
    for (std::uint64_t x : k) {
      h ^= x + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
      h *= 0xBF58476D1CE4E5B9ull;
    }
    return static_cast<std::size_t>(h ^ (h >> 31));
  }
};

using Key = std::array<std::uint64_t, 3>;

Key exactKey(const Vec3& p) {
  Key k;
  for (int i = 0; i < 3; ++i)
    k[static_cast<std::size_t>(i)] = std::bit_cast<std::uint64_t>(p[i] + 0.0);  // -0 → +0
  return k;
}

std::int64_t cellIndex(double x, double tol) {
  const double c = std::floor(x / tol);
  constexpr double lim = 4.0e18;
  return static_cast<std::int64_t>(std::clamp(c, -lim, lim));
}

// old vertex → representative (new) vertex, greedy in vertex order.
std::vector<std::uint32_t> weldMap(const std::vector<Vec3>& positions, double tol, std::size_t& count) {
  std::vector<std::uint32_t> map(positions.size());
  count = 0;
  if (tol <= 0) {
    std::unordered_map<Key, std::uint32_t, KeyHash> index;
    index.reserve(positions.size());
    for (std::size_t i = 0; i < positions.size(); ++i) {
      auto [it, inserted] = index.try_emplace(exactKey(positions[i]), static_cast<std::uint32_t>(count));
      if (inserted) ++count;
      map[i] = it->second;
    }
    return map;
  }
  // Spatial hash with cells of the tolerance: a partner within tol lies in
  // one of the 27 cells around the vertex's cell.
  std::unordered_map<Key, std::vector<std::uint32_t>, KeyHash> cells;
  cells.reserve(positions.size());
  std::vector<std::uint32_t> reps;  // new index → old index of the representative
  const double tol2 = tol * tol;
  for (std::size_t i = 0; i < positions.size(); ++i) {
    const Vec3& p = positions[i];
    const std::int64_t cx = cellIndex(p.x(), tol), cy = cellIndex(p.y(), tol), cz = cellIndex(p.z(), tol);
    std::int64_t found = -1;
    for (std::int64_t dx = -1; dx <= 1 && found < 0; ++dx)
      for (std::int64_t dy = -1; dy <= 1 && found < 0; ++dy)
        for (std::int64_t dz = -1; dz <= 1 && found < 0; ++dz) {
          const Key k{static_cast<std::uint64_t>(cx + dx), static_cast<std::uint64_t>(cy + dy),
                      static_cast<std::uint64_t>(cz + dz)};
          auto it = cells.find(k);
          if (it == cells.end()) continue;
          for (std::uint32_t r : it->second)
            if ((positions[reps[r]] - p).squaredNorm() <= tol2) {
              found = r;
              break;
            }
        }
    if (found >= 0) {
      map[i] = static_cast<std::uint32_t>(found);
    } else {
      map[i] = static_cast<std::uint32_t>(count++);
      reps.push_back(static_cast<std::uint32_t>(i));
      cells[Key{static_cast<std::uint64_t>(cx), static_cast<std::uint64_t>(cy),
                static_cast<std::uint64_t>(cz)}]
          .push_back(map[i]);
    }
  }
  return map;
}

// Non-manifold edges (more than two triangles) and edges whose two triangles
// disagree on orientation are reported, not rejected. O(t log t).
void reportTopology(const Mesh& mesh, const std::string& where) {
  // The sort needs 16 bytes per corner; beyond this the check is skipped.
  constexpr std::size_t kMaxCheckedTriangles = 10'000'000;
  if (mesh.triangles.size() > kMaxCheckedTriangles) {
    log::debug("%s: mesh '%s': topology check skipped (%zu triangles)", where.c_str(), mesh.name.c_str(),
               mesh.triangles.size());
    return;
  }
  std::vector<std::uint64_t> directed;
  directed.reserve(mesh.triangles.size() * 3);
  for (const Triangle& t : mesh.triangles)
    for (int c = 0; c < 3; ++c)
      directed.push_back((std::uint64_t{t[static_cast<std::size_t>(c)]} << 32) |
                         t[static_cast<std::size_t>((c + 1) % 3)]);
  std::vector<std::uint64_t> undirected(directed.size());
  std::transform(directed.begin(), directed.end(), undirected.begin(), [](std::uint64_t e) {
    const std::uint64_t a = e >> 32, b = e & 0xFFFFFFFFull;
    return a < b ? (a << 32) | b : (b << 32) | a;
  });
  std::sort(directed.begin(), directed.end());
  std::sort(undirected.begin(), undirected.end());
  std::size_t nonManifold = 0, boundary = 0, flipped = 0;
  for (std::size_t i = 0; i < undirected.size();) {
    std::size_t j = i;
    while (j < undirected.size() && undirected[j] == undirected[i]) ++j;
    if (j - i > 2) ++nonManifold;
    if (j - i == 1) ++boundary;
    i = j;
  }
  for (std::size_t i = 0; i + 1 < directed.size(); ++i)
    if (directed[i] == directed[i + 1] && (i + 2 >= directed.size() || directed[i + 2] != directed[i]))
      ++flipped;
  if (nonManifold > 0 || flipped > 0)
    log::warn(
        "%s: mesh '%s' is not a consistently oriented manifold: %zu non-manifold edges (more than two "
        "triangles), %zu edges shared by triangles of opposite orientation; loaded anyway",
        where.c_str(), mesh.name.c_str(), nonManifold, flipped);
  if (boundary > 0)
    log::debug("%s: mesh '%s' is open: %zu boundary edges", where.c_str(), mesh.name.c_str(), boundary);
}

// Welds, drops degenerate triangles and unreferenced vertices, settles the
// normals and checks the result. A mesh whose triangles all collapse comes
// back empty (named, nothing else) for the caller to skip or refuse.
Result<Mesh> finish(Builder&& b, const MeshImportOptions& options, const std::string& where) {
  Mesh& in = b.mesh;
  const std::size_t nIn = in.positions.size();

  // 1. Representative of every vertex.
  std::vector<std::uint32_t> rep(nIn);
  std::size_t nRep = nIn;
  if (options.weld)
    rep = weldMap(in.positions, options.weldTolerance, nRep);
  else
    for (std::size_t i = 0; i < nIn; ++i) rep[i] = static_cast<std::uint32_t>(i);

  // 2. Triangles in representatives; collapsed ones are dropped.
  std::vector<Triangle> tris;
  tris.reserve(in.triangles.size());
  std::size_t degenerate = 0;
  for (const Triangle& t : in.triangles) {
    const Triangle r{rep[t[0]], rep[t[1]], rep[t[2]]};
    if (r[0] == r[1] || r[1] == r[2] || r[0] == r[2]) {
      ++degenerate;
      continue;
    }
    tris.push_back(r);
  }
  if (tris.empty()) {
    log::debug("%s: mesh '%s': all %zu triangles are degenerate", where.c_str(), in.name.c_str(), degenerate);
    Mesh none;
    none.name = std::move(in.name);
    return none;
  }
  if (degenerate > 0)
    log::debug("%s: mesh '%s': dropped %zu degenerate triangles", where.c_str(), in.name.c_str(), degenerate);

  // 3. Referenced representatives get consecutive indices, in first-use order
  //    of the original vertices (so unwelded input keeps its order).
  constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint8_t> used(nRep, 0);
  for (const Triangle& t : tris)
    for (std::uint32_t v : t) used[v] = 1;
  std::vector<std::uint32_t> finalIndex(nRep, kNone);
  std::vector<std::uint32_t> firstOld;  // final index → first original vertex
  for (std::size_t i = 0; i < nIn; ++i) {
    const std::uint32_t r = rep[i];
    if (used[r] && finalIndex[r] == kNone) {
      finalIndex[r] = static_cast<std::uint32_t>(firstOld.size());
      firstOld.push_back(static_cast<std::uint32_t>(i));
    }
  }
  const std::size_t n = firstOld.size();

  Mesh out;
  out.name = std::move(in.name);
  out.positions.resize(n);
  for (std::size_t k = 0; k < n; ++k) out.positions[k] = in.positions[firstOld[k]];
  if (b.anyUv) {
    out.uvs.resize(n);
    for (std::size_t k = 0; k < n; ++k) out.uvs[k] = in.uvs[firstOld[k]];
  }
  if (b.anyColor) {
    out.colors.resize(n);
    for (std::size_t k = 0; k < n; ++k) out.colors[k] = in.colors[firstOld[k]];
  }
  out.triangles.reserve(tris.size());
  for (const Triangle& t : tris)
    out.triangles.push_back({finalIndex[t[0]], finalIndex[t[1]], finalIndex[t[2]]});

  // 4. Normals: a merged vertex keeps the file normal only if all its
  //    members had one and they agree (within about 1°).
  std::vector<Vec3> sum(n, Vec3::Zero());
  std::vector<std::uint8_t> keep(n, 1);
  constexpr double kAgree = 0.99985;  // cos 1°
  for (std::size_t i = 0; i < nIn; ++i) {
    const std::uint32_t k = finalIndex[rep[i]];
    if (k == kNone) continue;
    if (!b.hasNormal[i]) {
      keep[k] = 0;
      continue;
    }
    if (!sum[k].isZero() && sum[k].normalized().dot(in.normals[i]) < kAgree) keep[k] = 0;
    sum[k] += in.normals[i];
  }
  bool allKept = true;
  for (std::size_t k = 0; k < n; ++k) {
    const double len = sum[k].norm();
    if (keep[k] && len > 1e-12)
      sum[k] /= len;
    else
      keep[k] = 0;
    allKept = allKept && keep[k];
  }
  if (allKept) {
    out.normals = std::move(sum);
  } else if (options.computeNormals) {
    out.computeNormals();
    for (std::size_t k = 0; k < n; ++k)
      if (keep[k]) out.normals[k] = sum[k];
  }

  if (auto s = out.validate(); !s) return s.error().within(where);
  if (options.weld) reportTopology(out, where);
  return out;
}

// ---------------------------------------------------------------------------
// The import driver shared by readMesh, readMeshes and parseMesh.

struct Source {
  const fs::path* file = nullptr;    ///< read from disk, or
  std::vector<fs::path> roots;       ///< with a file: where the files it names may be
  std::span<const std::byte> bytes;  ///< parse from memory
  std::string hint;                  ///< extension for memory input
  std::string where;                 ///< name used in messages
  std::string stem;                  ///< name of the merged mesh
};

Status checkOptions(const MeshImportOptions& o, const std::string& where) {
  if (!std::isfinite(o.scale) || o.scale <= 0)
    return fail(ErrorCode::InvalidArgument, "MeshImportOptions::scale is " + std::to_string(o.scale), where,
                "give a finite factor > 0");
  if (!std::isfinite(o.weldTolerance) || o.weldTolerance < 0)
    return fail(ErrorCode::InvalidArgument,
                "MeshImportOptions::weldTolerance is " + std::to_string(o.weldTolerance), where,
                "give a finite distance >= 0 in metres");
  if (!std::isfinite(o.timeoutSeconds) || o.timeoutSeconds < 0 || o.timeoutSeconds > 1e6)
    return fail(ErrorCode::InvalidArgument,
                "MeshImportOptions::timeoutSeconds is " + std::to_string(o.timeoutSeconds), where,
                "give seconds in [0, 1e6]; 0 means no limit");
  if (auto u = metresPerUnit(o.unit); !u) return u.error().within(where);
  return ok();
}

// Size limit and the header guards: cheap checks on the raw input, before
// Assimp sees it.
Status checkInput(const Source& src, const MeshImportOptions& options) {
  const std::string& where = src.where;
  std::string head;
  std::uint64_t totalBytes = 0;
  std::string extension;
  if (src.file != nullptr) {
    std::error_code ec;
    const fs::file_status st = fs::status(*src.file, ec);
    if (ec || !fs::exists(st))
      return fail(ErrorCode::NotFound, "file does not exist", where, "check the path");
    if (!fs::is_regular_file(st))
      return fail(ErrorCode::Io, "is not a regular file", where, "give the path of a mesh file");
    totalBytes = fs::file_size(*src.file, ec);
    if (ec) return fail(ErrorCode::Io, "cannot read the file size: " + ec.message(), where);
    std::ifstream f(*src.file, std::ios::binary);
    if (!f) return fail(ErrorCode::Io, "cannot open the file for reading", where, "check the permissions");
    head.resize(kMeshHeadBytes);
    f.read(head.data(), static_cast<std::streamsize>(head.size()));
    head.resize(static_cast<std::size_t>(f.gcount()));
    extension = lower(src.file->extension().string());
    if (!extension.empty()) extension.erase(0, 1);
  } else {
    totalBytes = src.bytes.size();
    head.assign(reinterpret_cast<const char*>(src.bytes.data()),
                std::min<std::size_t>(src.bytes.size(), kMeshHeadBytes));
    extension = src.hint;
  }
  if (totalBytes == 0) return fail(ErrorCode::Parse, "is empty", where, "give a mesh file with triangles");
  if (totalBytes > options.maxFileBytes)
    return fail(ErrorCode::Unsupported,
                "is " + std::to_string(totalBytes) + " bytes, more than the limit of " +
                    std::to_string(options.maxFileBytes),
                where, "raise MeshImportOptions::maxFileBytes if the file is genuine");
  if (auto s = checkMeshHead({head, totalBytes, extension}, options.maxTriangles, where); !s) return s;
  const bool daeExtension = extension == "dae";
  if (looksLikeCollada(head, daeExtension)) {
    if (src.file == nullptr)
      return checkColladaIndexLists(
          std::string_view(reinterpret_cast<const char*>(src.bytes.data()), src.bytes.size()), where);
    auto bytes = readFile(*src.file, options.maxFileBytes);
    if (!bytes) return bytes.error();
    return checkColladaIndexLists(
        std::string_view(reinterpret_cast<const char*>(bytes->data()), bytes->size()), where);
  }
  return ok();
}

// Everything that touches Assimp: import, our raw-scene checks, validation,
// post-processing and flattening into builders (one merged or one per part).
// Runs in the child process when the import is isolated, so it must not log
// (another thread of the parent may have held the logger's lock at fork).
Result<std::vector<Builder>> loadWithAssimp(const Source& src, const MeshImportOptions& options, bool merge) {
  const std::string& where = src.where;
  const double toMetres = metresPerUnit(options.unit).value() * options.scale;

  ImportBudget budget;
  budget.maxBytes = options.maxFileBytes;
  Assimp::Importer importer;
  // BVH and other animation-only files would otherwise get a stick-figure
  // mesh made up by Assimp.
  importer.SetPropertyBool(AI_CONFIG_IMPORT_NO_SKELETON_MESHES, true);

  auto assimpError = [&](const char* stage) {
    std::string msg = importer.GetErrorString();
    if (msg.empty()) msg = "unknown error";
    if (!budget.refusal.empty()) msg += " (" + budget.refusal + ")";
    return fail(ErrorCode::Parse, std::string("Assimp ") + stage + " failed: " + msg, where,
                "check that the file is a complete, valid mesh file of the format its extension says");
  };

  const aiScene* scene = nullptr;
  try {
    if (src.file != nullptr) {
      std::error_code ec;
      budget.model = fs::weakly_canonical(fs::absolute(*src.file, ec), ec);
      budget.folder = budget.model.parent_path();
      budget.roots = src.roots;
      importer.SetIOHandler(new LimitedIOSystem(&budget));
      scene = importer.ReadFile(src.file->string(), 0);
      // A file named from outside the roots fails the import, even where
      // the reader would go on without it (a missing .mtl is a warning).
      if (budget.denied) return Error(*budget.denied).within(where);
    } else {
      importer.SetIOHandler(new NoFileIOSystem(&budget));
      scene = importer.ReadFileFromMemory(src.bytes.data(), src.bytes.size(), 0, src.hint.c_str());
    }
    if (scene == nullptr) return assimpError("import");

    auto polygons = checkRawScene(*scene, where);
    if (!polygons) return polygons.error();
    if (*polygons == 0)
      return fail(ErrorCode::Parse, "contains no triangles (no meshes)", where,
                  "the file holds no surface geometry (only a scene graph, cameras, lights or animation)");
    // The importer owns the scene; like a post-processing step we edit it in
    // place before the other steps run.
    pruneEmptyMeshes(*const_cast<aiScene*>(importer.GetScene()));

    // Validation first, alone, so the other steps only see valid data.
    scene = importer.ApplyPostProcessing(aiProcess_ValidateDataStructure);
    if (scene == nullptr) return assimpError("validation");
    scene = importer.ApplyPostProcessing(kPostProcess);
    if (scene == nullptr) return assimpError("post-processing");
  } catch (const std::exception& e) {
    return fail(ErrorCode::Parse, std::string("Assimp threw: ") + e.what(), where);
  } catch (...) {
    return fail(ErrorCode::Parse, "Assimp threw an unknown exception", where);
  }

  auto parts = collectParts(*scene, where, options);
  if (!parts) return parts.error();
  if (parts->empty())
    return fail(ErrorCode::Parse, "contains no triangles (only points or lines in the scene graph)", where,
                "a mesh needs triangles or polygons");
  if (merge && !options.mergeMeshes && parts->size() > 1) {
    std::string names;
    for (std::size_t i = 0; i < parts->size() && i < 8; ++i)
      names += (i ? ", " : "") + squote((*parts)[i].name);
    if (parts->size() > 8) names += ", ...";
    return fail(ErrorCode::InvalidArgument,
                "has " + std::to_string(parts->size()) + " parts (" + names + ") but mergeMeshes is off",
                where, "use readMeshes() for one mesh per part, or set MeshImportOptions::mergeMeshes");
  }

  const Affine3 scaleToMetres(Eigen::Scaling(toMetres));
  std::vector<Builder> out(merge ? 1 : parts->size());
  if (merge) out[0].mesh.name = src.stem;
  for (std::size_t i = 0; i < parts->size(); ++i) {
    const Part& p = (*parts)[i];
    Builder& b = out[merge ? 0 : i];
    if (!merge) b.mesh.name = p.name;
    if (auto s = appendPart(b, *scene->mMeshes[p.meshIndex], scaleToMetres * p.toFile, where); !s)
      return s.error();
  }
  return out;
}

// ---------------------------------------------------------------------------
// Isolation. Assimp 5.2 loops forever or corrupts its heap on some malformed
// files (found by Tests/fuzz/mesh_fuzz.cpp), which no check of ours can
// fully prevent in-process. With MeshImportOptions::isolate, loadWithAssimp()
// runs in a forked child that streams the builders back through a pipe; the
// parent enforces the deadline and turns a crash or a timeout into an Error.

static_assert(sizeof(Vec3) == 3 * sizeof(double) && sizeof(Vec2f) == 2 * sizeof(float) &&
                  sizeof(Vec4f) == 4 * sizeof(float) && sizeof(Triangle) == 3 * sizeof(std::uint32_t),
              "attribute arrays are sent as packed scalars");

void sendResult(FdWriter& w, const Result<std::vector<Builder>>& r) {
  if (!r) {
    w.u64(0);
    w.error(r.error());
    return;
  }
  w.u64(1);
  w.u64(r->size());
  for (const Builder& b : *r) {
    w.str(b.mesh.name);
    w.array<Vec3, double>(b.mesh.positions);
    w.array<Vec3, double>(b.mesh.normals);
    w.array<std::uint8_t, std::uint8_t>(b.hasNormal);
    w.array<Vec2f, float>(b.mesh.uvs);
    w.array<Vec4f, float>(b.mesh.colors);
    w.array<Triangle, std::uint32_t>(b.mesh.triangles);
    w.u64((b.anyUv ? 1u : 0u) | (b.anyColor ? 2u : 0u));
  }
  w.u64(0x444d4d45534844ull);  // end marker: the child got to the end
}

// A child's builders must be what appendPart() makes: every attribute array
// as long as the positions, finite positions and normals, every index in
// range. A child whose heap Assimp corrupted may still end cleanly with
// garbage, and finish() indexes by what it holds.
bool consistent(const Builder& b) {
  const std::size_t n = b.mesh.positions.size();
  if (n > std::numeric_limits<std::uint32_t>::max() || b.mesh.normals.size() != n ||
      b.hasNormal.size() != n || b.mesh.uvs.size() != n || b.mesh.colors.size() != n)
    return false;
  for (std::size_t i = 0; i < n; ++i)
    if (!b.mesh.positions[i].allFinite() || !b.mesh.normals[i].allFinite()) return false;
  for (const Triangle& t : b.mesh.triangles)
    for (const std::uint32_t v : t)
      if (v >= n) return false;
  return true;
}

// The bytes of one builder at the least: its name's length, six array
// lengths and the flags.
constexpr std::size_t kMinBuilderBytes = 8 * sizeof(std::uint64_t);

Result<std::vector<Builder>> receiveResult(const std::vector<char>& buf, const std::string& exitInfo,
                                           const std::string& where, const MeshImportOptions& options,
                                           bool merge) {
  ByteReader r(buf);
  auto broken = [&] {
    return fail(ErrorCode::Internal, "the import process ended (" + exitInfo + ") without a complete result",
                where, "please report this with the file");
  };
  const std::uint64_t okFlag = r.u64();
  if (!r.ok()) return broken();
  if (okFlag == 0) {
    Error e = r.error();
    if (!r.ok()) return broken();
    return e;
  }
  const std::uint64_t n = r.u64();
  if (!r.ok() || n > r.remaining() / kMinBuilderBytes || (merge && n != 1)) return broken();
  std::vector<Builder> out(static_cast<std::size_t>(n));
  std::size_t triangles = 0;
  for (Builder& b : out) {
    b.mesh.name = r.str();
    r.array(b.mesh.positions);
    r.array(b.mesh.normals);
    r.array(b.hasNormal);
    r.array(b.mesh.uvs);
    r.array(b.mesh.colors);
    r.array(b.mesh.triangles);
    const std::uint64_t flags = r.u64();
    b.anyUv = (flags & 1u) != 0;
    b.anyColor = (flags & 2u) != 0;
    triangles += b.mesh.triangles.size();
    if (!r.ok() || !consistent(b) || triangles > options.maxTriangles) return broken();
  }
  if (r.u64() != 0x444d4d45534844ull || !r.ok()) return broken();
  return out;
}

// Welded, indexed meshes from the builders, the parts without a triangle
// left out.
Result<std::vector<Mesh>> finishAll(std::vector<Builder>&& builders, const MeshImportOptions& options,
                                    const std::string& where) {
  std::vector<Mesh> out;
  for (Builder& b : builders) {
    auto m = finish(std::move(b), options, where);
    if (!m) return m.error();
    if (!m->empty()) out.push_back(std::move(*m));
  }
  if (out.empty())
    return fail(
        ErrorCode::Parse,
        "contains no triangles (all are degenerate" + std::string(options.weld ? " after welding)" : ")"),
        where,
        options.weld && options.weldTolerance > 0 ? "reduce MeshImportOptions::weldTolerance"
                                                  : "the surface has zero area everywhere");
  return out;
}

// The helper's request: the source, the options and `merge`, then a marker
// (assimpImportJob reads it back).
constexpr std::uint64_t kRequestEnd = 0x444d4d4553485251ull;

void writeRequest(FdWriter& w, const Source& src, const MeshImportOptions& o, bool merge) {
  w.u64(src.file != nullptr ? 1 : 0);
  if (src.file != nullptr) {
    w.str(src.file->string());
    w.u64(src.roots.size());
    for (const fs::path& root : src.roots) w.str(root.string());
  } else {
    w.u64(src.bytes.size());
    w.bytes(src.bytes.data(), src.bytes.size());
    w.str(src.hint);
  }
  w.str(src.where);
  w.str(src.stem);
  w.str(o.unit);
  w.f64(o.scale);
  w.u64((o.mergeMeshes ? 1u : 0u) | (o.weld ? 2u : 0u) | (o.computeNormals ? 4u : 0u) | (merge ? 8u : 0u));
  w.f64(o.weldTolerance);
  w.u64(o.maxTriangles);
  w.u64(o.maxFileBytes);
  w.f64(o.timeoutSeconds);
  w.u64(kRequestEnd);
}

Result<std::vector<Builder>> loadIsolated(const Source& src, const MeshImportOptions& options, bool merge) {
  IsolateOptions iso;
  iso.library = "Assimp";
  iso.timeoutSeconds = options.timeoutSeconds;
  iso.disableHint =
      "set MeshImportOptions::isolation to Isolation::Fork (single-threaded callers) or Isolation::InProcess "
      "(trusted files)";
  iso.crashHint = "the file is malformed or triggers an Assimp bug; check or re-export it";
  iso.timeoutHint =
      "the file is malformed (Assimp 5 loops on some broken files) or very large: check it, or raise "
      "MeshImportOptions::timeoutSeconds";
  // Assimp's scene, its post-processing copies and our builders take well
  // under 1 KiB per triangle; text formats expand up to ~64× in parsing.
  // Beyond that the file asks for memory its size cannot justify.
  const std::size_t perTriangle = 1024, maxTriangles = std::min(options.maxTriangles, std::size_t{1} << 40);
  std::size_t inputBytes = src.bytes.size();
  if (src.file != nullptr) {
    std::error_code ec;
    const auto size = fs::file_size(*src.file, ec);
    inputBytes = ec ? options.maxFileBytes : std::min<std::size_t>(size, options.maxFileBytes);
  }
  iso.memoryBudget = perTriangle * maxTriangles + 64 * std::min(inputBytes, std::size_t{1} << 40) +
                     (std::size_t{512} << 20);
  iso.budgetHint =
      "the file is corrupt or crafted (it asks Assimp for more memory than its size and "
      "MeshImportOptions::maxTriangles justify); check it, or raise maxTriangles";
  auto run =
      options.isolation == Isolation::Fork
          ? runIsolated([&](FdWriter& w) { sendResult(w, loadWithAssimp(src, options, merge)); }, iso,
                        src.where)
          : runHelper(
                "assimp-import", [&](FdWriter& w) { writeRequest(w, src, options, merge); }, iso, src.where);
  if (!run) return run.error();
  return receiveResult(run->bytes, run->exitInfo, src.where, options, merge);
}

Result<std::vector<Mesh>> import(const Source& src, const MeshImportOptions& options, bool merge) {
  const std::string& where = src.where;
  if (auto s = checkOptions(options, where); !s) return s.error();
  if (auto s = checkInput(src, options); !s) return s.error();

  auto builders = options.isolation == Isolation::InProcess ? loadWithAssimp(src, options, merge)
                                                            : loadIsolated(src, options, merge);
  if (!builders) return builders.error();
  return finishAll(std::move(*builders), options, where);
}

const std::set<std::string>& assimpExtensions() {
  static const std::set<std::string> exts = [] {
    std::set<std::string> s;
    Assimp::Importer importer;
    std::string list;
    importer.GetExtensionList(list);  // "*.3ds;*.obj;..."
    std::size_t pos = 0;
    while (pos < list.size()) {
      std::size_t end = list.find(';', pos);
      if (end == std::string::npos) end = list.size();
      std::string e = list.substr(pos, end - pos);
      if (e.rfind("*.", 0) == 0) e.erase(0, 2);
      if (!e.empty()) s.insert(lower(e));
      pos = end + 1;
    }
    return s;
  }();
  return exts;
}

}  // namespace

Result<double> metresPerUnit(std::string_view unit) {
  if (unit == "m") return units::m;
  if (unit == "cm") return units::cm;
  if (unit == "mm") return units::mm;
  if (unit == "um") return units::um;
  if (unit == "inch" || unit == "in") return units::inch;
  if (unit == "ft") return 12 * units::inch;
  return fail(ErrorCode::InvalidArgument, "unknown length unit '" + std::string(unit) + "'",
              "MeshImportOptions::unit", "use one of m, cm, mm, um, inch (in), ft");
}

std::string supportedMeshExtensions() {
  std::string out;
  for (const std::string& e : assimpExtensions()) out += (out.empty() ? "*." : ";*.") + e;
  return out;
}

bool canReadMesh(const std::filesystem::path& file) {
  std::string ext = lower(file.extension().string());
  if (ext.size() < 2) return false;
  return assimpExtensions().contains(ext.substr(1));
}

Result<Mesh> readMesh(const std::filesystem::path& file, const MeshImportOptions& options) {
  Source src;
  src.file = &file;
  src.roots = FileSystem::global().allowedRoots(fs::absolute(file).parent_path());
  src.where = file.string();
  src.stem = file.stem().string();
  auto meshes = import(src, options, true);
  if (!meshes) return meshes.error();
  return std::move(meshes->front());
}

Result<std::vector<Mesh>> readMeshes(const std::filesystem::path& file, const MeshImportOptions& options) {
  Source src;
  src.file = &file;
  src.roots = FileSystem::global().allowedRoots(fs::absolute(file).parent_path());
  src.where = file.string();
  src.stem = file.stem().string();
  return import(src, options, false);
}

Result<Mesh> parseMesh(std::span<const std::byte> bytes, std::string_view formatHint,
                       const MeshImportOptions& options) {
  std::string hint = lower(formatHint);
  if (!hint.empty() && hint.front() == '.') hint.erase(0, 1);
  const bool hintOk = !hint.empty() && hint.size() <= 16 && std::all_of(hint.begin(), hint.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) != 0;
  });
  if (!hintOk)
    return fail(ErrorCode::InvalidArgument,
                "format hint '" + std::string(formatHint) + "' is not an extension", "parseMesh",
                "give the file extension without the dot, e.g. \"stl\"");
  Source src;
  src.bytes = bytes;
  src.hint = hint;
  src.where = "<memory>." + hint;
  src.stem = hint;
  auto meshes = import(src, options, true);
  if (!meshes) return meshes.error();
  return std::move(meshes->front());
}

}  // namespace dm

namespace dm::detail {

Result<std::vector<Mesh>> meshesFromResult(const std::vector<char>& bytes, const MeshImportOptions& options,
                                           bool merge, const std::string& where) {
  auto builders = receiveResult(bytes, "exit status 0", where, options, merge);
  if (!builders) return builders.error();
  return finishAll(std::move(*builders), options, where);
}

// The helper's side of an isolated import: the request writeRequest() wrote,
// loadWithAssimp() on it, the builders back as sendResult() writes them.
void assimpImportJob(ByteReader& r, FdWriter& w) {
  Source src;
  fs::path file;
  std::vector<std::byte> bytes;
  if (r.u64() == 1) {
    file = r.str();
    const std::uint64_t roots = r.u64();
    for (std::uint64_t i = 0; i < roots && r.ok(); ++i) src.roots.emplace_back(r.str());
    src.file = &file;
  } else {
    const std::uint64_t n = r.u64();
    if (r.ok() && n <= r.remaining()) {
      bytes.resize(static_cast<std::size_t>(n));
      r.bytes(bytes.data(), bytes.size());
    } else {
      r.markBroken();
    }
    src.bytes = bytes;
    src.hint = r.str();
  }
  src.where = r.str();
  src.stem = r.str();
  MeshImportOptions o;
  o.unit = r.str();
  o.scale = r.f64();
  const std::uint64_t flags = r.u64();
  o.mergeMeshes = (flags & 1u) != 0;
  o.weld = (flags & 2u) != 0;
  o.computeNormals = (flags & 4u) != 0;
  const bool merge = (flags & 8u) != 0;
  o.weldTolerance = r.f64();
  o.maxTriangles = static_cast<std::size_t>(r.u64());
  o.maxFileBytes = static_cast<std::size_t>(r.u64());
  o.timeoutSeconds = r.f64();
  o.isolation = Isolation::InProcess;  // this is the isolated process
  if (r.u64() != kRequestEnd || !r.ok()) {
    sendResult(w, fail(ErrorCode::Internal, "the import helper got an incomplete request", src.where,
                       "please report this"));
    return;
  }
  sendResult(w, loadWithAssimp(src, o, merge));
}

}  // namespace dm::detail
