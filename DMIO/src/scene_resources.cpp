// scene_resources.cpp — volumes, meshes, isosurfaces, shapes and images of a
// scene file, loaded in dependency order.
#include <dm/core/resource.hpp>
#include <dm/io/image_io.hpp>
#include <dm/io/resources.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/math/isosurface.hpp>
#include <dm/math/mesh_filters.hpp>
#include <dm/math/phantom.hpp>
#include <dm/math/primitives.hpp>
#include <dm/math/volume_components.hpp>
#include <dm/math/volume_distance.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

namespace dm {

namespace {

template <class Map>
auto findIn(const Map& m, std::string_view name) -> typename Map::mapped_type {
  auto it = m.find(name);
  return it == m.end() ? nullptr : it->second;
}

std::string where(const SceneResource& r) { return "resources/" + r.name; }

// Box average over f x f x f voxel blocks (a remainder at the far faces is
// dropped); the coarse voxel sits at its block's centre in world space.
Result<Volume> downsampled(const Volume& v, int f, const std::string& where) {
  const Vec3i d = v.dims() / f;
  if (d.minCoeff() < 2)
    return fail(ErrorCode::InvalidArgument,
                formatString("downsample %d leaves fewer than 2 voxels on an axis", f), where,
                "use a smaller factor");
  Affine3 a = v.indexToWorld();
  a.translate(Vec3::Constant(0.5 * (f - 1)));
  a.scale(double(f));
  auto out = Volume::create(d, VoxelType::F32, a);
  if (!out) return out.error();
  float* o = out->data<float>();
  const double inv = 1.0 / (double(f) * f * f);
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i) {
        double sum = 0;
        for (int c = 0; c < f; ++c)
          for (int b = 0; b < f; ++b)
            for (int q = 0; q < f; ++q) sum += v.value(i * f + q, j * f + b, k * f + c);
        o[(std::size_t(k) * d.y() + j) * d.x() + i] = static_cast<float>(sum * inv);
      }
  return out;
}

Result<Mesh> makeIsosurface(const SceneResource& r, const Volume& full) {
  Volume coarse;
  if (r.downsample > 1) {
    auto c = downsampled(full, r.downsample, where(r) + "/downsample");
    if (!c) return c.error();
    coarse = std::move(*c);
  }
  const Volume& volume = r.downsample > 1 ? coarse : full;
  auto mesh = extractIsosurface(volume, {.iso = r.level, .closeBorders = true});
  if (!mesh) return mesh.error().within(where(r));
  if (mesh->empty())
    return fail(ErrorCode::InvalidArgument,
                formatString("no surface at level %g (volume values lie elsewhere)", r.level),
                where(r) + "/level",
                "pick a level between the volume's minimum and maximum (dmtool info shows them)");
  if (r.largestComponent) *mesh = keepLargestComponent(*mesh);
  if (r.smooth > 0)
    if (auto s = smoothMesh(*mesh, {.iterations = r.smooth, .maxDisplacement = r.smoothMaxDisplacement}); !s)
      return s.error().within(where(r) + "/smooth");
  mesh->name = r.name;
  return mesh;
}

}  // namespace

namespace {

// A mask volume a segment names ("outside", "near") must lie on the
// source's grid, voxel for voxel.
Status checkSameGrid(const Volume& mask, const Volume& source, const std::string& name,
                     const std::string& at) {
  const bool same = mask.dims() == source.dims() &&
                    (mask.indexToWorld().matrix() - source.indexToWorld().matrix()).cwiseAbs().maxCoeff() <=
                        1e-9 * (1.0 + source.indexToWorld().matrix().cwiseAbs().maxCoeff());
  if (same) return ok();
  const Vec3i a = mask.dims(), b = source.dims();
  return fail(ErrorCode::InvalidArgument,
              formatString("volume \"%s\" (%d x %d x %d) is not on the scan's grid (%d x %d x %d, its own "
                           "voxel positions)",
                           name.c_str(), a.x(), a.y(), a.z(), b.x(), b.y(), b.z()),
              at, "give a mask made on the same scan (a brain mask of the MRI, a label map of the CT)");
}

// The count of nonzero voxels of a U8 mask.
std::size_t countSet(const Volume& mask) {
  const std::uint8_t* m = mask.data<std::uint8_t>();
  return static_cast<std::size_t>(
      std::count_if(m, m + mask.voxelCount(), [](std::uint8_t x) { return x != 0; }));
}

// Keeps the largest 26-connected part of `mask` in place.
Status keepLargest(Volume& mask, const std::string& at) {
  auto largest = largestComponent(mask);
  if (!largest) return largest.error().within(at);
  mask = std::move(*largest);
  return ok();
}

}  // namespace

Result<Volume> makeSceneSegment(const SceneResource& r, const Volume& source, const Volume* outside,
                                const Volume* near) {
  if (!r.segment) return fail(ErrorCode::InvalidArgument, "not a segment", where(r));
  const SceneSegment& g = *r.segment;
  const std::string at = where(r) + "/segment";
  if (source.empty()) return fail(ErrorCode::InvalidArgument, "the volume is empty", at + "/volume");
  if (!g.outside.empty()) {
    if (outside == nullptr)
      return fail(ErrorCode::InvalidArgument, "the mask \"" + g.outside + "\" was not given",
                  at + "/outside");
    if (auto s = checkSameGrid(*outside, source, g.outside, at + "/outside"); !s) return s.error();
  }
  if (g.near) {
    if (near == nullptr)
      return fail(ErrorCode::InvalidArgument, "the mask \"" + g.near->volume + "\" was not given",
                  at + "/near/volume");
    if (auto s = checkSameGrid(*near, source, g.near->volume, at + "/near/volume"); !s) return s.error();
  }
  // The index range to visit: the box's corners in index space, or the grid.
  Vec3i lo = Vec3i::Zero(), hi = source.dims() - Vec3i::Ones();
  if (g.box) {
    Vec3 a = Vec3::Constant(std::numeric_limits<double>::infinity()), b = -a;
    for (int c = 0; c < 8; ++c) {
      const Vec3 corner((c & 1) ? g.box->max.x() : g.box->min.x(), (c & 2) ? g.box->max.y() : g.box->min.y(),
                        (c & 4) ? g.box->max.z() : g.box->min.z());
      const Vec3 idx = source.worldToIndex() * corner;
      a = a.cwiseMin(idx);
      b = b.cwiseMax(idx);
    }
    lo = lo.cwiseMax(a.array().floor().cast<int>().matrix());
    hi = hi.cwiseMin(b.array().ceil().cast<int>().matrix());
    if ((hi.array() < lo.array()).any())
      return fail(ErrorCode::InvalidArgument, "the box misses the volume", at + "/box",
                  "give world coordinates (m) inside the scan");
  }
  // "near": squared distances (in units of the smallest voxel size) to the
  // other mask's voxels, over the range grown by the distance — exact, as
  // no voxel farther out can be within it.
  std::vector<float> nearD2;
  Vec3i nearLo = lo, nearDims = Vec3i::Zero();
  double nearR2 = 0;
  if (g.near) {
    const Vec3 spacing = source.indexToWorld().linear().colwise().norm().transpose();
    const double unit = spacing.minCoeff();
    // (at most the grid: a tiny voxel size must not overflow the int)
    const Vec3i grow = (g.near->distance / spacing.array())
                           .ceil()
                           .matrix()
                           .cwiseMin(source.dims().cast<double>())
                           .cast<int>();
    nearLo = (lo - grow).cwiseMax(Vec3i::Zero());
    const Vec3i nearHi = (hi + grow).cwiseMin(source.dims() - Vec3i::Ones());
    nearDims = nearHi - nearLo + Vec3i::Ones();
    std::vector<std::uint8_t> fg(static_cast<std::size_t>(nearDims.prod()));
    std::size_t n = 0;
    for (int k = nearLo.z(); k <= nearHi.z(); ++k)
      for (int j = nearLo.y(); j <= nearHi.y(); ++j)
        for (int i = nearLo.x(); i <= nearHi.x(); ++i, ++n) fg[n] = near->value(i, j, k) != 0 ? 1 : 0;
    nearD2 = squaredDistanceToForeground(fg, nearDims, spacing / unit);
    const double reach = g.near->distance / unit;
    nearR2 = reach * reach * (1 + 1e-9);  // a voxel exactly at the distance is within it
  }
  const Vec3i dims = hi - lo + Vec3i::Ones();
  auto mask = Volume::create(dims, VoxelType::U8,
                             source.indexToWorld() * Affine3(Eigen::Translation3d(lo.cast<double>())));
  if (!mask) return mask.error().within(at);
  std::uint8_t* m = mask->data<std::uint8_t>();
  std::size_t selected = 0, n = 0;
  for (int k = lo.z(); k <= hi.z(); ++k)
    for (int j = lo.y(); j <= hi.y(); ++j)
      for (int i = lo.x(); i <= hi.x(); ++i, ++n) {
        const double v = source.value(i, j, k);
        bool keep = g.select == SceneSegment::Select::Above   ? v > g.value
                    : g.select == SceneSegment::Select::Below ? v < g.value
                                                              : v == g.value;
        if (!keep) continue;
        if (g.box) {
          const Vec3 p = source.indexToWorld() * Vec3(i, j, k);
          keep = (p.array() >= g.box->min.array()).all() && (p.array() <= g.box->max.array()).all();
        }
        if (keep && outside != nullptr && !g.outside.empty()) keep = outside->value(i, j, k) == 0;
        if (keep && g.near) {
          const Vec3i q = Vec3i(i, j, k) - nearLo;
          const float d2 =
              nearD2[(static_cast<std::size_t>(q.z()) * nearDims.y() + q.y()) * nearDims.x() + q.x()];
          keep = std::isfinite(d2) && d2 <= nearR2;  // +inf: no mask voxel anywhere
        }
        m[n] = keep ? 1 : 0;
        selected += keep;
      }
  if (selected == 0)
    return fail(ErrorCode::InvalidArgument, "the segment selects no voxel", at,
                "check the value against the scan's (dmtool info), the box, \"outside\" and \"near\"");
  if (g.largestComponent)
    if (auto s = keepLargest(*mask, at); !s) return s.error();
  if (!g.cuts.empty()) {
    // The centroid of what the cuts divide (world, m), for "point": "centroid".
    m = mask->data<std::uint8_t>();
    Vec3 sum = Vec3::Zero();
    std::size_t count = 0;
    n = 0;
    for (int k = 0; k < dims.z(); ++k)
      for (int j = 0; j < dims.y(); ++j)
        for (int i = 0; i < dims.x(); ++i, ++n)
          if (m[n] != 0) {
            sum += Vec3(i, j, k);
            ++count;
          }
    const Vec3 centroid = mask->indexToWorld() * (sum / static_cast<double>(count));
    n = 0;
    for (int k = 0; k < dims.z(); ++k)
      for (int j = 0; j < dims.y(); ++j)
        for (int i = 0; i < dims.x(); ++i, ++n) {
          if (m[n] == 0) continue;
          const Vec3 p = mask->indexToWorld() * Vec3(i, j, k);
          for (const SceneCut& c : g.cuts)
            if (!(c.normal.dot(p - (c.atCentroid ? centroid : c.point)) > 0.5 * c.kerf)) m[n] = 0;
        }
    if (countSet(*mask) == 0)
      return fail(ErrorCode::InvalidArgument, "the cuts leave no voxel", at + "/cuts",
                  "check the cuts' sides: each normal points to the side kept");
    if (g.largestComponent)
      if (auto s = keepLargest(*mask, at); !s) return s.error();
  }
  m = mask->data<std::uint8_t>();
  // Crop to the kept voxels with one empty voxel around them (a closed
  // isosurface, a small sphere tree); the voxels keep their world positions.
  Vec3i a = dims, b = -Vec3i::Ones();
  n = 0;
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i, ++n)
        if (m[n] != 0) {
          a = a.cwiseMin(Vec3i(i, j, k));
          b = b.cwiseMax(Vec3i(i, j, k));
        }
  a -= Vec3i::Ones();
  b += Vec3i::Ones();
  auto out = Volume::create(b - a + Vec3i::Ones(), VoxelType::U8,
                            mask->indexToWorld() * Affine3(Eigen::Translation3d(a.cast<double>())));
  if (!out) return out.error().within(at);
  for (int k = a.z() + 1; k < b.z(); ++k)
    for (int j = a.y() + 1; j < b.y(); ++j)
      for (int i = a.x() + 1; i < b.x(); ++i)
        if (mask->value(i, j, k) != 0) out->setValue(i - a.x(), j - a.y(), k - a.z(), 1.0);
  return out;
}

std::shared_ptr<const Mesh> SceneResources::mesh(std::string_view name) const { return findIn(meshes, name); }
std::shared_ptr<const Volume> SceneResources::volume(std::string_view name) const {
  return findIn(volumes, name);
}
std::shared_ptr<const Image> SceneResources::image(std::string_view name) const {
  return findIn(images, name);
}

SceneResource scenePartShape(const SceneResource& compound, const SceneResource::Part& part) {
  SceneResource one = compound;
  one.type = SceneResource::Type::Shape;
  one.shape = part.shape;
  one.radius = part.radius;
  one.height = part.height;
  one.halfExtents = part.halfExtents;
  one.parts.clear();
  return one;
}

Result<Mesh> makeSceneShape(const SceneResource& r) {
  if (r.type != SceneResource::Type::Shape)
    return fail(ErrorCode::InvalidArgument, "not a shape resource", where(r));
  const int sub = std::clamp(r.subdivisions, 0, 8);
  const int segments = std::min(8 << sub, 1024);  // around an axis: 8, 16, ..., 1024
  Mesh m;
  switch (r.shape) {
    case SceneResource::Shape::Sphere:
      if (!(r.radius > 0)) break;
      m = makeIcosphere(r.radius, std::min(sub, 7));
      break;
    case SceneResource::Shape::Box:
      if (!(r.halfExtents.minCoeff() > 0)) break;
      m = makeBox(r.halfExtents);
      break;
    case SceneResource::Shape::Capsule:
      if (!(r.radius > 0) || !(r.height > 0)) break;
      m = makeCapsule(r.radius, r.height, segments, std::max(2, segments / 4));
      break;
    case SceneResource::Shape::Cylinder:
      if (!(r.radius > 0) || !(r.height > 0)) break;
      m = makeCylinder(r.radius, r.height, segments);
      break;
    case SceneResource::Shape::Plane:
      if (!(r.halfExtents.x() > 0) || !(r.halfExtents.y() > 0)) break;
      m = makePlane(r.halfExtents.x(), r.halfExtents.y(), std::max(1, 1 << std::min(sub, 8)));
      break;
    case SceneResource::Shape::Compound:
      // Each part's own closed mesh, placed: their union drawn and touched
      // as one mesh (overlapping parts keep their inner faces).
      for (const SceneResource::Part& part : r.parts) {
        auto pm = makeSceneShape(scenePartShape(r, part));
        if (!pm) return pm.error();
        pm->transform(Affine3(part.pose.isometry().matrix()));
        m.append(*pm);
      }
      break;
  }
  if (m.empty())
    return fail(ErrorCode::InvalidArgument, "shape with a non-positive size", where(r),
                "give radius, half_extents or height > 0 as the shape needs");
  m.name = r.name;
  return m;
}

namespace {

std::uint64_t bytesOf(const Mesh& m) {
  return m.positions.size() * sizeof(Vec3) + m.normals.size() * sizeof(Vec3) +
         m.triangles.size() * sizeof(Triangle) + m.uvs.size() * sizeof(Vec2f) +
         m.colors.size() * sizeof(Vec4f);
}
std::uint64_t bytesOf(const Volume& v) { return v.byteSize(); }
std::uint64_t bytesOf(const Image& i) { return std::uint64_t(i.strideBytes()) * std::uint64_t(i.height()); }

// The scene's memory budget (SceneLoadOptions::maxBytes). What the scene
// declares itself (its phantoms' voxels) is summed before anything is
// made; each resource then counts as it arrives (one held by two names,
// a file the resource manager shares, once), and the first that takes the
// total over the budget fails, naming both figures.
class SceneBudget {
 public:
  explicit SceneBudget(std::size_t limit) : limit_(limit) {}

  Status declare(const SceneDesc& scene) {
    std::uint64_t declared = 0;
    std::size_t phantoms = 0;
    for (const SceneResource& r : scene.resources) {
      if (!r.phantom) continue;
      const Vec3i n = calvariumPhantomDims(*r.phantom);
      declared += std::uint64_t(n.x()) * std::uint64_t(n.y()) * std::uint64_t(n.z()) * sizeof(std::int16_t);
      ++phantoms;
    }
    if (declared <= limit_) return ok();
    return fail(
        ErrorCode::InvalidArgument,
        formatString("the scene's %zu phantom(s) declare %llu bytes of voxels, more than the budget of %zu "
                     "bytes",
                     phantoms, static_cast<unsigned long long>(declared), limit_),
        "resources", kHint);
  }

  template <class T>
  Status add(const std::shared_ptr<const T>& item, const SceneResource& r) {
    if (!counted_.insert(item.get()).second) return ok();
    used_ += bytesOf(*item);
    if (used_ <= limit_) return ok();
    return fail(
        ErrorCode::InvalidArgument,
        formatString("it brings the scene's resources to %llu bytes, more than the budget of %zu bytes",
                     static_cast<unsigned long long>(used_), limit_),
        where(r), kHint);
  }

 private:
  static constexpr const char* kHint =
      "raise SceneLoadOptions::maxBytes if the memory is there, or use smaller, coarser resources";
  std::size_t limit_;
  std::uint64_t used_ = 0;
  std::set<const void*> counted_;
};

}  // namespace

Result<SceneResources> loadSceneResources(const SceneDesc& scene, const SceneLoadOptions& options) {
  ResourceManager local;
  ResourceManager* rm = options.resourceManager;
  if (rm == nullptr) {
    if (auto s = registerIoLoaders(local); !s) return s.error();
    rm = &local;
  }
  // The manager's cache is weak: its handles stay alive through the load so
  // that a file two resources name is read once.
  std::vector<Handle<Volume>> heldVolumes;
  std::vector<Handle<Mesh>> heldMeshes;
  SceneBudget budget(options.maxBytes);
  if (auto s = budget.declare(scene); !s) return s.error();
  SceneResources out;
  const double total = std::max<std::size_t>(scene.resources.size(), 1);
  std::size_t done = 0;
  auto report = [&](const SceneResource& r) {
    if (options.progress) options.progress(r.name, double(done) / total);
    ++done;
  };
  // Counted against the budget, then kept under the resource's name.
  auto keep = [&budget](auto& map, const SceneResource& r, auto item) -> Status {
    if (auto s = budget.add(item, r); !s) return s;
    map.emplace(r.name, std::move(item));
    return ok();
  };
  auto missing = [](const SceneResource& r) -> Error {
    return fail(ErrorCode::NotFound, "\"" + r.source + "\" does not exist", where(r) + "/source",
                "check the path (relative paths resolve against the scene file's folder) or the mount name");
  };
  // Volumes first: isosurfaces derive from them.
  for (const SceneResource& r : scene.resources) {
    if (r.type != SceneResource::Type::Volume) continue;
    if (r.segment) continue;  // made from another volume, below
    report(r);
    if (r.phantom) {
      auto v = makeCalvariumPhantom(*r.phantom);
      if (!v) return v.error().within(where(r) + "/phantom");
      if (auto s = keep(out.volumes, r, std::make_shared<const Volume>(std::move(*v))); !s) return s.error();
      continue;
    }
    if (r.path.empty()) return missing(r);
    auto h = rm->load<Volume>(r.path);
    if (!h) return h.error().within(where(r));
    if (auto s = keep(out.volumes, r, h->get()); !s) return s.error();
    heldVolumes.push_back(std::move(*h));
  }
  // Segments, from the volumes they cut (never another segment: parseScene checks).
  for (const SceneResource& r : scene.resources) {
    if (!r.segment) continue;
    report(r);
    auto vol = out.volume(r.segment->volume);
    if (!vol)
      return fail(ErrorCode::NotFound, "no volume resource \"" + r.segment->volume + "\"",
                  where(r) + "/segment/volume");
    const auto mask = [&](const std::string& name) -> std::shared_ptr<const Volume> {
      return name.empty() ? nullptr : out.volume(name);
    };
    const std::shared_ptr<const Volume> outside = mask(r.segment->outside);
    const std::shared_ptr<const Volume> near =
        mask(r.segment->near ? r.segment->near->volume : std::string());
    auto seg = makeSceneSegment(r, *vol, outside.get(), near.get());
    if (!seg) return seg.error();
    if (auto s = keep(out.volumes, r, std::make_shared<const Volume>(std::move(*seg))); !s) return s.error();
  }
  for (const SceneResource& r : scene.resources) {
    switch (r.type) {
      case SceneResource::Type::Volume:
        break;
      case SceneResource::Type::Mesh: {
        report(r);
        if (r.path.empty()) return missing(r);
        ImportOptions o;
        o.set("unit", r.unit);
        if (r.scale != 1.0) o.set("scale", formatString("%.17g", r.scale));
        auto h = rm->load<Mesh>(r.path, o);
        if (!h) return h.error().within(where(r));
        if (auto s = keep(out.meshes, r, h->get()); !s) return s.error();
        heldMeshes.push_back(std::move(*h));
        break;
      }
      case SceneResource::Type::Isosurface: {
        report(r);
        auto vol = out.volume(r.volume);
        if (!vol)
          return fail(ErrorCode::NotFound, "no volume resource \"" + r.volume + "\"", where(r) + "/volume");
        auto mesh = makeIsosurface(r, *vol);
        if (!mesh) return mesh.error();
        if (auto s = keep(out.meshes, r, std::make_shared<const Mesh>(std::move(*mesh))); !s)
          return s.error();
        break;
      }
      case SceneResource::Type::Shape: {
        report(r);
        auto mesh = makeSceneShape(r);
        if (!mesh) return mesh.error();
        if (auto s = keep(out.meshes, r, std::make_shared<const Mesh>(std::move(*mesh))); !s)
          return s.error();
        break;
      }
      case SceneResource::Type::Image: {
        report(r);
        if (r.path.empty()) return missing(r);
        auto img = readPng(r.path);
        if (!img) return img.error().within(where(r));
        if (auto s = keep(out.images, r, std::make_shared<const Image>(std::move(*img))); !s)
          return s.error();
        break;
      }
    }
  }
  if (options.progress) options.progress("", 1.0);
  return out;
}

}  // namespace dm
