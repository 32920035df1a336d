// Collision shapes: support mappings, bounds, volumes; see dm/collide/shapes.hpp.
#include <dm/collide/shapes.hpp>
#include <dm/core/assert.hpp>
#include <dm/math/convex_hull.hpp>
#include <dm/math/mass_properties.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <numbers>
#include <string>

#include "collide_internal.hpp"

namespace dm {

namespace {

constexpr std::array<std::string_view, static_cast<int>(ShapeType::FirstUser)> kBuiltinNames = {
    "point",         "segment",  "plane",       "triangle",    "sphere",
    "box",           "capsule",  "cylinder",    "ellipsoid",   "convex-hull",
    "triangle-mesh", "compound", "point-shell", "sphere-tree", "voxel-model"};

// User shape names. A slot is written once under the mutex before the count
// is published (release), so readers below the count need no lock.
struct TypeRegistry {
  std::mutex mutex;
  std::array<std::string, kMaxShapeTypes> names;
  std::atomic<int> count{static_cast<int>(ShapeType::FirstUser)};
};

TypeRegistry& typeRegistry() {
  static TypeRegistry registry;
  return registry;
}

using detail::kInf;

Aabb centredBox(const Vec3& centre, const Vec3& half) { return Aabb(centre - half, centre + half); }

}  // namespace

Result<ShapeType> registerShapeType(std::string_view name) {
  if (name.empty())
    return fail(ErrorCode::InvalidArgument, "empty shape type name", "registerShapeType",
                "pass a short unique name such as \"voxel-model\"");
  for (std::string_view builtin : kBuiltinNames)
    if (builtin == name)
      return fail(ErrorCode::InvalidArgument,
                  "shape type name \"" + std::string(name) + "\" is a built-in type", "registerShapeType",
                  "use the built-in ShapeType or choose another name");
  TypeRegistry& reg = typeRegistry();
  std::lock_guard lock(reg.mutex);
  const int count = reg.count.load(std::memory_order_relaxed);
  for (int i = static_cast<int>(ShapeType::FirstUser); i < count; ++i)
    if (reg.names[i] == name) return static_cast<ShapeType>(i);
  if (count >= kMaxShapeTypes)
    return fail(ErrorCode::Busy, "all " + std::to_string(kMaxShapeTypes) + " shape type ids are taken",
                "registerShapeType(\"" + std::string(name) + "\")",
                "reuse an existing type or raise dm::kMaxShapeTypes");
  reg.names[count] = std::string(name);
  reg.count.store(count + 1, std::memory_order_release);
  return static_cast<ShapeType>(count);
}

std::string_view shapeTypeName(ShapeType type) noexcept {
  const int id = static_cast<int>(type);
  if (id < static_cast<int>(ShapeType::FirstUser)) return kBuiltinNames[id];
  TypeRegistry& reg = typeRegistry();
  if (id < reg.count.load(std::memory_order_acquire)) return reg.names[id];
  return "unknown";
}

Aabb transformAabb(const Aabb& local, const Isometry3& pose) noexcept {
  if (local.isEmpty()) return local;
  const Vec3 half = pose.linear().cwiseAbs() * (0.5 * local.sizes());
  return centredBox(pose * local.center(), half);
}

// ---------------------------------------------------------------- Shape ---

Aabb Shape::aabb(const Isometry3& pose) const noexcept { return transformAabb(localAabb(), pose); }

BoundingSphere Shape::boundingSphere() const noexcept {
  const Aabb box = localAabb();
  return {box.center(), 0.5 * box.sizes().norm()};
}

Vec3 ConvexShape::support(const Vec3& direction) const noexcept {
  std::uint32_t hint = 0;
  const Vec3 core = supportCore(direction, hint);
  const double n = direction.norm();
  return n > 0 ? Vec3(core + (margin_ / n) * direction) : core;
}

Vec3 ConvexShape::interiorPoint() const noexcept {
  std::uint32_t hint = 0;
  Vec3 sum = Vec3::Zero();
  for (int i = 0; i < 3; ++i)
    sum += supportCore(Vec3::Unit(i), hint) + supportCore(-Vec3::Unit(i), hint);
  return sum / 6.0;
}

Aabb ConvexShape::aabb(const Isometry3& pose) const noexcept {
  Aabb out;
  std::uint32_t hint = 0;
  const Mat3& r = pose.linear();
  for (int i = 0; i < 3; ++i) {
    const Vec3 axis = r.row(i).transpose();  // world axis i in the local frame
    out.max()[i] = pose.translation()[i] + r.row(i).dot(supportCore(axis, hint)) + margin_;
    out.min()[i] = pose.translation()[i] + r.row(i).dot(supportCore(-axis, hint)) - margin_;
  }
  return out;
}

Aabb Segment::localAabb() const noexcept { return Aabb(a_.cwiseMin(b_), a_.cwiseMax(b_)); }

Plane::Plane(const Vec3& normal, double offset) noexcept : Shape(ShapeType::Plane), offset_(offset) {
  const double n = normal.norm();
  normal_ = n > 0 ? Vec3(normal / n) : Vec3::UnitZ();
  if (n > 0) offset_ = offset / n;
}

Aabb Plane::localAabb() const noexcept {
  Aabb box(Vec3::Constant(-kInf), Vec3::Constant(kInf));
  // An axis-aligned half-space is bounded on its normal's axis.
  for (int i = 0; i < 3; ++i) {
    if (normal_[i] == 1.0) box.max()[i] = offset_;
    if (normal_[i] == -1.0) box.min()[i] = -offset_;
  }
  return box;
}

Aabb Plane::aabb(const Isometry3& pose) const noexcept {
  const Vec3 n = pose.linear() * normal_;
  const double d = offset_ + n.dot(pose.translation());
  Aabb box(Vec3::Constant(-kInf), Vec3::Constant(kInf));
  for (int i = 0; i < 3; ++i) {
    if (std::abs(n[i]) < 1.0 - 1e-12) continue;
    if (n[i] > 0)
      box.max()[i] = d / n[i];
    else
      box.min()[i] = d / n[i];
  }
  return box;
}

double Plane::volume() const noexcept { return kInf; }

Vec3 TriangleShape::supportCore(const Vec3& d, std::uint32_t&) const noexcept {
  const double d0 = d.dot(v_[0]), d1 = d.dot(v_[1]), d2 = d.dot(v_[2]);
  if (d0 >= d1 && d0 >= d2) return v_[0];
  return d1 >= d2 ? v_[1] : v_[2];
}

Aabb TriangleShape::localAabb() const noexcept {
  return Aabb(v_[0].cwiseMin(v_[1]).cwiseMin(v_[2]), v_[0].cwiseMax(v_[1]).cwiseMax(v_[2]));
}

Aabb Sphere::localAabb() const noexcept { return centredBox(Vec3::Zero(), Vec3::Constant(radius())); }

Aabb Sphere::aabb(const Isometry3& pose) const noexcept {
  return centredBox(pose.translation(), Vec3::Constant(radius()));
}

double Sphere::volume() const noexcept { return 4.0 / 3.0 * std::numbers::pi * std::pow(radius(), 3); }

Vec3 Box::supportCore(const Vec3& d, std::uint32_t&) const noexcept {
  return {d.x() >= 0 ? half_.x() : -half_.x(), d.y() >= 0 ? half_.y() : -half_.y(),
          d.z() >= 0 ? half_.z() : -half_.z()};
}

Aabb Box::aabb(const Isometry3& pose) const noexcept {
  return centredBox(pose.translation(), pose.linear().cwiseAbs() * half_);
}

Aabb Capsule::localAabb() const noexcept {
  const double r = radius();
  return centredBox(Vec3::Zero(), Vec3(r, r, h_ + r));
}

Aabb Capsule::aabb(const Isometry3& pose) const noexcept {
  const Vec3 axis = pose.linear().col(2) * h_;
  return centredBox(pose.translation(), axis.cwiseAbs() + Vec3::Constant(radius()));
}

double Capsule::volume() const noexcept {
  const double r = radius();
  return std::numbers::pi * r * r * (2.0 * h_ + 4.0 / 3.0 * r);
}

Vec3 Cylinder::supportCore(const Vec3& d, std::uint32_t&) const noexcept {
  const double s = std::hypot(d.x(), d.y());
  const double z = d.z() >= 0 ? h_ : -h_;
  if (s == 0.0) return {0, 0, z};
  return {r_ * d.x() / s, r_ * d.y() / s, z};
}

Aabb Cylinder::localAabb() const noexcept { return centredBox(Vec3::Zero(), Vec3(r_, r_, h_)); }

Aabb Cylinder::aabb(const Isometry3& pose) const noexcept {
  const Vec3 a = pose.linear().col(2);
  Vec3 half;
  for (int i = 0; i < 3; ++i)
    half[i] = h_ * std::abs(a[i]) + r_ * std::sqrt(std::max(0.0, 1.0 - a[i] * a[i]));
  return centredBox(pose.translation(), half);
}

double Cylinder::volume() const noexcept { return 2.0 * std::numbers::pi * r_ * r_ * h_; }

BoundingSphere Cylinder::boundingSphere() const noexcept { return {Vec3::Zero(), std::hypot(r_, h_)}; }

Vec3 Ellipsoid::supportCore(const Vec3& d, std::uint32_t&) const noexcept {
  const Vec3 rd = radii_.cwiseProduct(d);
  const double n = rd.norm();
  if (n == 0.0) return Vec3::Zero();
  return radii_.cwiseProduct(rd) / n;
}

Aabb Ellipsoid::aabb(const Isometry3& pose) const noexcept {
  // Extent along world axis i is |row_i(R)·diag(radii)|.
  const Vec3 half = (pose.linear() * radii_.asDiagonal()).rowwise().norm();
  return centredBox(pose.translation(), half);
}

double Ellipsoid::volume() const noexcept { return 4.0 / 3.0 * std::numbers::pi * radii_.prod(); }

// ------------------------------------------------------------ ConvexHull ---

Result<std::shared_ptr<const ConvexHull>> ConvexHull::create(std::span<const Vec3> points) {
  auto mesh = convexHull(points);
  if (!mesh) return mesh.error();
  std::shared_ptr<ConvexHull> hull(new ConvexHull());
  hull->mesh_ = std::move(*mesh);
  const auto& pos = hull->mesh_.positions;
  const std::size_t n = pos.size();
  // Directed edges of a closed CCW mesh list every undirected edge both ways,
  // so each vertex collects each neighbour exactly once.
  std::vector<std::uint32_t> degree(n + 1, 0);
  for (const auto& t : hull->mesh_.triangles)
    for (int k = 0; k < 3; ++k) ++degree[t[k] + 1];
  for (std::size_t i = 0; i < n; ++i) degree[i + 1] += degree[i];
  hull->adjacencyStart_ = degree;
  hull->adjacency_.resize(degree[n]);
  for (const auto& t : hull->mesh_.triangles)
    for (int k = 0; k < 3; ++k) hull->adjacency_[degree[t[k]]++] = t[(k + 1) % 3];

  constexpr int g = kCubeGrid;
  hull->startVertex_.resize(6 * g * g);
  for (int face = 0; face < 6; ++face)
    for (int iu = 0; iu < g; ++iu)
      for (int iv = 0; iv < g; ++iv) {
        const int axis = face / 2;
        Vec3 d;
        d[axis] = face % 2 == 0 ? 1.0 : -1.0;
        d[(axis + 1) % 3] = -1.0 + (iu + 0.5) * 2.0 / g;
        d[(axis + 2) % 3] = -1.0 + (iv + 0.5) * 2.0 / g;
        std::uint32_t best = 0;
        for (std::uint32_t v = 1; v < n; ++v)
          if (d.dot(pos[v]) > d.dot(pos[best])) best = v;
        hull->startVertex_[(face * g + iu) * g + iv] = best;
      }
  const std::size_t padded = (n + 3) & ~std::size_t(3);
  hull->coordinates_.resize(3 * padded);
  for (std::size_t i = 0; i < padded; ++i)
    for (int k = 0; k < 3; ++k) hull->coordinates_[k * padded + i] = pos[i < n ? i : 0][k];
  hull->bounds_ = hull->mesh_.bounds();
  const Vec3 c = hull->bounds_.center();
  double r2 = 0;
  for (const Vec3& p : pos) r2 = std::max(r2, (p - c).squaredNorm());
  hull->sphere_ = {c, std::sqrt(r2)};
  for (const Vec3& p : pos) hull->centroid_ += p;
  hull->centroid_ /= static_cast<double>(pos.size());
  if (auto mp = computeMassProperties(hull->mesh_); mp) hull->volume_ = mp->volume;
  return std::shared_ptr<const ConvexHull>(std::move(hull));
}

int ConvexHull::cubeCell(const Vec3& d) noexcept {
  // Branch-free: the dominant axis by conditional moves, one division for
  // both in-face coordinates (the support mappings call this on every
  // query, with directions that jump around).
  const double ax = std::abs(d.x()), ay = std::abs(d.y()), az = std::abs(d.z());
  int axis = ay > ax ? 1 : 0;
  double m = std::max(ax, ay);
  axis = az > m ? 2 : axis;
  m = std::max(m, az);
  if (!(m > 0)) return 0;
  static constexpr int kNext[3][2] = {{1, 2}, {2, 0}, {0, 1}};
  const double scale = 0.5 * kCubeGrid / m;
  const auto bin = [scale](double x) {
    return std::min(static_cast<int>(x * scale + 0.5 * kCubeGrid), kCubeGrid - 1);  // x·scale ≥ −g/2
  };
  const int face = 2 * axis + (d[axis] >= 0 ? 0 : 1);
  return (face * kCubeGrid + bin(d[kNext[axis][0]])) * kCubeGrid + bin(d[kNext[axis][1]]);
}

Vec3 ConvexHull::supportCore(const Vec3& d, std::uint32_t& hint) const noexcept {
  const auto& pos = mesh_.positions;
  const auto n = static_cast<std::uint32_t>(pos.size());
  // Below a few dozen vertices a linear scan beats the pointer chasing.
  if (n <= 12) {
    std::uint32_t best = 0;
    double bestDot = d.dot(pos[0]);
    for (std::uint32_t i = 1; i < n; ++i) {
      const double v = d.dot(pos[i]);
      if (v > bestDot) bestDot = v, best = i;
    }
    hint = best;
    return pos[best];
  }
  // Hill-climbing: a linear function over a convex polytope has no local
  // maximum on the vertex graph other than the global one.
  // Start from the better of the caller's hint and the tabulated extreme
  // vertex of the direction's cube-map cell.
  std::uint32_t cur = startVertex_[cubeCell(d)];
  double curDot = d.dot(pos[cur]);
  if (hint < n && d.dot(pos[hint]) > curDot) cur = hint, curDot = d.dot(pos[hint]);
  for (bool moved = true; moved;) {
    moved = false;
    for (std::uint32_t j = adjacencyStart_[cur], e = adjacencyStart_[cur + 1]; j < e; ++j) {
      const std::uint32_t v = adjacency_[j];
      const double dv = d.dot(pos[v]);
      if (dv > curDot) {
        curDot = dv;
        cur = v;
        moved = true;
      }
    }
  }
  hint = cur;
  return pos[cur];
}

// ---------------------------------------------------------- TriangleMesh ---

TriangleMesh::TriangleMesh(std::shared_ptr<const Mesh> mesh, std::shared_ptr<const MeshBvh> bvh)
    : Shape(ShapeType::TriangleMesh), mesh_(std::move(mesh)), bvh_(std::move(bvh)) {
  DM_DEMAND(mesh_ != nullptr, "TriangleMesh needs a mesh");
  bounds_ = mesh_->bounds();
  if (!mesh_->empty())
    if (auto mp = computeMassProperties(*mesh_); mp) volume_ = mp->volume;
}

// -------------------------------------------------------------- Compound ---

Compound::Compound(std::vector<CompoundChild> children) : Shape(ShapeType::Compound) {
  for (auto& c : children)
    if (c.shape) children_.push_back(std::move(c));
  for (const auto& c : children_) bounds_.extend(c.shape->aabb(c.pose));
}

Aabb Compound::aabb(const Isometry3& pose) const noexcept {
  Aabb out;
  for (const auto& c : children_) out.extend(c.shape->aabb(pose * c.pose));
  return out;
}

double Compound::volume() const noexcept {
  double v = 0;
  for (const auto& c : children_) v += c.shape->volume();
  return v;
}

}  // namespace dm
