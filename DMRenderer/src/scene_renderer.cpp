// scene_renderer.cpp — GPU meshes, textures and materials behind generational
// handles; the render queue (cull, LOD, sort, instance); shadow and camera passes.
#include <dm/collide/bvh.hpp>
#include <dm/renderer/scene_renderer.hpp>
#include <dm/renderer/shader.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <string>

#include "gl.hpp"
#include "light_uniforms.hpp"
#include "scene_shaders.hpp"

namespace dm {

namespace {

// Interleaved vertex as the shaders read it (64 bytes).
struct GpuVertex {
  float position[3];
  float normal[3];
  float uv[2];
  float color[4];
  float tangent[4];
};
static_assert(sizeof(GpuVertex) == 64);

// Per instance: the column-major model matrix, then its normal matrix (the
// inverse transpose of the 3x3 part) as three vec4 columns, computed once per
// instance on the CPU instead of per vertex in the shader.
using InstanceMatrix = std::array<float, 28>;

// A run of triangles of the index buffer and the box of their vertices
// (mesh frame).
struct MeshCluster {
  std::uint32_t first = 0, count = 0;
  Aabb box;
};

struct MeshSlot {
  std::uint32_t generation = 0;
  bool alive = false;
  GLuint vao = 0, vbo = 0, ibo = 0;
  std::size_t vertexCount = 0;
  std::vector<Triangle> triangles;  // CPU copy: tells an in-place update from a topology change
  bool hasColors = false;           // per-vertex colours given (selects the VERTEX_COLOR variant)
  Aabb bounds;
  Vec3 sphereCenter = Vec3::Zero();
  double sphereRadius = 0;
  int uploads = 0, inPlaceUpdates = 0;
  std::vector<LodLevel> lods;  // by maxScreenFraction, largest first
  // Cluster culling (setMeshTree): the index buffer holds the triangles in
  // the tree's leaf order (GPU triangle k = triangles[leafOrder[k]]), cut
  // into runs of whole subtrees with their local-frame boxes. Empty: none.
  std::vector<std::uint32_t> leafOrder;
  std::vector<MeshCluster> clusters;
};

struct TextureSlot {
  std::uint32_t generation = 0;
  bool alive = false;
  GLuint texture = 0;
  int width = 0, height = 0, channels = 0;
  SceneTextureOptions options;
};

struct MaterialSlot {
  std::uint32_t generation = 0;
  bool alive = false;
  Material material;
};

// Slots reused through a free list; a handle matches only while its
// generation equals the slot's and the slot is alive.
template <class Slot>
struct Pool {
  std::vector<Slot> slots;
  std::vector<std::uint32_t> freeList;

  template <class Handle>
  Slot* get(Handle h) {
    if (h.generation == 0 || h.index >= slots.size()) return nullptr;
    Slot& s = slots[h.index];
    return s.alive && s.generation == h.generation ? &s : nullptr;
  }
  template <class Handle>
  const Slot* get(Handle h) const {
    return const_cast<Pool*>(this)->get(h);
  }
  template <class Handle>
  Handle allocate() {
    std::uint32_t index;
    if (!freeList.empty()) {
      index = freeList.back();
      freeList.pop_back();
    } else {
      index = static_cast<std::uint32_t>(slots.size());
      slots.emplace_back();
    }
    Slot& s = slots[index];
    s.generation = s.generation + 1 == 0 ? 1 : s.generation + 1;
    s.alive = true;
    return Handle{index, s.generation};
  }
  void release(std::uint32_t index) {
    slots[index].alive = false;
    freeList.push_back(index);
  }
};

Error staleHandle(const char* kind, std::uint32_t index, std::uint32_t generation) {
  return fail(ErrorCode::NotFound,
              formatString("%s id %u (generation %u) is not alive", kind, index, generation), "SceneRenderer",
              "use an id returned by this renderer and not removed since");
}

// Per-vertex tangents from uvs (Lengyel): accumulate each triangle's uv
// gradient directions, orthogonalise against the normal, store handedness.
// `tan` and `bitangents` are scratch (their capacity is reused across uploads).
void computeTangents(const Mesh& mesh, const std::vector<Vec3>& normals, std::vector<Vec4f>& out,
                     std::vector<Vec3>& tan, std::vector<Vec3>& bitangents) {
  const std::size_t n = mesh.positions.size();
  tan.assign(n, Vec3::Zero());
  bitangents.assign(n, Vec3::Zero());
  if (!mesh.uvs.empty()) {
    for (const Triangle& t : mesh.triangles) {
      const Vec3 e1 = mesh.positions[t[1]] - mesh.positions[t[0]];
      const Vec3 e2 = mesh.positions[t[2]] - mesh.positions[t[0]];
      const Vec2f d1 = mesh.uvs[t[1]] - mesh.uvs[t[0]];
      const Vec2f d2 = mesh.uvs[t[2]] - mesh.uvs[t[0]];
      const double det = double(d1.x()) * d2.y() - double(d2.x()) * d1.y();
      if (std::abs(det) < 1e-20) continue;
      const double r = 1.0 / det;
      const Vec3 sdir = (e1 * d2.y() - e2 * d1.y()) * r;
      const Vec3 tdir = (e2 * d1.x() - e1 * d2.x()) * r;
      for (std::uint32_t v : t) {
        tan[v] += sdir;
        bitangents[v] += tdir;
      }
    }
  }
  out.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3& nn = normals[i];
    Vec3 t = tan[i] - nn * nn.dot(tan[i]);
    double w = 1;
    if (t.squaredNorm() < 1e-24) {
      // No uv gradient: any unit vector across the normal keeps the frame valid.
      t = std::abs(nn.x()) < 0.9 ? nn.cross(Vec3::UnitX()) : nn.cross(Vec3::UnitY());
    } else {
      w = nn.cross(t).dot(bitangents[i]) < 0 ? -1 : 1;
    }
    const double len = t.norm();
    if (len > 0) t /= len;
    out[i] = Vec4f(float(t.x()), float(t.y()), float(t.z()), float(w));
  }
}

// Gribb–Hartmann planes of a view-projection matrix; a box is outside when
// its most positive corner is behind any plane.
struct Frustum {
  std::array<Vec4, 6> planes;
  explicit Frustum(const Mat4& m) {
    for (int i = 0; i < 3; ++i) {
      planes[2 * i] = (m.row(3) + m.row(i)).transpose();
      planes[2 * i + 1] = (m.row(3) - m.row(i)).transpose();
    }
  }
  bool outside(const Aabb& box) const {
    for (const Vec4& p : planes) {
      const Vec3 v(p.x() >= 0 ? box.max().x() : box.min().x(), p.y() >= 0 ? box.max().y() : box.min().y(),
                   p.z() >= 0 ? box.max().z() : box.min().z());
      if (p.head<3>().dot(v) + p.w() < 0) return true;
    }
    return false;
  }
};

Aabb transformBox(const Aabb& box, const Affine3& t) {
  Aabb out;
  for (int c = 0; c < 8; ++c) out.extend(t * box.corner(static_cast<Aabb::CornerType>(c)));
  return out;
}

Vec3 anyUp(const Vec3& dir) { return std::abs(dir.normalized().y()) < 0.99 ? Vec3::UnitY() : Vec3::UnitX(); }

Status validateLight(const Light& l, std::size_t i) {
  const std::string where = formatString("lights[%zu]", i);
  const bool needsDir = l.type != Light::Type::Point;
  const bool needsPos = l.type != Light::Type::Directional;
  if (needsDir && (!l.direction.allFinite() || l.direction.norm() < 1e-12))
    return fail(ErrorCode::InvalidArgument, "light direction is zero or not finite", where + ".direction",
                "give the direction the light travels");
  if (needsPos && !l.position.allFinite())
    return fail(ErrorCode::InvalidArgument, "light position is not finite", where + ".position");
  if (needsPos && !(l.range > 0))
    return fail(ErrorCode::InvalidArgument, formatString("range is %g m", l.range), where + ".range",
                "use a positive range in metres");
  if (l.type == Light::Type::Spot &&
      !(l.innerConeDeg >= 0 && l.outerConeDeg > l.innerConeDeg && l.outerConeDeg < 90))
    return fail(ErrorCode::InvalidArgument,
                formatString("cone angles inner %g, outer %g degrees", l.innerConeDeg, l.outerConeDeg),
                where + ".outerConeDeg", "need 0 <= inner < outer < 90");
  if (!l.color.allFinite() || !std::isfinite(l.intensity) || l.intensity < 0)
    return fail(ErrorCode::InvalidArgument, "light colour or intensity is negative or not finite",
                where + ".intensity");
  return ok();
}

Status validateMaterial(const Material& m) {
  auto bad = [](const char* field, const char* hint) {
    return fail(ErrorCode::InvalidArgument, formatString("%s is out of range or not finite", field),
                formatString("material.%s", field), hint);
  };
  if (!m.baseColor.allFinite() || (m.baseColor.array() < 0).any()) return bad("baseColor", "use [0, 1]");
  if (!m.specular.allFinite() || (m.specular.array() < 0).any()) return bad("specular", "use [0, 1]");
  if (!(m.shininess >= 1 && m.shininess <= 1e4f)) return bad("shininess", "use 1..10000");
  if (!(m.metallic >= 0 && m.metallic <= 1)) return bad("metallic", "use [0, 1]");
  if (!(m.roughness >= 0 && m.roughness <= 1)) return bad("roughness", "use [0, 1]");
  if (!m.emissive.allFinite() || (m.emissive.array() < 0).any()) return bad("emissive", "use >= 0");
  if (!(m.heightScale >= 0 && std::isfinite(m.heightScale)))
    return bad("heightScale", "use a finite depth >= 0 in metres (0 turns the relief off)");
  return ok();
}

}  // namespace

Light Light::directional(const Vec3& dir, float intensity, const Vec3f& color) {
  Light l;
  l.type = Type::Directional;
  l.direction = dir;
  l.intensity = intensity;
  l.color = color;
  return l;
}

Light Light::point(const Vec3& pos, float intensity, double range, const Vec3f& color) {
  Light l;
  l.type = Type::Point;
  l.position = pos;
  l.intensity = intensity;
  l.range = range;
  l.color = color;
  return l;
}

Light Light::spot(const Vec3& pos, const Vec3& dir, double innerDeg, double outerDeg, float intensity,
                  double range, const Vec3f& color) {
  Light l;
  l.type = Type::Spot;
  l.position = pos;
  l.direction = dir;
  l.innerConeDeg = innerDeg;
  l.outerConeDeg = outerDeg;
  l.intensity = intensity;
  l.range = range;
  l.color = color;
  return l;
}

RenderStats& RenderStats::operator+=(const RenderStats& o) {
  drawCalls += o.drawCalls;
  instances += o.instances;
  triangles += o.triangles;
  itemsCulled += o.itemsCulled;
  clustersCulled += o.clustersCulled;
  lodSwitches += o.lodSwitches;
  shadowMaps += o.shadowMaps;
  shadowDrawCalls += o.shadowDrawCalls;
  return *this;
}

struct SceneRenderer::Impl {
  struct View {
    Viewport viewport;
    Camera camera;
  };
  // One draw call: `count` instances starting at `first` in the instance buffer.
  struct Batch {
    int program = 0;
    std::uint32_t material = 0;
    std::uint32_t mesh = 0;
    std::uint32_t first = 0;
    std::uint32_t count = 0;
    std::uint32_t item = 0;  // the first item's index
  };
  struct Record {
    std::uint64_t key = 0;
    std::uint32_t item = 0;
    std::uint32_t mesh = 0;
  };
  struct ShadowLight {
    int layer = 0;
    Mat4f viewProj;
    float texel = 0;  // world size of a texel (per metre of distance for spots)
    bool perspective = false;
  };

  SceneRendererOptions options;
  // Programs by ShadingModel x variant flags (kColorTex, kNormalTex,
  // kVertexColor, kShadows, kHeightTex, kDirectionalOnly, kSingle) x light
  // count 0..kMaxLights, compiled on first use: slot = (model * kVariants +
  // flags) * kLightCounts + lights. kShadows and kDirectionalOnly are per
  // frame, kSingle per draw (one instance).
  static constexpr int kColorTex = 1, kNormalTex = 2, kVertexColor = 4, kShadows = 8, kHeightTex = 16,
                       kDirectionalOnly = 32, kSingle = 64;
  static constexpr int kVariants = 128;
  static constexpr int kLightCounts = kMaxLights + 1;
  std::array<ShaderProgram, 3 * kVariants * kLightCounts> programs;
  std::string normalOffset;

  int programIndex(const Material& m, const MeshSlot& mesh) const {
    int flags = 0;
    if (textures.get(m.colorTexture) != nullptr) flags |= kColorTex;
    if (textures.get(m.normalTexture) != nullptr) flags |= kNormalTex;
    // No relief (scale 0) or nothing to shift (no colour or normal map): the
    // parallax march would change no pixel, so that variant is not paid for.
    if (textures.get(m.heightTexture) != nullptr && m.heightScale > 0 &&
        (flags & (kColorTex | kNormalTex)) != 0)
      flags |= kHeightTex;
    if (m.useVertexColors && mesh.hasColors) flags |= kVertexColor;
    return int(m.model) * kVariants + flags;
  }

  Status compileProgram(int index) {
    if (programs[std::size_t(index)].valid()) return ok();
    static const char* names[3] = {"scene_unlit", "scene_blinn_phong", "scene_pbr"};
    const int lightCount = index % kLightCounts, variant = index / kLightCounts;
    const int model = variant / kVariants, flags = variant % kVariants;
    auto bit = [&](int f) { return std::string((flags & f) != 0 ? "1" : "0"); };
    auto p = ShaderProgram::create(
        names[model],
        {{ShaderStage::Vertex, scene_glsl::kMeshVs}, {ShaderStage::Fragment, scene_glsl::kMeshFs}},
        {{"MODEL", std::to_string(model)},
         {"NORMAL_OFFSET", normalOffset},
         {"COLOR_TEX", bit(kColorTex)},
         {"NORMAL_TEX", bit(kNormalTex)},
         {"HEIGHT_TEX", bit(kHeightTex)},
         {"VERTEX_COLOR", bit(kVertexColor)},
         {"SHADOWS", bit(kShadows)},
         {"DIRECTIONAL_ONLY", bit(kDirectionalOnly)},
         {"SINGLE", bit(kSingle)},
         {"NUM_LIGHTS", std::to_string(lightCount)}});
    if (!p) return p.error();
    programs[std::size_t(index)] = std::move(*p);
    return ok();
  }
  // The frame's lights as the last setFrameUniforms call saw them.
  Vec3f frameAmbient = Vec3f::Zero();
  std::array<Vec3f, kMaxLights> frameLightColor{};
  int frameLightCount = 0;
  ShaderProgram depthProgram;
  GLuint shadowTex = 0, shadowFbo = 0;
  GLuint instanceBuffer = 0;
  std::size_t instanceCapacity = 0;  // matrices
  int maxTextureSize = 0;

  Pool<MeshSlot> meshes;
  Pool<TextureSlot> textures;
  Pool<MaterialSlot> materials;
  RenderStats stats;

  // Scratch reused across frames and uploads (no allocation once warm).
  std::vector<GLsizei> rangeCounts;
  std::vector<const void*> rangeOffsets;
  std::vector<GpuVertex> vertices;
  Mesh normalScratch;
  std::vector<Vec4f> tangents;
  std::vector<Vec3> tangentSums;
  std::vector<Vec3> bitangents;
  std::vector<InstanceMatrix> instances;
  std::vector<Record> records;
  std::vector<Batch> shadowBatches;
  std::vector<std::vector<Batch>> viewBatches;
  std::vector<ShadowLight> shadowLights;
  std::vector<int> lightLayer;
  std::vector<Mat4f, Eigen::aligned_allocator<Mat4f>> viewProjs;

  ~Impl() {
    for (MeshSlot& m : meshes.slots) freeMesh(m);
    for (TextureSlot& t : textures.slots)
      if (t.texture != 0) glDeleteTextures(1, &t.texture);
    if (shadowTex != 0) glDeleteTextures(1, &shadowTex);
    if (shadowFbo != 0) glDeleteFramebuffers(1, &shadowFbo);
    if (instanceBuffer != 0) glDeleteBuffers(1, &instanceBuffer);
  }

  static void freeMesh(MeshSlot& m) {
    if (m.vao != 0) glDeleteVertexArrays(1, &m.vao);
    if (m.vbo != 0) glDeleteBuffers(1, &m.vbo);
    if (m.ibo != 0) glDeleteBuffers(1, &m.ibo);
    m.vao = m.vbo = m.ibo = 0;
  }

  // Fills `vertices` from a validated mesh (normals computed when missing).
  void buildVertices(const Mesh& mesh) {
    const std::vector<Vec3>* normals = &mesh.normals;
    if (mesh.normals.empty()) {
      normalScratch.positions = mesh.positions;
      normalScratch.triangles = mesh.triangles;
      normalScratch.computeNormals();
      normals = &normalScratch.normals;
    }
    computeTangents(mesh, *normals, tangents, tangentSums, bitangents);
    const std::size_t n = mesh.positions.size();
    vertices.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      GpuVertex& v = vertices[i];
      const Vec3& p = mesh.positions[i];
      const Vec3& nn = (*normals)[i];
      v = GpuVertex{{float(p.x()), float(p.y()), float(p.z())},
                    {float(nn.x()), float(nn.y()), float(nn.z())},
                    {0, 0},
                    {1, 1, 1, 1},
                    {tangents[i].x(), tangents[i].y(), tangents[i].z(), tangents[i].w()}};
      if (!mesh.uvs.empty()) {
        v.uv[0] = mesh.uvs[i].x();
        v.uv[1] = mesh.uvs[i].y();
      }
      if (!mesh.colors.empty())
        for (int c = 0; c < 4; ++c) v.color[c] = mesh.colors[i][c];
    }
  }

  // Each cluster's box over the vertices of its triangles, from `positions`.
  static void setClusterBoxes(MeshSlot& s, std::span<const Vec3> positions) {
    for (MeshCluster& c : s.clusters) {
      c.box.setEmpty();
      for (std::uint32_t k = c.first; k < c.first + c.count; ++k)
        for (std::uint32_t v : s.triangles[s.leafOrder[k]]) c.box.extend(positions[v]);
    }
  }

  static void setBounds(MeshSlot& s, const Mesh& mesh) {
    s.bounds = mesh.bounds();
    s.sphereCenter = s.bounds.center();
    s.sphereRadius = 0;
    for (const Vec3& p : mesh.positions)
      s.sphereRadius = std::max(s.sphereRadius, (p - s.sphereCenter).norm());
  }

  Status upload(MeshSlot& s, const Mesh& mesh) {
    buildVertices(mesh);
    freeMesh(s);
    glCreateBuffers(1, &s.vbo);
    glNamedBufferStorage(s.vbo, GLsizeiptr(vertices.size() * sizeof(GpuVertex)), vertices.data(),
                         GL_DYNAMIC_STORAGE_BIT);
    glCreateBuffers(1, &s.ibo);
    glNamedBufferStorage(s.ibo, GLsizeiptr(mesh.triangles.size() * sizeof(Triangle)), mesh.triangles.data(),
                         0);
    glCreateVertexArrays(1, &s.vao);
    glVertexArrayVertexBuffer(s.vao, 0, s.vbo, 0, sizeof(GpuVertex));
    glVertexArrayElementBuffer(s.vao, s.ibo);
    const struct {
      GLuint loc;
      GLint size;
      GLuint offset;
    } attribs[] = {{0, 3, offsetof(GpuVertex, position)},
                   {1, 3, offsetof(GpuVertex, normal)},
                   {2, 2, offsetof(GpuVertex, uv)},
                   {3, 4, offsetof(GpuVertex, color)},
                   {4, 4, offsetof(GpuVertex, tangent)}};
    for (const auto& a : attribs) {
      glEnableVertexArrayAttrib(s.vao, a.loc);
      glVertexArrayAttribFormat(s.vao, a.loc, a.size, GL_FLOAT, GL_FALSE, a.offset);
      glVertexArrayAttribBinding(s.vao, a.loc, 0);
    }
    for (GLuint c = 0; c < 7; ++c) {  // 5..8 model matrix, 9..11 normal matrix
      glEnableVertexArrayAttrib(s.vao, 5 + c);
      glVertexArrayAttribFormat(s.vao, 5 + c, 4, GL_FLOAT, GL_FALSE, c * 4 * sizeof(float));
      glVertexArrayAttribBinding(s.vao, 5 + c, 1);
    }
    glVertexArrayBindingDivisor(s.vao, 1, 1);
    s.vertexCount = mesh.positions.size();
    s.triangles = mesh.triangles;
    s.leafOrder.clear();  // new triangles: a tree of the old ones no longer applies
    s.clusters.clear();
    s.hasColors = !mesh.colors.empty();
    setBounds(s, mesh);
    ++s.uploads;
    return gl::check("SceneRenderer mesh upload");
  }

  static Status checkMesh(const Mesh& mesh) {
    if (Status v = mesh.validate(); !v) return v;
    if (mesh.triangles.empty())
      return fail(ErrorCode::InvalidArgument, "mesh has no triangles", mesh.name.empty() ? "mesh" : mesh.name,
                  "give at least one triangle");
    return ok();
  }

  Status checkItems(std::span<const DrawItem> items) {
    for (std::size_t i = 0; i < items.size(); ++i) {
      const DrawItem& it = items[i];
      if (!it.visible) continue;
      if (meshes.get(it.mesh) == nullptr)
        return fail(ErrorCode::InvalidArgument, "mesh id is stale or invalid",
                    formatString("items[%zu].mesh", i), "use an id from addMesh() not removed since");
      if (materials.get(it.material) == nullptr)
        return fail(ErrorCode::InvalidArgument, "material id is stale or invalid",
                    formatString("items[%zu].material", i), "use an id from addMaterial() not removed since");
      if (!it.model.matrix().allFinite())
        return fail(ErrorCode::InvalidArgument, "model matrix is not finite",
                    formatString("items[%zu].model", i));
    }
    return ok();
  }

  // The coarsest registered level whose threshold still covers the item's
  // projected size; the base mesh when none does.
  std::uint32_t pickLod(const MeshSlot& base, std::uint32_t baseIndex, const Camera& cam, const Vec3& center,
                        double radius) {
    if (base.lods.empty()) return baseIndex;
    double fraction;
    if (cam.projection == Camera::Projection::Perspective) {
      const double d = (center - cam.position).norm();
      if (d <= radius) return baseIndex;
      fraction = radius / (d * std::tan(cam.fovYDeg * std::numbers::pi / 360.0));
    } else {
      fraction = 2 * radius / cam.orthoHeight;
    }
    std::uint32_t chosen = baseIndex;
    for (const LodLevel& l : base.lods)
      if (fraction <= l.maxScreenFraction && meshes.get(l.mesh) != nullptr) chosen = l.mesh.index;
    return chosen;
  }

  // Groups sorted records into batches (consecutive equal keys share one draw).
  void makeBatches(std::span<const DrawItem> items, std::vector<Batch>& out, bool byMaterial) {
    std::sort(records.begin(), records.end(), [](const Record& a, const Record& b) {
      return a.key != b.key ? a.key < b.key : a.item < b.item;
    });
    out.clear();
    for (std::size_t i = 0; i < records.size(); ++i) {
      const Record& r = records[i];
      if (out.empty() || i == 0 || records[i - 1].key != r.key) {
        Batch b;
        const DrawItem& it = items[r.item];
        b.mesh = r.mesh;
        b.material = byMaterial ? it.material.index : 0;
        b.program = byMaterial ? programIndex(materials.get(it.material)->material, meshes.slots[r.mesh]) : 0;
        b.first = static_cast<std::uint32_t>(instances.size());
        b.item = r.item;
        out.push_back(b);
      }
      InstanceMatrix m{};
      const Affine3& model = items[r.item].model;
      const Mat4f mf = model.matrix().cast<float>();
      std::copy(mf.data(), mf.data() + 16, m.begin());
      const Mat3 nm = model.linear().inverse().transpose();
      for (int c = 0; c < 3; ++c)
        for (int k = 0; k < 3; ++k) m[std::size_t(16 + 4 * c + k)] = float(nm(k, c));
      instances.push_back(m);
      ++out.back().count;
    }
  }

  void fitShadow(const Light& l, const Aabb& scene, ShadowLight& s) const {
    const Vec3 dir = l.direction.normalized();
    if (l.type == Light::Type::Directional) {
      const Vec3 c = scene.center();
      const double r = std::max(0.5 * scene.diagonal().norm(), 1e-3);
      const Camera aim = Camera::lookAt(c - 2 * r * dir, c, anyUp(dir));
      const Mat4 view = aim.viewMatrix().cast<double>();
      Aabb ls;
      for (int k = 0; k < 8; ++k)
        ls.extend((view * scene.corner(static_cast<Aabb::CornerType>(k)).homogeneous()).head<3>());
      // A square orthographic frustum around the scene's box in light space:
      // the eye sits at the middle of the box's face towards the light.
      const double pad = 0.02 * r + 2.0 * r / options.shadowMapSize;
      const double w = ls.sizes().head<2>().maxCoeff() + 2 * pad;
      Camera cam = aim;
      cam.projection = Camera::Projection::Orthographic;
      cam.position = aim.pose() * Vec3(ls.center().x(), ls.center().y(), ls.max().z() + pad);
      cam.target = cam.position + dir;
      cam.orthoHeight = w;
      cam.nearPlane = 0.5 * pad;
      cam.farPlane = ls.sizes().z() + 2 * pad;
      s.viewProj = cam.projectionMatrix(1.0) * cam.viewMatrix();
      s.texel = float(w / options.shadowMapSize);
      s.perspective = false;
    } else {
      Camera cam = Camera::lookAt(l.position, l.position + dir, anyUp(dir));
      cam.fovYDeg = std::min(2 * l.outerConeDeg + 4, 170.0);
      cam.farPlane = l.range;
      cam.nearPlane = std::max(l.range * 1e-3, 1e-4);
      s.viewProj = cam.projectionMatrix(1.0) * cam.viewMatrix();
      s.texel = float(2 * std::tan(cam.fovYDeg * std::numbers::pi / 360.0) / options.shadowMapSize);
      s.perspective = true;
    }
  }

  void setFrameUniforms(ShaderProgram& p, const Camera& cam, const Mat4f& viewProj,
                        std::span<const Light> lights, const RenderSettings& settings) {
    p.set("u_viewProj", viewProj);
    p.set("u_cameraPos", Vec3f(cam.position.cast<float>()));
    // Orthographic: every eye ray runs along -forward (the parallax march needs it exact).
    const bool ortho = cam.projection == Camera::Projection::Orthographic;
    const Vec3f toEye = -cam.forward().cast<float>();
    p.set("u_orthoToEye", ortho ? Vec4f(toEye.x(), toEye.y(), toEye.z(), 1) : Vec4f::Zero());
    p.set("u_ambient", settings.ambient);
    const int n = static_cast<int>(lights.size());
    frameAmbient = settings.ambient;
    frameLightCount = n;
    gl::LightUniforms packed;
    packed.pack(lights);
    packed.upload(p);
    std::array<int, kMaxLights> shadow{};
    for (int i = 0; i < n; ++i) {
      shadow[std::size_t(i)] = lightLayer[std::size_t(i)];
      frameLightColor[std::size_t(i)] = lights[std::size_t(i)].color * lights[std::size_t(i)].intensity;
    }
    const GLuint id = p.id();
    if (n > 0) glProgramUniform1iv(id, p.location("u_lightShadow"), n, shadow.data());
    const int ns = static_cast<int>(shadowLights.size());
    if (ns > 0) {
      std::array<float, 16 * kMaxShadowMaps> mats{};
      std::array<float, kMaxShadowMaps> texel{};
      std::array<int, kMaxShadowMaps> persp{};
      for (const ShadowLight& s : shadowLights) {
        std::copy(s.viewProj.data(), s.viewProj.data() + 16, mats.begin() + 16 * s.layer);
        texel[std::size_t(s.layer)] = s.texel;
        persp[std::size_t(s.layer)] = s.perspective ? 1 : 0;
      }
      glProgramUniformMatrix4fv(id, p.location("u_shadowMatrix"), ns, GL_FALSE, mats.data());
      glProgramUniform1fv(id, p.location("u_shadowTexel"), ns, texel.data());
      glProgramUniform1iv(id, p.location("u_shadowPerspective"), ns, persp.data());
    }
  }

  // Material uniforms, and for Blinn–Phong the material × light products of
  // the frame's lights (set by setFrameUniforms before): the light's colour
  // times the specular colour and, where the base colour is the same for
  // every fragment (no vertex colours, no colour texture: `flags`), times the
  // base colour, with ambient × base + emissive as one term. llvmpipe loads
  // and broadcasts every uniform for every block of fragments, so each
  // product folded here is work the fragment stage does not repeat.
  void setMaterialUniforms(ShaderProgram& p, const Material& m, int flags) {
    if (m.model == ShadingModel::BlinnPhong) {
      const bool constBase = (flags & (kColorTex | kVertexColor)) == 0;
      const Vec3f base = constBase ? Vec3f(m.baseColor.head<3>()) : Vec3f::Ones();
      if (frameLightCount > 0) {
        std::array<float, 3 * kMaxLights> diffuse{}, specular{};
        for (int i = 0; i < frameLightCount; ++i)
          for (int k = 0; k < 3; ++k) {
            const float c = frameLightColor[std::size_t(i)][k];
            diffuse[std::size_t(3 * i + k)] = c * base[k];
            specular[std::size_t(3 * i + k)] = c * m.specular[k];
          }
        glProgramUniform3fv(p.id(), p.location("u_lightDiffuse"), frameLightCount, diffuse.data());
        glProgramUniform3fv(p.id(), p.location("u_lightSpecular"), frameLightCount, specular.data());
      }
      if (constBase) p.set("u_ambientEmissive", Vec3f(frameAmbient.cwiseProduct(base) + m.emissive));
    }
    p.set("u_baseColor", m.baseColor);
    p.set("u_specular", m.specular);
    p.set("u_shininess", m.shininess);
    p.set("u_metallic", m.metallic);
    p.set("u_roughness", m.roughness);
    p.set("u_emissive", m.emissive);
    const TextureSlot* color = textures.get(m.colorTexture);
    const TextureSlot* normal = textures.get(m.normalTexture);
    const TextureSlot* height = textures.get(m.heightTexture);
    p.set("u_doubleSided", m.doubleSided ? 1 : 0);
    p.set("u_heightScale", m.heightScale);
    glBindTextureUnit(0, color != nullptr ? color->texture : 0);
    glBindTextureUnit(1, normal != nullptr ? normal->texture : 0);
    glBindTextureUnit(3, height != nullptr ? height->texture : 0);  // unit 2: the shadow maps
    if (m.doubleSided)
      glDisable(GL_CULL_FACE);
    else
      glEnable(GL_CULL_FACE);
  }

  void drawBatch(const Batch& b) {
    const MeshSlot& m = meshes.slots[b.mesh];
    glVertexArrayVertexBuffer(m.vao, 1, instanceBuffer, GLintptr(b.first * sizeof(InstanceMatrix)),
                              sizeof(InstanceMatrix));
    glBindVertexArray(m.vao);
    glDrawElementsInstanced(GL_TRIANGLES, GLsizei(m.triangles.size() * 3), GL_UNSIGNED_INT, nullptr,
                            GLsizei(b.count));
  }

  // A single item of a clustered mesh: only the clusters whose box meets
  // the view frustum (tested in the mesh's frame, planes · model), adjacent
  // ones merged into one range, all ranges in one glMultiDrawElements.
  // Returns the triangles drawn and counts the clusters culled.
  std::size_t drawClusters(const Batch& b, const Mat4& viewProj, const Affine3& model, int& culled) {
    const MeshSlot& m = meshes.slots[b.mesh];
    const Frustum local(viewProj * model.matrix());
    rangeCounts.clear();
    rangeOffsets.clear();
    std::size_t drawn = 0;
    std::uint32_t end = ~0u;
    for (const MeshCluster& c : m.clusters) {
      if (local.outside(c.box)) {
        ++culled;
        continue;
      }
      drawn += c.count;
      if (c.first == end) {
        rangeCounts.back() += GLsizei(3 * c.count);
      } else {
        rangeCounts.push_back(GLsizei(3 * c.count));
        rangeOffsets.push_back(reinterpret_cast<const void*>(std::uintptr_t(c.first) * sizeof(Triangle)));
      }
      end = c.first + c.count;
    }
    if (rangeCounts.empty()) return 0;
    glVertexArrayVertexBuffer(m.vao, 1, instanceBuffer, GLintptr(b.first * sizeof(InstanceMatrix)),
                              sizeof(InstanceMatrix));
    glBindVertexArray(m.vao);
    glMultiDrawElements(GL_TRIANGLES, rangeCounts.data(), GL_UNSIGNED_INT, rangeOffsets.data(),
                        GLsizei(rangeCounts.size()));
    return drawn;
  }

  Result<RenderStats> renderViews(const RenderTarget& target, std::span<const View> views,
                                  std::span<const DrawItem> items, std::span<const Light> lights,
                                  const RenderSettings& settings);
};

Result<RenderStats> SceneRenderer::Impl::renderViews(const RenderTarget& target, std::span<const View> views,
                                                     std::span<const DrawItem> items,
                                                     std::span<const Light> lights,
                                                     const RenderSettings& settings) {
  if (!target.valid())
    return fail(ErrorCode::InvalidArgument, "render target is empty", "SceneRenderer::render",
                "create it with RenderTarget::create()");
  for (const View& v : views) {
    if (Status s = v.camera.validate(); !s) return s.error();
    const Viewport& vp = v.viewport;
    if (vp.width <= 0 || vp.height <= 0 || vp.x < 0 || vp.y < 0 || vp.x + vp.width > target.width() ||
        vp.y + vp.height > target.height())
      return fail(ErrorCode::InvalidArgument,
                  formatString("viewport %dx%d at (%d, %d) outside the %dx%d target", vp.width, vp.height,
                               vp.x, vp.y, target.width(), target.height()),
                  "viewport", "keep the viewport inside the target");
  }
  if (lights.size() > std::size_t(kMaxLights))
    return fail(ErrorCode::InvalidArgument, formatString("%zu lights", lights.size()), "lights",
                formatString("give at most %d lights per frame", kMaxLights));
  for (std::size_t i = 0; i < lights.size(); ++i)
    if (Status s = validateLight(lights[i], i); !s) return s.error();
  if (Status s = checkItems(items); !s) return s.error();

  RenderStats st;
  instances.clear();

  // Shadow casters and the bounds the directional light frusta are fitted to.
  Aabb scene;
  records.clear();
  for (std::size_t i = 0; i < items.size(); ++i) {
    const DrawItem& it = items[i];
    if (!it.visible) continue;
    const MeshSlot& m = *meshes.get(it.mesh);
    scene.extend(transformBox(m.bounds, it.model));
    if (it.castsShadow) records.push_back({it.mesh.index, std::uint32_t(i), it.mesh.index});
  }
  shadowLights.clear();
  lightLayer.assign(lights.size(), -1);
  if (settings.shadows && !scene.isEmpty()) {
    for (std::size_t i = 0; i < lights.size() && shadowLights.size() < std::size_t(kMaxShadowMaps); ++i) {
      const Light& l = lights[i];
      if (!l.castsShadow || l.type == Light::Type::Point) continue;
      ShadowLight s;
      s.layer = static_cast<int>(shadowLights.size());
      fitShadow(l, scene, s);
      lightLayer[i] = s.layer;
      shadowLights.push_back(s);
    }
  }
  if (!shadowLights.empty())
    makeBatches(items, shadowBatches, false);
  else
    shadowBatches.clear();

  // Camera passes: cull, pick LODs, sort by program, material, mesh.
  if (viewBatches.size() < views.size()) viewBatches.resize(views.size());
  viewProjs.clear();
  for (std::size_t v = 0; v < views.size(); ++v) {
    const Camera& cam = views[v].camera;
    const double aspect = double(views[v].viewport.width) / views[v].viewport.height;
    const Mat4f vp = cam.projectionMatrix(aspect) * cam.viewMatrix();
    viewProjs.push_back(vp);
    const Frustum frustum(vp.cast<double>());
    records.clear();
    for (std::size_t i = 0; i < items.size(); ++i) {
      const DrawItem& it = items[i];
      if (!it.visible) continue;
      const MeshSlot& m = *meshes.get(it.mesh);
      if (frustum.outside(transformBox(m.bounds, it.model))) {
        ++st.itemsCulled;
        continue;
      }
      const double scale = it.model.linear().colwise().norm().maxCoeff();
      const std::uint32_t mesh =
          pickLod(m, it.mesh.index, cam, it.model * m.sphereCenter, m.sphereRadius * scale);
      if (mesh != it.mesh.index) ++st.lodSwitches;
      const std::uint64_t program =
          std::uint64_t(programIndex(materials.get(it.material)->material, meshes.slots[mesh]));
      // Key: program (9 bits: 3 models x kVariants), material, mesh (27 bits each).
      records.push_back(
          {(program << 55) | (std::uint64_t(it.material.index) << 27) | mesh, std::uint32_t(i), mesh});
    }
    makeBatches(items, viewBatches[v], true);
  }

  // One upload of every pass's instance matrices.
  if (instances.size() > instanceCapacity) {
    instanceCapacity = std::max<std::size_t>(instances.size(), 2 * instanceCapacity);
    glNamedBufferData(instanceBuffer, GLsizeiptr(instanceCapacity * sizeof(InstanceMatrix)), nullptr,
                      GL_STREAM_DRAW);
  } else if (!instances.empty()) {
    glInvalidateBufferData(instanceBuffer);
  }
  if (!instances.empty())
    glNamedBufferSubData(instanceBuffer, 0, GLsizeiptr(instances.size() * sizeof(InstanceMatrix)),
                         instances.data());

  GLint prevFbo = 0;
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &prevFbo);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  glDisable(GL_BLEND);
  glFrontFace(GL_CCW);
  glCullFace(GL_BACK);

  // Shadow passes: depth only, back faces culled off so thin casters still
  // cast, slope-scaled bias against acne.
  if (!shadowLights.empty()) {
    glBindFramebuffer(GL_FRAMEBUFFER, shadowFbo);
    glViewport(0, 0, options.shadowMapSize, options.shadowMapSize);
    glDisable(GL_CULL_FACE);
    glEnable(GL_POLYGON_OFFSET_FILL);
    glPolygonOffset(options.shadowSlopeBias, 1.0f);
    glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
    depthProgram.use();
    for (const ShadowLight& s : shadowLights) {
      glNamedFramebufferTextureLayer(shadowFbo, GL_DEPTH_ATTACHMENT, shadowTex, 0, s.layer);
      const float one = 1.0f;
      glClearBufferfv(GL_DEPTH, 0, &one);
      depthProgram.set("u_viewProj", s.viewProj);
      for (const Batch& b : shadowBatches) {
        drawBatch(b);
        ++st.shadowDrawCalls;
      }
      ++st.shadowMaps;
    }
    glDisable(GL_POLYGON_OFFSET_FILL);
  }

  glBindTextureUnit(2, shadowTex);
  glPolygonMode(GL_FRONT_AND_BACK, settings.wireframe ? GL_LINE : GL_FILL);
  for (std::size_t v = 0; v < views.size(); ++v) {
    const Viewport& vp = views[v].viewport;
    target.bindViewport(vp.x, vp.y, vp.width, vp.height);
    if (settings.clear) {
      glEnable(GL_SCISSOR_TEST);
      glScissor(vp.x, target.height() - vp.y - vp.height, vp.width, vp.height);
      const float one = 1.0f;
      glClearBufferfv(GL_COLOR, 0, settings.background.data());
      glClearBufferfv(GL_DEPTH, 0, &one);
      glDisable(GL_SCISSOR_TEST);
    }
    // Every variant this view draws exists before the frame uniforms go out.
    // Per-frame flags: shadow maps, and every light directional (the
    // point/spot attenuation is compiled out: llvmpipe would run both sides
    // of the light-type branch for every fragment).
    int frameFlags = shadowLights.empty() ? 0 : kShadows;
    if (std::all_of(lights.begin(), lights.end(), [](const Light& l) { return l.type == Light::Type::Directional; }))
      frameFlags |= kDirectionalOnly;
    const int lightCount = int(lights.size());
    auto slot = [&](const Batch& b) {
      return (b.program | frameFlags | (b.count == 1 ? kSingle : 0)) * kLightCounts + lightCount;
    };
    for (const Batch& b : viewBatches[v])
      if (Status s = compileProgram(slot(b)); !s) return s.error();
    for (ShaderProgram& p : programs)
      if (p.valid()) setFrameUniforms(p, views[v].camera, viewProjs[v], lights, settings);
    int program = -1;
    std::uint32_t material = ~0u;
    for (const Batch& b : viewBatches[v]) {
      if (slot(b) != program) {
        program = slot(b);
        programs[std::size_t(program)].use();
        material = ~0u;
      }
      if (b.material != material) {
        material = b.material;
        setMaterialUniforms(programs[std::size_t(program)], materials.slots[material].material,
                            (program / kLightCounts) % kVariants);
      }
      if (b.count == 1) {  // SINGLE: the instance's matrices as uniforms
        const InstanceMatrix& m = instances[b.first];
        ShaderProgram& p = programs[std::size_t(program)];
        p.set("u_model", Mat4f(Eigen::Map<const Mat4f>(m.data())));
        Mat3f normal;
        for (int c = 0; c < 3; ++c) normal.col(c) = Eigen::Map<const Vec3f>(m.data() + 16 + 4 * c);
        p.set("u_normalMatrix", normal);
      }
      if (b.count == 1 && !meshes.slots[b.mesh].clusters.empty()) {
        st.triangles += drawClusters(b, viewProjs[v].cast<double>(), items[b.item].model, st.clustersCulled);
      } else {
        drawBatch(b);
        st.triangles += b.count * meshes.slots[b.mesh].triangles.size();
      }
      ++st.drawCalls;
      st.instances += int(b.count);
    }
  }

  // Leave the state as a plain draw expects it.
  glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
  glDisable(GL_CULL_FACE);
  glBindVertexArray(0);
  glUseProgram(0);
  for (GLuint unit = 0; unit < 3; ++unit) glBindTextureUnit(unit, 0);
  glBindFramebuffer(GL_FRAMEBUFFER, GLuint(prevFbo));
  if (Status s = gl::check("SceneRenderer::render"); !s) return s.error();
  stats = st;
  return st;
}

SceneRenderer::SceneRenderer() = default;
SceneRenderer::SceneRenderer(SceneRenderer&&) noexcept = default;
SceneRenderer& SceneRenderer::operator=(SceneRenderer&&) noexcept = default;
SceneRenderer::~SceneRenderer() = default;

Result<SceneRenderer> SceneRenderer::create(const SceneRendererOptions& options) {
  if (options.shadowMapSize < 64 || options.shadowMapSize > 8192)
    return fail(ErrorCode::InvalidArgument, formatString("shadowMapSize is %d", options.shadowMapSize),
                "SceneRendererOptions.shadowMapSize", "use 64..8192");
  if (!(options.shadowSlopeBias >= 0) || !(options.shadowNormalOffset >= 0))
    return fail(ErrorCode::InvalidArgument, "negative or NaN shadow bias", "SceneRendererOptions",
                "use shadowSlopeBias >= 0 and shadowNormalOffset >= 0");
  SceneRenderer r;
  r.impl_ = std::make_unique<Impl>();
  Impl& im = *r.impl_;
  im.options = options;
  im.normalOffset = formatString("%.6f", double(options.shadowNormalOffset));
  // The plain variant of each model now, so a driver that cannot compile
  // them fails here; the others on first use.
  for (int model = 0; model < 3; ++model)
    if (Status st = im.compileProgram(model * Impl::kVariants * Impl::kLightCounts + 1); !st)
      return st.error();
  auto depth = ShaderProgram::create("scene_shadow_depth", {{ShaderStage::Vertex, scene_glsl::kDepthVs},
                                                            {ShaderStage::Fragment, scene_glsl::kDepthFs}});
  if (!depth) return depth.error();
  im.depthProgram = std::move(*depth);

  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &im.maxTextureSize);
  if (options.shadowMapSize > im.maxTextureSize)
    return fail(ErrorCode::InvalidArgument,
                formatString("shadowMapSize %d exceeds GL_MAX_TEXTURE_SIZE %d", options.shadowMapSize,
                             im.maxTextureSize),
                "SceneRendererOptions.shadowMapSize", "use a smaller shadow map");
  glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &im.shadowTex);
  glTextureStorage3D(im.shadowTex, 1, GL_DEPTH_COMPONENT32F, options.shadowMapSize, options.shadowMapSize,
                     kMaxShadowMaps);
  glTextureParameteri(im.shadowTex, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTextureParameteri(im.shadowTex, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTextureParameteri(im.shadowTex, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTextureParameteri(im.shadowTex, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  glTextureParameteri(im.shadowTex, GL_TEXTURE_COMPARE_MODE, GL_COMPARE_REF_TO_TEXTURE);
  glTextureParameteri(im.shadowTex, GL_TEXTURE_COMPARE_FUNC, GL_LEQUAL);
  glCreateFramebuffers(1, &im.shadowFbo);
  glNamedFramebufferTextureLayer(im.shadowFbo, GL_DEPTH_ATTACHMENT, im.shadowTex, 0, 0);
  glNamedFramebufferDrawBuffer(im.shadowFbo, GL_NONE);
  glNamedFramebufferReadBuffer(im.shadowFbo, GL_NONE);
  if (glCheckNamedFramebufferStatus(im.shadowFbo, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    return fail(ErrorCode::Unsupported, "the driver refuses a depth-only shadow framebuffer",
                "SceneRenderer::create", "update Mesa or the GPU driver");
  glCreateBuffers(1, &im.instanceBuffer);
  if (Status s = gl::check("SceneRenderer::create"); !s) return s.error();
  return r;
}

Result<MeshId> SceneRenderer::addMesh(const Mesh& mesh) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  if (Status s = Impl::checkMesh(mesh); !s) return s.error();
  const MeshId id = impl_->meshes.allocate<MeshId>();
  MeshSlot& slot = impl_->meshes.slots[id.index];
  slot.uploads = slot.inPlaceUpdates = 0;
  slot.lods.clear();
  if (Status s = impl_->upload(slot, mesh); !s) {
    Impl::freeMesh(slot);
    impl_->meshes.release(id.index);
    return s.error();
  }
  return id;
}

Status SceneRenderer::updateMesh(MeshId id, const Mesh& mesh) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  MeshSlot* slot = impl_->meshes.get(id);
  if (slot == nullptr) return staleHandle("mesh", id.index, id.generation);
  if (Status s = Impl::checkMesh(mesh); !s) return s;
  if (mesh.positions.size() != slot->vertexCount || mesh.triangles != slot->triangles)
    return impl_->upload(*slot, mesh);
  impl_->buildVertices(mesh);
  glNamedBufferSubData(slot->vbo, 0, GLsizeiptr(impl_->vertices.size() * sizeof(GpuVertex)),
                       impl_->vertices.data());
  Impl::setBounds(*slot, mesh);
  Impl::setClusterBoxes(*slot, mesh.positions);
  ++slot->inPlaceUpdates;
  return gl::check("SceneRenderer::updateMesh");
}

Status SceneRenderer::setMeshTree(MeshId id, const MeshBvh& tree, std::size_t clusterTriangles) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  constexpr const char* where = "SceneRenderer::setMeshTree";
  MeshSlot* slot = impl_->meshes.get(id);
  if (slot == nullptr) return staleHandle("mesh", id.index, id.generation);
  const std::size_t n = slot->triangles.size();
  if (tree.triangleCount() != n)
    return fail(ErrorCode::InvalidArgument,
                formatString("the tree has %zu triangles, the mesh %zu", tree.triangleCount(), n), where,
                "build the tree from the mesh given to addMesh/updateMesh");
  for (std::uint32_t k = 0; k < n; ++k)
    if (tree.originalTriangle(k) >= n || tree.triangleIndices(k) != slot->triangles[tree.originalTriangle(k)])
      return fail(ErrorCode::InvalidArgument,
                  formatString("the tree's triangle %u is not the mesh's triangle %u", k, tree.originalTriangle(k)),
                  where, "build the tree from the mesh given to addMesh/updateMesh");
  if (clusterTriangles == 0)
    return fail(ErrorCode::InvalidArgument, "clusterTriangles is 0", where, "e.g. 2048 triangles per cluster");
  // Triangle range of every node reachable from the root (children have
  // larger indices, so a reverse walk of the visiting order is bottom-up).
  const auto nodes = tree.nodes();
  std::vector<std::uint32_t> order{0};
  for (std::size_t i = 0; i < order.size(); ++i)
    if (const BvhNode& nd = nodes[order[i]]; !nd.isLeaf()) order.insert(order.end(), {nd.first, nd.first + 1});
  std::vector<std::array<std::uint32_t, 2>> range(nodes.size());
  for (auto it = order.rbegin(); it != order.rend(); ++it) {
    const BvhNode& nd = nodes[*it];
    if (nd.isLeaf()) {
      range[*it] = {nd.first, nd.first + nd.count};
      continue;
    }
    const auto &l = range[nd.first], &r = range[nd.first + 1];
    if (l[1] != r[0])
      return fail(ErrorCode::Unsupported, formatString("node %u's subtrees are not contiguous in leaf order", *it),
                  where, "use a dm::MeshBvh built by MeshBvh::build");
    range[*it] = {l[0], r[1]};
  }
  // Clusters: the largest subtrees of at most clusterTriangles triangles.
  std::vector<MeshCluster> clusters;
  std::vector<std::uint32_t> stack{0};
  while (!stack.empty()) {
    const std::uint32_t i = stack.back();
    stack.pop_back();
    const BvhNode& nd = nodes[i];
    if (nd.isLeaf() || range[i][1] - range[i][0] <= clusterTriangles) {
      clusters.push_back({range[i][0], range[i][1] - range[i][0], Aabb()});
      continue;
    }
    stack.push_back(nd.first + 1);
    stack.push_back(nd.first);
  }
  std::sort(clusters.begin(), clusters.end(),
            [](const MeshCluster& a, const MeshCluster& b) { return a.first < b.first; });
  // The index buffer in leaf order (its storage is immutable: a new buffer).
  std::vector<Triangle> ordered(n);
  slot->leafOrder.resize(n);
  for (std::uint32_t k = 0; k < n; ++k) {
    slot->leafOrder[k] = tree.originalTriangle(k);
    ordered[k] = slot->triangles[slot->leafOrder[k]];
  }
  GLuint ibo = 0;
  glCreateBuffers(1, &ibo);
  glNamedBufferStorage(ibo, GLsizeiptr(n * sizeof(Triangle)), ordered.data(), 0);
  glVertexArrayElementBuffer(slot->vao, ibo);
  glDeleteBuffers(1, &slot->ibo);
  slot->ibo = ibo;
  slot->clusters = std::move(clusters);
  for (MeshCluster& c : slot->clusters) {
    c.box.setEmpty();
    for (std::uint32_t k = c.first; k < c.first + c.count; ++k)
      for (int v = 0; v < 3; ++v) c.box.extend(tree.corners(k)[v]);
  }
  return gl::check(where);
}

Status SceneRenderer::removeMesh(MeshId id) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  MeshSlot* slot = impl_->meshes.get(id);
  if (slot == nullptr) return staleHandle("mesh", id.index, id.generation);
  Impl::freeMesh(*slot);
  slot->triangles = {};
  slot->lods.clear();
  impl_->meshes.release(id.index);
  return ok();
}

Result<MeshInfo> SceneRenderer::meshInfo(MeshId id) const {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  const MeshSlot* slot = impl_->meshes.get(id);
  if (slot == nullptr) return staleHandle("mesh", id.index, id.generation);
  MeshInfo info;
  info.vertexCount = slot->vertexCount;
  info.triangleCount = slot->triangles.size();
  info.bounds = slot->bounds;
  info.uploads = slot->uploads;
  info.inPlaceUpdates = slot->inPlaceUpdates;
  info.clusters = slot->clusters.size();
  info.vertexBuffer = slot->vbo;
  return info;
}

Status SceneRenderer::setLods(MeshId base, std::vector<LodLevel> levels) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  MeshSlot* slot = impl_->meshes.get(base);
  if (slot == nullptr) return staleHandle("mesh", base.index, base.generation);
  for (std::size_t i = 0; i < levels.size(); ++i) {
    if (impl_->meshes.get(levels[i].mesh) == nullptr || levels[i].mesh == base)
      return fail(ErrorCode::InvalidArgument, "LOD mesh id is stale or the base mesh itself",
                  formatString("levels[%zu].mesh", i), "register the coarser mesh with addMesh() first");
    if (!(levels[i].maxScreenFraction > 0) || !std::isfinite(levels[i].maxScreenFraction))
      return fail(
          ErrorCode::InvalidArgument, formatString("maxScreenFraction is %g", levels[i].maxScreenFraction),
          formatString("levels[%zu].maxScreenFraction", i), "use a positive fraction of the viewport height");
  }
  std::sort(levels.begin(), levels.end(),
            [](const LodLevel& a, const LodLevel& b) { return a.maxScreenFraction > b.maxScreenFraction; });
  slot->lods = std::move(levels);
  return ok();
}

namespace {

// Checks that `image` can become a texture of at most `maxSize` pixels a side.
Status checkTextureImage(const Image& image, int maxSize, const char* where) {
  if (image.empty()) return fail(ErrorCode::InvalidArgument, "image is empty", where, "give a loaded image");
  if (image.type() != PixelType::U8 || image.channels() == 2)
    return fail(ErrorCode::Unsupported,
                formatString("%s image with %d channels", toString(image.type()), image.channels()), where,
                "convert to 8-bit gray, RGB or RGBA");
  if (image.width() > maxSize || image.height() > maxSize)
    return fail(ErrorCode::InvalidArgument,
                formatString("%dx%d image exceeds GL_MAX_TEXTURE_SIZE %d", image.width(), image.height(), maxSize),
                where, "downscale the image");
  return ok();
}

// Writes `image` into level 0 of `texture` (storage of the same size and
// channel count) and regenerates the mipmaps when `mipmaps`.
void writeTexturePixels(GLuint texture, const Image& image, bool mipmaps) {
  const GLenum format = image.channels() == 1 ? GL_RED : image.channels() == 3 ? GL_RGB : GL_RGBA;
  // Rows whose stride is not a whole number of pixels cannot be described by
  // GL_UNPACK_ROW_LENGTH: those (rare, wrapped foreign memory) are packed first.
  Image packed;
  const Image* src = &image;
  if (image.strideBytes() % image.pixelBytes() != 0) {
    packed = image.clone();
    src = &packed;
  }
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, GLint(src->strideBytes() / src->pixelBytes()));
  glTextureSubImage2D(texture, 0, 0, 0, image.width(), image.height(), format, GL_UNSIGNED_BYTE, src->data());
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  if (mipmaps) glGenerateTextureMipmap(texture);
}

// A new GL texture holding `image` as `options` say; 0 and an error when GL refuses.
Result<GLuint> createTexture(const Image& image, const SceneTextureOptions& options, const char* where) {
  const bool srgb = options.srgb;
  const GLenum internal = image.channels() == 1   ? (srgb ? GL_SRGB8 : GL_R8)
                          : image.channels() == 3 ? (srgb ? GL_SRGB8 : GL_RGB8)
                                                  : (srgb ? GL_SRGB8_ALPHA8 : GL_RGBA8);
  const int levels =
      options.mipmaps ? 1 + static_cast<int>(std::floor(std::log2(std::max(image.width(), image.height())))) : 1;
  GLuint texture = 0;
  glCreateTextures(GL_TEXTURE_2D, 1, &texture);
  glTextureStorage2D(texture, levels, internal, image.width(), image.height());
  if (image.channels() == 1) {
    const GLint swizzle[4] = {GL_RED, GL_RED, GL_RED, GL_ONE};
    glTextureParameteriv(texture, GL_TEXTURE_SWIZZLE_RGBA, swizzle);
  } else if (options.bgr) {
    // The bytes go up as they are; sampling swaps red and blue.
    const GLint swizzle[4] = {GL_BLUE, GL_GREEN, GL_RED, image.channels() == 4 ? GL_ALPHA : GL_ONE};
    glTextureParameteriv(texture, GL_TEXTURE_SWIZZLE_RGBA, swizzle);
  }
  writeTexturePixels(texture, image, options.mipmaps);
  glTextureParameteri(texture, GL_TEXTURE_MIN_FILTER, options.mipmaps ? GL_LINEAR_MIPMAP_LINEAR : GL_LINEAR);
  glTextureParameteri(texture, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTextureParameteri(texture, GL_TEXTURE_WRAP_S, GL_REPEAT);
  glTextureParameteri(texture, GL_TEXTURE_WRAP_T, GL_REPEAT);
  if (Status s = gl::check(where); !s) {
    glDeleteTextures(1, &texture);
    return s.error();
  }
  return texture;
}

}  // namespace

Result<TextureId> SceneRenderer::addTexture(const Image& image, bool srgb) {
  return addTexture(image, SceneTextureOptions{.srgb = srgb});
}

Result<TextureId> SceneRenderer::addTexture(const Image& image, const SceneTextureOptions& options) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  constexpr const char* kWhere = "SceneRenderer::addTexture";
  if (Status s = checkTextureImage(image, impl_->maxTextureSize, kWhere); !s) return s.error();
  auto texture = createTexture(image, options, kWhere);
  if (!texture) return texture.error();
  const TextureId id = impl_->textures.allocate<TextureId>();
  TextureSlot& slot = impl_->textures.slots[id.index];
  slot.texture = *texture;
  slot.width = image.width();
  slot.height = image.height();
  slot.channels = image.channels();
  slot.options = options;
  return id;
}

Status SceneRenderer::updateTexture(TextureId id, const Image& image) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  constexpr const char* kWhere = "SceneRenderer::updateTexture";
  TextureSlot* slot = impl_->textures.get(id);
  if (slot == nullptr) return staleHandle("texture", id.index, id.generation);
  if (Status s = checkTextureImage(image, impl_->maxTextureSize, kWhere); !s) return s;
  if (image.width() == slot->width && image.height() == slot->height && image.channels() == slot->channels) {
    writeTexturePixels(slot->texture, image, slot->options.mipmaps);
    return gl::check(kWhere);
  }
  auto texture = createTexture(image, slot->options, kWhere);
  if (!texture) return texture.error();
  glDeleteTextures(1, &slot->texture);
  slot->texture = *texture;
  slot->width = image.width();
  slot->height = image.height();
  slot->channels = image.channels();
  return ok();
}

Status SceneRenderer::removeTexture(TextureId id) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  TextureSlot* slot = impl_->textures.get(id);
  if (slot == nullptr) return staleHandle("texture", id.index, id.generation);
  glDeleteTextures(1, &slot->texture);
  slot->texture = 0;
  impl_->textures.release(id.index);
  return ok();
}

Result<MaterialId> SceneRenderer::addMaterial(const Material& material) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  if (Status s = validateMaterial(material); !s) return s.error();
  for (const TextureId t : {material.colorTexture, material.normalTexture, material.heightTexture})
    if (t.valid() && impl_->textures.get(t) == nullptr) return staleHandle("texture", t.index, t.generation);
  const MaterialId id = impl_->materials.allocate<MaterialId>();
  impl_->materials.slots[id.index].material = material;
  return id;
}

Status SceneRenderer::setMaterial(MaterialId id, const Material& material) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  MaterialSlot* slot = impl_->materials.get(id);
  if (slot == nullptr) return staleHandle("material", id.index, id.generation);
  if (Status s = validateMaterial(material); !s) return s;
  for (const TextureId t : {material.colorTexture, material.normalTexture, material.heightTexture})
    if (t.valid() && impl_->textures.get(t) == nullptr) return staleHandle("texture", t.index, t.generation);
  slot->material = material;
  return ok();
}

Status SceneRenderer::removeMaterial(MaterialId id) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  if (impl_->materials.get(id) == nullptr) return staleHandle("material", id.index, id.generation);
  impl_->materials.release(id.index);
  return ok();
}

Result<RenderStats> SceneRenderer::render(const RenderTarget& target, const Camera& camera,
                                          std::span<const DrawItem> items, std::span<const Light> lights,
                                          const RenderSettings& settings) {
  return render(target, Viewport{0, 0, target.width(), target.height()}, camera, items, lights, settings);
}

Result<RenderStats> SceneRenderer::render(const RenderTarget& target, const Viewport& viewport,
                                          const Camera& camera, std::span<const DrawItem> items,
                                          std::span<const Light> lights, const RenderSettings& settings) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  const Impl::View view{viewport, camera};
  return impl_->renderViews(target, {&view, 1}, items, lights, settings);
}

Result<RenderStats> SceneRenderer::renderStereo(const RenderTarget& target, const Camera& camera,
                                                double eyeSeparation, double convergence,
                                                std::span<const DrawItem> items,
                                                std::span<const Light> lights,
                                                const RenderSettings& settings) {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  if (camera.projection != Camera::Projection::Perspective || !(eyeSeparation > 0) || !(convergence > 0) ||
      !std::isfinite(eyeSeparation) || !std::isfinite(convergence))
    return fail(ErrorCode::InvalidArgument,
                formatString("eye separation %g m, convergence %g m", eyeSeparation, convergence),
                "SceneRenderer::renderStereo", "use a perspective camera and positive distances");
  if (target.width() < 2)
    return fail(ErrorCode::InvalidArgument, "target narrower than 2 pixels", "SceneRenderer::renderStereo");
  const auto [left, right] = camera.stereoPair(eyeSeparation, convergence);
  const int half = target.width() / 2;
  const Impl::View views[2] = {{Viewport{0, 0, half, target.height()}, left},
                               {Viewport{half, 0, half, target.height()}, right}};
  return impl_->renderViews(target, views, items, lights, settings);
}

const RenderStats& SceneRenderer::lastStats() const {
  DM_DEMAND(impl_ != nullptr, "SceneRenderer used after move or default construction");
  return impl_->stats;
}

}  // namespace dm
