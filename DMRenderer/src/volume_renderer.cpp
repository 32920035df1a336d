// volume_renderer.cpp — 3-D texture upload with value normalisation and
// macro-cell min/max, transfer-function tables and cell activity, the ray
// casting, slice and voxel draws.
#include <dm/renderer/shader.hpp>
#include <dm/renderer/volume_renderer.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "gl.hpp"
#include "volume_shaders.hpp"

namespace dm {

namespace {

constexpr int kTfSize = 1024;                           // transfer function table entries
constexpr std::uint32_t kMaxVoxelInstances = 1u << 22;  // Voxels mode: 32 MiB of instances

struct GpuVolume {
  std::uint32_t generation = 0;
  bool alive = false;
  Vec3i dims = Vec3i::Zero();
  Affine3 indexToWorld = Affine3::Identity();
  double lo = 0, hi = 1;
  bool floatTex = false;
  int cellSize = 8;
  Vec3i cellGrid = Vec3i::Zero();
  std::vector<float> cellMin, cellMax;  // normalised, cell-major (x fastest)
  std::size_t activeCells = 0;
  double unitLength = 1e-3;  // m, of the current transfer function's opacity
  GLuint volumeTex = 0, tfTex = 0, cellTex = 0, minMaxTex = 0;
  GLuint instBuffer = 0;
  std::uint32_t instCapacity = 0, instCount = 0;
  double instThreshold = std::numeric_limits<double>::quiet_NaN();

  void release() {
    for (GLuint* t : {&volumeTex, &tfTex, &cellTex, &minMaxTex}) {
      if (*t != 0) glDeleteTextures(1, t);
      *t = 0;
    }
    if (instBuffer != 0) glDeleteBuffers(1, &instBuffer);
    instBuffer = 0;
    instCapacity = instCount = 0;
    instThreshold = std::numeric_limits<double>::quiet_NaN();
    cellMin.clear();
    cellMax.clear();
    alive = false;
  }
};

Mat4f toMat4f(const Affine3& a) { return a.matrix().cast<float>(); }

// World bounds of the volume box [-0.5, dims - 0.5] (voxel edges, not centres).
Aabb boxBounds(const GpuVolume& g) {
  Aabb box;
  for (int c = 0; c < 8; ++c)
    box.extend(g.indexToWorld * Vec3((c & 1) ? g.dims.x() - 0.5 : -0.5, (c & 2) ? g.dims.y() - 0.5 : -0.5,
                                     (c & 4) ? g.dims.z() - 0.5 : -0.5));
  return box;
}

// Cells whose apron [c·cs − 1, c·cs + cs] contains voxel i along one axis.
void cellsOfVoxel(int i, int cs, int grid, int& c0, int& c1) {
  c0 = i >= cs ? (i - 1) / cs : 0;
  c1 = std::min(grid - 1, (i + 1) / cs);
}

// Converts one z-slab to normalised texels and folds its values into the
// cell min/max. T is the voxel type; Out is std::uint16_t (R16) or float.
template <class T, class Out>
void convertSlice(const T* src, int k, GpuVolume& g, double lo, double scale, std::vector<Out>& out,
                  std::vector<float>& rowMin, std::vector<float>& rowMax) {
  const int nx = g.dims.x(), ny = g.dims.y(), cs = g.cellSize;
  const Vec3i& grid = g.cellGrid;
  int cz0 = 0, cz1 = 0;
  cellsOfVoxel(k, cs, grid.z(), cz0, cz1);
  for (int j = 0; j < ny; ++j) {
    std::fill(rowMin.begin(), rowMin.end(), 2.0f);
    std::fill(rowMax.begin(), rowMax.end(), -1.0f);
    const T* row = src + static_cast<std::size_t>(j) * static_cast<std::size_t>(nx);
    Out* dst = out.data() + static_cast<std::size_t>(j) * static_cast<std::size_t>(nx);
    for (int i = 0; i < nx; ++i) {
      const double u = std::clamp((static_cast<double>(row[i]) - lo) * scale, 0.0, 1.0);
      float stored = 0;
      if constexpr (std::is_same_v<Out, std::uint16_t>) {
        dst[i] = static_cast<std::uint16_t>(std::lround(u * 65535.0));
        stored = static_cast<float>(dst[i]) / 65535.0f;
      } else {
        dst[i] = static_cast<float>(u);
        stored = dst[i];
      }
      int cx0 = 0, cx1 = 0;
      cellsOfVoxel(i, cs, grid.x(), cx0, cx1);
      for (int c = cx0; c <= cx1; ++c) {
        rowMin[static_cast<std::size_t>(c)] = std::min(rowMin[static_cast<std::size_t>(c)], stored);
        rowMax[static_cast<std::size_t>(c)] = std::max(rowMax[static_cast<std::size_t>(c)], stored);
      }
    }
    int cy0 = 0, cy1 = 0;
    cellsOfVoxel(j, cs, grid.y(), cy0, cy1);
    for (int cz = cz0; cz <= cz1; ++cz)
      for (int cy = cy0; cy <= cy1; ++cy) {
        const std::size_t base = static_cast<std::size_t>(grid.x()) *
                                 (static_cast<std::size_t>(cy) + static_cast<std::size_t>(grid.y()) * cz);
        for (int cx = 0; cx < grid.x(); ++cx) {
          const std::size_t c = base + static_cast<std::size_t>(cx);
          g.cellMin[c] = std::min(g.cellMin[c], rowMin[static_cast<std::size_t>(cx)]);
          g.cellMax[c] = std::max(g.cellMax[c], rowMax[static_cast<std::size_t>(cx)]);
        }
      }
  }
}

template <class T>
void uploadTyped(const Volume& v, GpuVolume& g) {
  const T* data = v.data<T>();
  const double scale = 1.0 / (g.hi - g.lo);
  const std::size_t slice = static_cast<std::size_t>(g.dims.x()) * static_cast<std::size_t>(g.dims.y());
  std::vector<float> rowMin(static_cast<std::size_t>(g.cellGrid.x())),
      rowMax(static_cast<std::size_t>(g.cellGrid.x()));
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  if (!g.floatTex) {
    std::vector<std::uint16_t> buf(slice);
    for (int k = 0; k < g.dims.z(); ++k) {
      convertSlice(data + slice * static_cast<std::size_t>(k), k, g, g.lo, scale, buf, rowMin, rowMax);
      glTextureSubImage3D(g.volumeTex, 0, 0, 0, k, g.dims.x(), g.dims.y(), 1, GL_RED, GL_UNSIGNED_SHORT,
                          buf.data());
    }
  } else {
    std::vector<float> buf(slice);
    for (int k = 0; k < g.dims.z(); ++k) {
      convertSlice(data + slice * static_cast<std::size_t>(k), k, g, g.lo, scale, buf, rowMin, rowMax);
      glTextureSubImage3D(g.volumeTex, 0, 0, 0, k, g.dims.x(), g.dims.y(), 1, GL_RED, GL_FLOAT, buf.data());
    }
  }
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);  // back to GL's default
}

GLuint makeTexture3D(GLenum internalFormat, const Vec3i& dims, GLint filter) {
  GLuint t = 0;
  glCreateTextures(GL_TEXTURE_3D, 1, &t);
  glTextureStorage3D(t, 1, internalFormat, dims.x(), dims.y(), dims.z());
  glTextureParameteri(t, GL_TEXTURE_MIN_FILTER, filter);
  glTextureParameteri(t, GL_TEXTURE_MAG_FILTER, filter);
  for (GLenum w : {GL_TEXTURE_WRAP_S, GL_TEXTURE_WRAP_T, GL_TEXTURE_WRAP_R})
    glTextureParameteri(t, w, GL_CLAMP_TO_EDGE);
  return t;
}

// Normalised window of the settings (NaN bounds = the whole range).
Vec2f normalisedWindow(const VolumeRenderSettings& s, const GpuVolume& g) {
  const double lo = std::isnan(s.windowLow) ? g.lo : s.windowLow;
  const double hi = std::isnan(s.windowHigh) ? g.hi : s.windowHigh;
  const double w = g.hi - g.lo;
  return Vec2f(static_cast<float>((lo - g.lo) / w), static_cast<float>((hi - g.lo) / w));
}

}  // namespace

struct VolumeRenderer::Impl {
  ShaderProgram ray[3];  // composite, MIP, iso
  ShaderProgram slice, voxelCompute, voxel;
  GLuint vao = 0, statsBuffer = 0, countBuffer = 0;
  GLuint depthCopy = 0;
  int depthW = 0, depthH = 0;
  int max3d = 0;
  std::vector<GpuVolume> volumes;

  ~Impl() {
    for (GpuVolume& g : volumes) g.release();
    if (vao != 0) glDeleteVertexArrays(1, &vao);
    if (statsBuffer != 0) glDeleteBuffers(1, &statsBuffer);
    if (countBuffer != 0) glDeleteBuffers(1, &countBuffer);
    if (depthCopy != 0) glDeleteTextures(1, &depthCopy);
  }

  Result<GpuVolume*> find(VolumeId id, const char* where) {
    if (id.index < volumes.size() && volumes[id.index].alive &&
        volumes[id.index].generation == id.generation && id.generation != 0)
      return &volumes[id.index];
    return fail(ErrorCode::NotFound, formatString("volume id %u/%u is not live", id.index, id.generation),
                where, "use an id returned by addVolume() and not removed since");
  }

  // Copies the target's resolved depth so the ray caster can read it while
  // drawing into the same target (no feedback loop at 1 sample).
  void copyDepth(const RenderTarget& target) {
    if (depthCopy == 0 || depthW != target.width() || depthH != target.height()) {
      if (depthCopy != 0) glDeleteTextures(1, &depthCopy);
      glCreateTextures(GL_TEXTURE_2D, 1, &depthCopy);
      glTextureStorage2D(depthCopy, 1, GL_DEPTH_COMPONENT32F, target.width(), target.height());
      glTextureParameteri(depthCopy, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
      glTextureParameteri(depthCopy, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
      depthW = target.width();
      depthH = target.height();
    }
    target.resolve();
    glCopyImageSubData(target.depthTexture(), GL_TEXTURE_2D, 0, 0, 0, 0, depthCopy, GL_TEXTURE_2D, 0, 0, 0, 0,
                       depthW, depthH, 1);
  }
};

VolumeRenderer::VolumeRenderer() = default;
VolumeRenderer::VolumeRenderer(VolumeRenderer&&) noexcept = default;
VolumeRenderer& VolumeRenderer::operator=(VolumeRenderer&&) noexcept = default;
VolumeRenderer::~VolumeRenderer() = default;

Result<VolumeRenderer> VolumeRenderer::create() {
  GLint max3d = 0;
  glGetIntegerv(GL_MAX_3D_TEXTURE_SIZE, &max3d);
  if (max3d <= 0)
    return fail(ErrorCode::InvalidArgument, "no OpenGL context is current", "VolumeRenderer::create",
                "create a dm::GlContext on this thread first");
  VolumeRenderer r;
  r.impl_ = std::make_unique<Impl>();
  Impl& m = *r.impl_;
  m.max3d = max3d;
  const std::string boxVs = std::string(volume_shaders::kCube) + volume_shaders::kBoxVs;
  const std::string voxelVs = std::string(volume_shaders::kCube) + volume_shaders::kVoxelVs;
  static constexpr const char* kRayNames[3] = {"volume composite", "volume mip", "volume iso"};
  for (int mode = 0; mode < 3; ++mode) {
    auto p = ShaderProgram::create(
        kRayNames[mode], {{ShaderStage::Vertex, boxVs}, {ShaderStage::Fragment, volume_shaders::kRayFs}},
        {{"MODE", std::to_string(mode)}});
    if (!p) return p.error();
    m.ray[mode] = std::move(*p);
  }
  auto slice = ShaderProgram::create("volume slice", {{ShaderStage::Vertex, volume_shaders::kSliceVs},
                                                      {ShaderStage::Fragment, volume_shaders::kSliceFs}});
  if (!slice) return slice.error();
  m.slice = std::move(*slice);
  auto cs = ShaderProgram::create("volume voxel select", {{ShaderStage::Compute, volume_shaders::kVoxelCs}});
  if (!cs) return cs.error();
  m.voxelCompute = std::move(*cs);
  auto vox = ShaderProgram::create(
      "volume voxels", {{ShaderStage::Vertex, voxelVs}, {ShaderStage::Fragment, volume_shaders::kVoxelFs}});
  if (!vox) return vox.error();
  m.voxel = std::move(*vox);
  glCreateVertexArrays(1, &m.vao);
  glCreateBuffers(1, &m.statsBuffer);
  glNamedBufferStorage(m.statsBuffer, 4 * sizeof(GLuint), nullptr, GL_DYNAMIC_STORAGE_BIT);
  glCreateBuffers(1, &m.countBuffer);
  glNamedBufferStorage(m.countBuffer, sizeof(GLuint), nullptr, GL_DYNAMIC_STORAGE_BIT);
  if (auto s = gl::check("VolumeRenderer::create"); !s) return s.error();
  return r;
}

Result<VolumeId> VolumeRenderer::addVolume(const Volume& volume, const VolumeUploadOptions& options) {
  const char* where = "VolumeRenderer::addVolume";
  DM_DEMAND(impl_ != nullptr, "VolumeRenderer used after move");
  if (volume.empty())
    return fail(ErrorCode::InvalidArgument, "empty volume", where, "load or create the volume first");
  if (options.cellSize < 2 || options.cellSize > 64)
    return fail(ErrorCode::InvalidArgument, formatString("cellSize is %d", options.cellSize),
                "VolumeUploadOptions::cellSize", "use 2..64 voxels (8 is typical)");
  const Vec3i dims = volume.dims();
  for (int a = 0; a < 3; ++a)
    if (dims[a] > impl_->max3d)
      return fail(ErrorCode::InvalidArgument,
                  formatString("dims[%d] is %d voxels, above this GPU's GL_MAX_3D_TEXTURE_SIZE %d", a,
                               dims[a], impl_->max3d),
                  where, "crop or downsample the volume (e.g. dmtool convert) before rendering it");
  auto [lo, hi] = volume.range();
  if (!std::isfinite(lo) || !std::isfinite(hi))
    return fail(ErrorCode::InvalidArgument, formatString("value range [%g, %g] is not finite", lo, hi), where,
                "replace NaN/Inf voxels before rendering");
  if (!(hi > lo)) hi = lo + 1;  // a constant volume: any range maps it to 0

  GpuVolume g;
  g.dims = dims;
  g.indexToWorld = volume.indexToWorld();
  g.lo = lo;
  g.hi = hi;
  const VoxelType t = volume.type();
  g.floatTex = !(t == VoxelType::U8 || t == VoxelType::I8 || t == VoxelType::U16 || t == VoxelType::I16);
  g.cellSize = options.cellSize;
  for (int a = 0; a < 3; ++a) g.cellGrid[a] = (dims[a] + g.cellSize - 1) / g.cellSize;
  const std::size_t cells = static_cast<std::size_t>(g.cellGrid.x()) *
                            static_cast<std::size_t>(g.cellGrid.y()) *
                            static_cast<std::size_t>(g.cellGrid.z());
  g.cellMin.assign(cells, 2.0f);
  g.cellMax.assign(cells, -1.0f);
  g.volumeTex = makeTexture3D(g.floatTex ? GL_R32F : GL_R16, dims, GL_LINEAR);
  switch (t) {
    case VoxelType::U8:
      uploadTyped<std::uint8_t>(volume, g);
      break;
    case VoxelType::I8:
      uploadTyped<std::int8_t>(volume, g);
      break;
    case VoxelType::U16:
      uploadTyped<std::uint16_t>(volume, g);
      break;
    case VoxelType::I16:
      uploadTyped<std::int16_t>(volume, g);
      break;
    case VoxelType::U32:
      uploadTyped<std::uint32_t>(volume, g);
      break;
    case VoxelType::I32:
      uploadTyped<std::int32_t>(volume, g);
      break;
    case VoxelType::F32:
      uploadTyped<float>(volume, g);
      break;
    case VoxelType::F64:
      uploadTyped<double>(volume, g);
      break;
  }
  g.minMaxTex = makeTexture3D(GL_RG32F, g.cellGrid, GL_NEAREST);
  std::vector<float> mm(2 * cells);
  for (std::size_t c = 0; c < cells; ++c) {
    mm[2 * c] = g.cellMin[c];
    mm[2 * c + 1] = g.cellMax[c];
  }
  glTextureSubImage3D(g.minMaxTex, 0, 0, 0, 0, g.cellGrid.x(), g.cellGrid.y(), g.cellGrid.z(), GL_RG,
                      GL_FLOAT, mm.data());
  g.cellTex = makeTexture3D(GL_R8, g.cellGrid, GL_NEAREST);
  glCreateTextures(GL_TEXTURE_1D, 1, &g.tfTex);
  glTextureStorage1D(g.tfTex, 1, GL_RGBA32F, kTfSize);
  glTextureParameteri(g.tfTex, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTextureParameteri(g.tfTex, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTextureParameteri(g.tfTex, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  if (auto s = gl::check(where); !s) {
    g.release();
    return s.error();
  }
  g.alive = true;
  // Reuse a free slot, bumping its generation so stale ids stay invalid.
  std::size_t slot = impl_->volumes.size();
  for (std::size_t i = 0; i < impl_->volumes.size(); ++i)
    if (!impl_->volumes[i].alive) {
      slot = i;
      break;
    }
  if (slot == impl_->volumes.size()) impl_->volumes.emplace_back();
  g.generation = impl_->volumes[slot].generation + 1;
  impl_->volumes[slot] = std::move(g);
  const VolumeId id{static_cast<std::uint32_t>(slot), impl_->volumes[slot].generation};
  auto tf = TransferFunction::greyRamp(lo, hi);
  if (!tf) return tf.error();
  if (auto s = setTransferFunction(id, *tf); !s) return s.error();
  return id;
}

Status VolumeRenderer::removeVolume(VolumeId id) {
  DM_DEMAND(impl_ != nullptr, "VolumeRenderer used after move");
  auto g = impl_->find(id, "VolumeRenderer::removeVolume");
  if (!g) return g.error();
  (*g)->release();
  return ok();
}

Status VolumeRenderer::setTransferFunction(VolumeId id, const TransferFunction& tf) {
  const char* where = "VolumeRenderer::setTransferFunction";
  DM_DEMAND(impl_ != nullptr, "VolumeRenderer used after move");
  auto found = impl_->find(id, where);
  if (!found) return found.error();
  GpuVolume& g = **found;
  auto table = tf.bake(kTfSize, g.lo, g.hi);
  if (!table) return table.error();
  glTextureSubImage1D(g.tfTex, 0, 0, kTfSize, GL_RGBA, GL_FLOAT, table->data());
  // A cell is active when any table entry its value interval can reach
  // (with the neighbours linear filtering blends in) has opacity.
  const std::size_t cells = g.cellMin.size();
  std::vector<std::uint8_t> active(cells, 0);
  g.activeCells = 0;
  for (std::size_t c = 0; c < cells; ++c) {
    if (g.cellMax[c] < g.cellMin[c]) continue;  // no voxels (cannot happen with ceil-sized grids)
    const int i0 = std::max(0, static_cast<int>(std::floor(g.cellMin[c] * (kTfSize - 1))) - 1);
    const int i1 = std::min(kTfSize - 1, static_cast<int>(std::ceil(g.cellMax[c] * (kTfSize - 1))) + 1);
    for (int i = i0; i <= i1; ++i)
      if ((*table)[static_cast<std::size_t>(i)].w() > 0.0f) {
        active[c] = 255;
        ++g.activeCells;
        break;
      }
  }
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glTextureSubImage3D(g.cellTex, 0, 0, 0, 0, g.cellGrid.x(), g.cellGrid.y(), g.cellGrid.z(), GL_RED,
                      GL_UNSIGNED_BYTE, active.data());
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);  // back to GL's default
  g.unitLength = tf.opacityUnitLength();
  return gl::check(where);
}

Result<VolumeGpuInfo> VolumeRenderer::info(VolumeId id) const {
  DM_DEMAND(impl_ != nullptr, "VolumeRenderer used after move");
  auto found = impl_->find(id, "VolumeRenderer::info");
  if (!found) return found.error();
  const GpuVolume& g = **found;
  return VolumeGpuInfo{.dims = g.dims,
                       .valueLow = g.lo,
                       .valueHigh = g.hi,
                       .floatTexture = g.floatTex,
                       .cellGrid = g.cellGrid,
                       .cellSize = g.cellSize,
                       .activeCells = g.activeCells};
}

namespace {

Status checkSettings(const VolumeRenderSettings& s, const RenderTarget& target) {
  const char* where = "VolumeRenderSettings";
  auto bad = [&](const char* field, double v, const char* hint) {
    return fail(ErrorCode::InvalidArgument, formatString("%s is %g", field, v),
                std::string(where) + "::" + field, hint);
  };
  if (!target.valid())
    return fail(ErrorCode::InvalidArgument, "empty render target", "VolumeRenderer::render",
                "create the target with RenderTarget::create()");
  if (!(s.stepVoxels >= 0.05 && s.stepVoxels <= 8))
    return bad("stepVoxels", s.stepVoxels, "use 0.05..8 voxels");
  if (!(s.terminationAlpha > 0 && s.terminationAlpha <= 1))
    return bad("terminationAlpha", s.terminationAlpha, "use (0, 1]");
  if (!(s.depthAlpha > 0 && s.depthAlpha <= 1)) return bad("depthAlpha", s.depthAlpha, "use (0, 1]");
  if (!std::isfinite(s.isoValue)) return bad("isoValue", s.isoValue, "use a finite value");
  if (!std::isfinite(s.voxelThreshold)) return bad("voxelThreshold", s.voxelThreshold, "use a finite value");
  if (!s.lightDirection.allFinite())
    return bad("lightDirection", s.lightDirection.norm(), "use a finite vector");
  if (!s.slicePosition.allFinite()) return bad("slicePosition", s.slicePosition.norm(), "use a finite point");
  if (!(s.shininess >= 1 && s.shininess <= 1024)) return bad("shininess", s.shininess, "use 1..1024");
  const Viewport& v = s.viewport;
  const bool whole = v.width == 0 || v.height == 0;
  if (!whole && (v.x < 0 || v.y < 0 || v.width < 0 || v.height < 0 || v.x + v.width > target.width() ||
                 v.y + v.height > target.height()))
    return fail(ErrorCode::InvalidArgument,
                formatString("viewport %d,%d %dx%d outside the %dx%d target", v.x, v.y, v.width, v.height,
                             target.width(), target.height()),
                "VolumeRenderSettings::viewport",
                "use a rectangle inside the target, or width 0 for all of it");
  return ok();
}

}  // namespace

Status VolumeRenderer::render(const RenderTarget& target, const Camera& camera, VolumeId id,
                              const VolumeRenderSettings& settings) {
  const char* where = "VolumeRenderer::render";
  DM_DEMAND(impl_ != nullptr, "VolumeRenderer used after move");
  Impl& m = *impl_;
  auto found = m.find(id, where);
  if (!found) return found.error();
  GpuVolume& g = **found;
  if (auto s = camera.validate(); !s) return s.error().within(where);
  if (auto s = checkSettings(settings, target); !s) return s.error();
  Viewport vp = settings.viewport;
  if (vp.width == 0 || vp.height == 0) vp = Viewport{0, 0, target.width(), target.height()};

  const Mat4f viewProj = camera.projectionMatrix(double(vp.width) / double(vp.height)) * camera.viewMatrix();
  const Mat4f invViewProj = viewProj.cast<double>().inverse().cast<float>();
  const Mat4f indexToWorld = toMat4f(g.indexToWorld);
  const Mat4f worldToIndex = toMat4f(g.indexToWorld.inverse());
  const Mat3f gradToWorld = g.indexToWorld.linear().inverse().transpose().cast<float>();
  const Vec3f dimsF = g.dims.cast<float>();
  const Vec3 light = settings.lightDirection.squaredNorm() > 0 ? settings.lightDirection.normalized()
                                                               : Vec3(-camera.forward());
  const Vec4f material(float(settings.ambient), float(settings.diffuse), float(settings.specular),
                       float(settings.shininess));
  const Vec2f window = normalisedWindow(settings, g);
  const Vec2f tfMap(float(kTfSize - 1) / kTfSize, 0.5f / kTfSize);
  const bool mirrored = g.indexToWorld.linear().determinant() < 0;
  const VolumeRenderMode mode = settings.mode;
  const bool rayMode =
      mode == VolumeRenderMode::Composite || mode == VolumeRenderMode::Mip || mode == VolumeRenderMode::Iso;

  if (rayMode) m.copyDepth(target);
  target.bindViewport(vp.x, vp.y, vp.width, vp.height);
  gl::StateGuard guard;
  glBindVertexArray(m.vao);
  glBindTextureUnit(0, g.volumeTex);
  glBindTextureUnit(1, g.tfTex);
  glBindTextureUnit(2, g.cellTex);
  glBindTextureUnit(3, g.minMaxTex);
  glBindTextureUnit(4, m.depthCopy);
  glFrontFace(mirrored ? GL_CW : GL_CCW);

  if (rayMode) {
    const int modeIndex = mode == VolumeRenderMode::Composite ? 0 : mode == VolumeRenderMode::Mip ? 1 : 2;
    ShaderProgram& p = m.ray[modeIndex];
    p.use();
    p.set("u_viewProj", viewProj);
    p.set("u_invViewProj", invViewProj);
    p.set("u_indexToWorld", indexToWorld);
    p.set("u_worldToIndex", worldToIndex);
    p.set("u_gradToWorld", gradToWorld);
    p.set("u_dims", dimsF);
    p.set("u_viewport",
          Vec4f(float(vp.x), float(target.height() - vp.y - vp.height), float(vp.width), float(vp.height)));
    p.set("u_volume", 0);
    p.set("u_tf", 1);
    p.set("u_cells", 2);
    p.set("u_cellMinMax", 3);
    p.set("u_sceneDepth", 4);
    p.set("u_cellSize", float(g.cellSize));
    glProgramUniform3i(p.id(), p.location("u_cellGrid"), g.cellGrid.x(), g.cellGrid.y(), g.cellGrid.z());
    p.set("u_step", float(settings.stepVoxels));
    p.set("u_unitLength", float(g.unitLength));
    p.set("u_tfMap", tfMap);
    p.set("u_skip", settings.emptySpaceSkipping ? 1 : 0);
    p.set("u_stats", settings.collectStats ? 1 : 0);
    p.set("u_shading", settings.shading ? 1 : 0);
    p.set("u_writeDepth", settings.writeDepth ? 1 : 0);
    p.set("u_termAlpha", float(settings.terminationAlpha));
    p.set("u_depthAlpha", float(settings.depthAlpha));
    p.set("u_lightDir", light.cast<float>().eval());
    p.set("u_material", material);
    p.set("u_window", window);
    p.set("u_iso", float((settings.isoValue - g.lo) / (g.hi - g.lo)));
    p.set("u_isoColor", settings.isoColor.cast<float>().eval());
    if (settings.collectStats) {
      const GLuint zero[4] = {0, 0, 0, 0};
      glNamedBufferSubData(m.statsBuffer, 0, sizeof(zero), zero);
    }
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, m.statsBuffer);
    // One fragment per pixel: the box's back faces (the camera may be inside).
    glEnable(GL_CULL_FACE);
    glCullFace(GL_FRONT);
    glEnable(GL_BLEND);
    glBlendFuncSeparate(GL_ONE, GL_ONE_MINUS_SRC_ALPHA, GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
    glBlendEquation(GL_FUNC_ADD);
    const bool depthOut = mode != VolumeRenderMode::Mip && settings.writeDepth;
    if (depthOut) {
      glEnable(GL_DEPTH_TEST);
      glDepthFunc(GL_ALWAYS);
      glDepthMask(GL_TRUE);
    } else {
      glDisable(GL_DEPTH_TEST);
      glDepthMask(GL_FALSE);
    }
    glDrawArrays(GL_TRIANGLES, 0, 36);
    if (settings.collectStats) {
      glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
      GLuint counts[4] = {0, 0, 0, 0};
      glGetNamedBufferSubData(m.statsBuffer, 0, sizeof(counts), counts);
      stats_ = VolumeRenderStats{.rays = counts[0], .samples = counts[1], .skippedSamples = counts[2]};
    }
  } else if (mode == VolumeRenderMode::Slice) {
    // A quad over the volume's world bounds in the plane; the fragment
    // shader discards what lies outside the volume box.
    const int axis = settings.sliceAxis == SliceAxis::Sagittal  ? 0
                     : settings.sliceAxis == SliceAxis::Coronal ? 1
                                                                : 2;
    const Aabb box = boxBounds(g);
    const int u = (axis + 1) % 3, w = (axis + 2) % 3;
    const double pad = 0.01 * box.diagonal().norm();
    std::array<Vec3f, 4> quad;
    for (int c = 0; c < 4; ++c) {
      Vec3 q;
      q[axis] = settings.slicePosition[axis];
      q[u] = (c == 1 || c == 2) ? box.max()[u] + pad : box.min()[u] - pad;
      q[w] = (c >= 2) ? box.max()[w] + pad : box.min()[w] - pad;
      quad[static_cast<std::size_t>(c)] = q.cast<float>();
    }
    ShaderProgram& p = m.slice;
    p.use();
    p.set("u_viewProj", viewProj);
    glProgramUniform3fv(p.id(), p.location("u_quad"), 4, quad[0].data());
    p.set("u_worldToIndex", worldToIndex);
    p.set("u_dims", dimsF);
    p.set("u_volume", 0);
    p.set("u_tf", 1);
    p.set("u_tfMap", tfMap);
    p.set("u_window", window);
    p.set("u_useTf", settings.sliceUsesTransferFunction ? 1 : 0);
    glDisable(GL_CULL_FACE);
    glDisable(GL_BLEND);
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glDepthMask(GL_TRUE);
    glDrawArrays(GL_TRIANGLES, 0, 6);
  } else {
    // Voxels: select on the GPU (no CPU copy of the voxels is kept), then
    // one instanced cube per selected voxel.
    const std::size_t voxels = static_cast<std::size_t>(g.dims.x()) * static_cast<std::size_t>(g.dims.y()) *
                               static_cast<std::size_t>(g.dims.z());
    if (g.instBuffer == 0) {
      g.instCapacity = static_cast<std::uint32_t>(std::min<std::size_t>(voxels, kMaxVoxelInstances));
      glCreateBuffers(1, &g.instBuffer);
      glNamedBufferStorage(g.instBuffer, GLsizeiptr(g.instCapacity) * 2 * GLsizeiptr(sizeof(GLuint)), nullptr,
                           0);
    }
    if (!(g.instThreshold == settings.voxelThreshold)) {
      const GLuint zero = 0;
      glNamedBufferSubData(m.countBuffer, 0, sizeof(zero), &zero);
      ShaderProgram& c = m.voxelCompute;
      c.use();
      c.set("u_volume", 0);
      glProgramUniform3i(c.id(), c.location("u_idims"), g.dims.x(), g.dims.y(), g.dims.z());
      c.set("u_threshold", float((settings.voxelThreshold - g.lo) / (g.hi - g.lo)));
      glProgramUniform1ui(c.id(), c.location("u_capacity"), g.instCapacity);
      glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, m.countBuffer);
      glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 2, g.instBuffer);
      glDispatchCompute(GLuint(g.dims.x() + 7) / 8, GLuint(g.dims.y() + 7) / 8, GLuint(g.dims.z() + 3) / 4);
      glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT | GL_SHADER_STORAGE_BARRIER_BIT);
      GLuint count = 0;
      glGetNamedBufferSubData(m.countBuffer, 0, sizeof(count), &count);
      if (count > g.instCapacity) {
        g.instThreshold = std::numeric_limits<double>::quiet_NaN();
        return fail(
            ErrorCode::InvalidArgument,
            formatString("%u voxels are at or above voxelThreshold %g; the voxel view draws at most %u",
                         count, settings.voxelThreshold, g.instCapacity),
            "VolumeRenderSettings::voxelThreshold", "raise the threshold");
      }
      g.instCount = count;
      g.instThreshold = settings.voxelThreshold;
    }
    ShaderProgram& p = m.voxel;
    p.use();
    p.set("u_viewProj", viewProj);
    p.set("u_indexToWorld", indexToWorld);
    p.set("u_gradToWorld", gradToWorld);
    p.set("u_volume", 0);
    p.set("u_tf", 1);
    p.set("u_tfMap", tfMap);
    p.set("u_window", window);
    p.set("u_useTf", settings.sliceUsesTransferFunction ? 1 : 0);
    p.set("u_lightDir", light.cast<float>().eval());
    p.set("u_material", material);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 2, g.instBuffer);
    glEnable(GL_CULL_FACE);
    glCullFace(GL_BACK);
    glDisable(GL_BLEND);
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glDepthMask(GL_TRUE);
    glDrawArraysInstanced(GL_TRIANGLES, 0, 36, static_cast<GLsizei>(g.instCount));
    stats_.voxelsDrawn = g.instCount;
  }
  return gl::check(where);
}

Result<Camera> VolumeRenderer::sliceViewCamera(VolumeId id, SliceAxis axis, const Vec3& worldPosition,
                                               double aspect) const {
  const char* where = "VolumeRenderer::sliceViewCamera";
  DM_DEMAND(impl_ != nullptr, "VolumeRenderer used after move");
  auto found = impl_->find(id, where);
  if (!found) return found.error();
  if (!(aspect > 0) || !std::isfinite(aspect) || !worldPosition.allFinite())
    return fail(ErrorCode::InvalidArgument, formatString("aspect %g or a non-finite position", aspect), where,
                "pass a positive aspect (width / height) and a finite point");
  const GpuVolume& g = **found;
  const Aabb box = boxBounds(g);
  // Radiological views (see the header): viewing direction, image up, the
  // world axes along image right and up.
  Vec3 forward = Vec3::UnitZ(), up = Vec3::UnitY();
  int rightAxis = 0, upAxis = 1, normalAxis = 2;
  switch (axis) {
    case SliceAxis::Axial:
      forward = Vec3::UnitZ(), up = Vec3::UnitY(), rightAxis = 0, upAxis = 1, normalAxis = 2;
      break;
    case SliceAxis::Coronal:
      forward = -Vec3::UnitY(), up = Vec3::UnitZ(), rightAxis = 0, upAxis = 2, normalAxis = 1;
      break;
    case SliceAxis::Sagittal:
      forward = Vec3::UnitX(), up = Vec3::UnitZ(), rightAxis = 1, upAxis = 2, normalAxis = 0;
      break;
  }
  Vec3 centre = box.center();
  centre[normalAxis] = worldPosition[normalAxis];
  const double distance = box.diagonal().norm() + 0.1;
  Camera cam = Camera::lookAt(centre - forward * distance, centre, up);
  cam.projection = Camera::Projection::Orthographic;
  const Vec3 extent = box.sizes();
  cam.orthoHeight = std::max(extent[upAxis], extent[rightAxis] / aspect);
  cam.nearPlane = 0.01 * distance;
  cam.farPlane = 2 * distance;
  return cam;
}

Status VolumeRenderer::renderSliceView(const RenderTarget& target, const Viewport& viewport, VolumeId id,
                                       SliceAxis axis, const Vec3& worldPosition,
                                       const VolumeRenderSettings& settings) {
  Viewport vp = viewport;
  if (vp.width == 0 || vp.height == 0) vp = Viewport{0, 0, target.width(), target.height()};
  auto cam = sliceViewCamera(id, axis, worldPosition, double(vp.width) / double(vp.height));
  if (!cam) return cam.error();
  VolumeRenderSettings s = settings;
  s.mode = VolumeRenderMode::Slice;
  s.viewport = vp;
  s.sliceAxis = axis;
  s.slicePosition = worldPosition;
  return render(target, *cam, id, s);
}

}  // namespace dm
