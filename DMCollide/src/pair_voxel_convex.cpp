// Voxel-model pairs of the collider table against the convex shapes with
// flat or curved faces: box, cylinder, ellipsoid, convex hull and triangle
// (A: the convex shape, B: the voxel model; see dm/collide/voxel_model.hpp).
//
// The convex shape's surface is sampled on the fly, never stored: it is a
// small set of parametric patches (faces, edges and vertices of boxes, hulls
// and triangles; side, caps and rims of cylinders; the six cube-sphere faces
// of ellipsoids), each a map p(s, t) from [0,1]² (edges [0,1], vertices a
// point) with bounds Ls ≥ |∂p/∂s|, Lt ≥ |∂p/∂t| over any parameter cell. A
// cell's points lie within R = (Ls·Δs + Lt·Δt)/2 of its centre, so with the
// model's Lipschitz bound K a cell whose centre has distance d is skipped
// when d − K·R exceeds the cutoff. Cells are halved along their longer side
// until both metric sides are ≤ h, the model's smallest voxel spacing; the
// leaf's centre is the sample (every surface point lies within h of one,
// and edges and vertices are sampled themselves, so corners are not cut).
//  * intersect: true at the first sample with distance ≤ 0.
//  * contacts: one per sample with distance d ≤ 0 (Voxmap–PointShell rule:
//    depth −d, normal −∇d from the shape into the model, position midway),
//    reduced with reduceContacts() to request.maxContacts.
//  * distance: branch and bound for the smallest sample distance (cutoff =
//    best so far). With ρ ≤ h the sample spacing, the answer D satisfies
//    m ≤ D ≤ m + K·h where m is the minimum of the model's interpolated
//    distance over the shape's surface: exact-to-sampling when separated,
//    −(depth of the deepest surface point inside the model) when
//    overlapping, as for the round shapes of pair_voxel.cpp.
// When no surface sample lies inside the model the model's solid may still
// lie wholly inside the shape: an octree over the shape's bounds, pruned by
// the model's Lipschitz bound (no solid in the cell) and a lower bound of the
// shape's signed distance (cell outside the shape), looks for a cell centre
// inside both, down to cells of about one voxel (a part of the solid that
// holds no ball of one voxel's radius may go unseen). If one is found the
// pair collides; contacts and distance then give that point with the
// shape's outward normal nearest to it (A → B) and depth = its depth below
// the shape's surface (a lower bound of the translation that separates them).
//
// Cost: O(patches + samples near the model's surface), the samples within
// K·h of the surface; plus, when no sample penetrates, the octree cells near
// both surfaces (hulls: O(faces) per cell). No allocation (contacts append
// to the caller's vector, whose capacity it keeps), lock or throw; stacks
// are fixed arrays.
#include <dm/collide/voxel_model.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "collide_internal.hpp"
#include "pair_colliders.hpp"

namespace dm {

namespace {

using detail::kInf;
using detail::modelOf;
using detail::normalFromGradient;
constexpr double kTwoPi = 2.0 * std::numbers::pi;
constexpr int kCellStackSize = 160;

// Smallest x² over x ∈ [x0, x1].
double minSquare(double x0, double x1) noexcept {
  if (x0 <= 0 && x1 >= 0) return 0.0;
  return std::min(x0 * x0, x1 * x1);
}

// Triangle (a, b, c) as the collapsed square p = a + s(b − a) + s·t(c − b):
// |∂p/∂s| ≤ max(|b − a|, |c − a|), |∂p/∂t| = s·|c − b|.
Vec3 trianglePoint(const Vec3& a, const Vec3& b, const Vec3& c, double s, double t) noexcept {
  return a + s * (b - a) + s * t * (c - b);
}
void triangleBounds(const Vec3& a, const Vec3& b, const Vec3& c, double s1, double& ls, double& lt) noexcept {
  ls = std::max((b - a).norm(), (c - a).norm());
  lt = s1 * (c - b).norm();
}

// Parameter cell of one patch.
struct Cell {
  double s0, s1, t0, t1;
};

// The surface of a convex shape as patches (see the file comment).
class ConvexSurface {
 public:
  explicit ConvexSurface(const Shape& shape) noexcept : shape_(shape) {}

  int patchCount() const noexcept {
    switch (shape_.type()) {
      case ShapeType::Box:
        return 26;  // 6 faces, 12 edges, 8 vertices
      case ShapeType::Cylinder:
        return 5;  // side, 2 caps, 2 rims
      case ShapeType::Ellipsoid:
        return 6;  // cube-sphere faces
      case ShapeType::TriangleShape:
        return 7;  // face, 3 edges, 3 vertices
      default: {
        const Mesh& m = hull().mesh();
        return static_cast<int>(4 * m.triangles.size() + m.positions.size());
      }
    }
  }

  // 2 face, 1 edge, 0 vertex; −1 for a patch to skip (a hull edge met from
  // its second triangle).
  int dim(int patch) const noexcept {
    switch (shape_.type()) {
      case ShapeType::Box:
        return patch < 6 ? 2 : patch < 18 ? 1 : 0;
      case ShapeType::Cylinder:
        return patch < 3 ? 2 : 1;
      case ShapeType::Ellipsoid:
        return 2;
      case ShapeType::TriangleShape:
        return patch < 1 ? 2 : patch < 4 ? 1 : 0;
      default: {
        const Mesh& m = hull().mesh();
        const int f = static_cast<int>(m.triangles.size());
        if (patch < f) return 2;
        if (patch < 4 * f) {
          const auto& tri = m.triangles[(patch - f) / 3];
          const int e = (patch - f) % 3;
          return tri[e] < tri[(e + 1) % 3] ? 1 : -1;
        }
        return 0;
      }
    }
  }

  Vec3 eval(int patch, double s, double t) const noexcept {
    switch (shape_.type()) {
      case ShapeType::Box:
        return boxPoint(patch, s, t);
      case ShapeType::Cylinder:
        return cylinderPoint(patch, s, t);
      case ShapeType::Ellipsoid:
        return ellipsoidPoint(patch, s, t);
      case ShapeType::TriangleShape: {
        const auto& tri = static_cast<const TriangleShape&>(shape_);
        return polygonPoint(tri.vertex(0), tri.vertex(1), tri.vertex(2), patch - 1, patch - 4, s, t);
      }
      default: {
        const Mesh& m = hull().mesh();
        const int f = static_cast<int>(m.triangles.size());
        if (patch >= 4 * f) return m.positions[patch - 4 * f];
        const auto& tri = m.triangles[patch < f ? patch : (patch - f) / 3];
        const Vec3 &a = m.positions[tri[0]], &b = m.positions[tri[1]], &c = m.positions[tri[2]];
        return polygonPoint(a, b, c, patch < f ? -1 : (patch - f) % 3, -1, s, t);
      }
    }
  }

  // Ls, Lt over the cell (see the file comment).
  void bounds(int patch, const Cell& c, double& ls, double& lt) const noexcept {
    ls = lt = 0.0;
    switch (shape_.type()) {
      case ShapeType::Box: {
        const Vec3& h = static_cast<const Box&>(shape_).halfExtents();
        if (patch < 6) {
          const int a = patch / 2;
          ls = 2 * h[(a + 1) % 3], lt = 2 * h[(a + 2) % 3];
        } else if (patch < 18) {
          ls = 2 * h[(patch - 6) / 4];
        }
        return;
      }
      case ShapeType::Cylinder: {
        const auto& cyl = static_cast<const Cylinder&>(shape_);
        if (patch == 0)
          ls = kTwoPi * cyl.radius(), lt = 2 * cyl.halfLength();
        else if (patch < 3)
          ls = cyl.radius(), lt = kTwoPi * cyl.radius() * c.s1;
        else
          ls = kTwoPi * cyl.radius();
        return;
      }
      case ShapeType::Ellipsoid: {
        // p = r∘q/|q| with q on a cube face: |d(q/|q|)/dq| = 1/|q|, dq/ds = 2.
        const double rmax = static_cast<const Ellipsoid&>(shape_).radii().cwiseAbs().maxCoeff();
        const double qmin =
            std::sqrt(1.0 + minSquare(2 * c.s0 - 1, 2 * c.s1 - 1) + minSquare(2 * c.t0 - 1, 2 * c.t1 - 1));
        ls = lt = 2 * rmax / qmin;
        return;
      }
      case ShapeType::TriangleShape: {
        const auto& tri = static_cast<const TriangleShape&>(shape_);
        polygonBounds(tri.vertex(0), tri.vertex(1), tri.vertex(2), patch - 1, patch - 4, c, ls, lt);
        return;
      }
      default: {
        const Mesh& m = hull().mesh();
        const int f = static_cast<int>(m.triangles.size());
        if (patch >= 4 * f) return;
        const auto& tri = m.triangles[patch < f ? patch : (patch - f) / 3];
        polygonBounds(m.positions[tri[0]], m.positions[tri[1]], m.positions[tri[2]],
                      patch < f ? -1 : (patch - f) % 3, -1, c, ls, lt);
        return;
      }
    }
  }

  // Lower bound of the shape's signed distance at local point p (m, < 0
  // inside): exact for box and cylinder and for a hull inside, ≤ the true
  // distance outside, and inside ≥ −(true depth), so −value never overstates
  // the depth. Triangles have no interior (+∞).
  double signedDistanceBound(const Vec3& p) const noexcept {
    switch (shape_.type()) {
      case ShapeType::Box:
        return detail::boxSignedDistance(p, static_cast<const Box&>(shape_).halfExtents());
      case ShapeType::Cylinder: {
        const auto& cyl = static_cast<const Cylinder&>(shape_);
        return detail::cylinderSignedDistance(p, cyl.radius(), cyl.halfLength());
      }
      case ShapeType::Ellipsoid: {
        // f = |p/r| has Lipschitz bound 1/rmin and is 1 on the surface, so
        // rmin·(f − 1) bounds the distance from below outside and the depth
        // from below inside. Outside, the support plane with normal
        // n ∝ p/r² (the surface normal where the ray to p exits) is a
        // separating plane: n·p − |r∘n| is a lower bound too, nearly exact.
        const Vec3& r = static_cast<const Ellipsoid&>(shape_).radii();
        const double f = p.cwiseQuotient(r).norm();
        const double scaled = r.cwiseAbs().minCoeff() * (f - 1.0);
        if (f <= 1.0) return scaled;
        const Vec3 n = p.cwiseQuotient(r.cwiseProduct(r)).normalized();
        return std::max(scaled, n.dot(p) - r.cwiseProduct(n).norm());
      }
      case ShapeType::TriangleShape:
        return kInf;
      default: {
        const Mesh& m = hull().mesh();
        double best = -kInf;
        for (const auto& tri : m.triangles) {
          const Vec3& a = m.positions[tri[0]];
          const Vec3 n = (m.positions[tri[1]] - a).cross(m.positions[tri[2]] - a);
          const double len = n.norm();
          if (len > 0) best = std::max(best, n.dot(p - a) / len);
        }
        return best;
      }
    }
  }

  bool hasInterior() const noexcept { return shape_.type() != ShapeType::TriangleShape; }
  Aabb localAabb() const noexcept { return shape_.localAabb(); }

 private:
  const ConvexHull& hull() const noexcept { return static_cast<const ConvexHull&>(shape_); }

  Vec3 boxPoint(int patch, double s, double t) const noexcept {
    const Vec3& h = static_cast<const Box&>(shape_).halfExtents();
    Vec3 p;
    if (patch < 6) {
      const int a = patch / 2;
      p[a] = patch % 2 ? h[a] : -h[a];
      p[(a + 1) % 3] = (2 * s - 1) * h[(a + 1) % 3];
      p[(a + 2) % 3] = (2 * t - 1) * h[(a + 2) % 3];
    } else if (patch < 18) {
      const int e = patch - 6, a = e / 4;
      p[a] = (2 * s - 1) * h[a];
      p[(a + 1) % 3] = e & 1 ? h[(a + 1) % 3] : -h[(a + 1) % 3];
      p[(a + 2) % 3] = e & 2 ? h[(a + 2) % 3] : -h[(a + 2) % 3];
    } else {
      const int v = patch - 18;
      p = Vec3(v & 1 ? h.x() : -h.x(), v & 2 ? h.y() : -h.y(), v & 4 ? h.z() : -h.z());
    }
    return p;
  }

  Vec3 cylinderPoint(int patch, double s, double t) const noexcept {
    const auto& cyl = static_cast<const Cylinder&>(shape_);
    const double r = cyl.radius(), h = cyl.halfLength();
    if (patch == 0) return {r * std::cos(kTwoPi * s), r * std::sin(kTwoPi * s), (2 * t - 1) * h};
    if (patch < 3) return {s * r * std::cos(kTwoPi * t), s * r * std::sin(kTwoPi * t), patch == 1 ? -h : h};
    return {r * std::cos(kTwoPi * s), r * std::sin(kTwoPi * s), patch == 3 ? -h : h};
  }

  Vec3 ellipsoidPoint(int patch, double s, double t) const noexcept {
    const int a = patch / 2;
    Vec3 q;
    q[a] = patch % 2 ? 1.0 : -1.0;
    q[(a + 1) % 3] = 2 * s - 1;
    q[(a + 2) % 3] = 2 * t - 1;
    return static_cast<const Ellipsoid&>(shape_).radii().cwiseProduct(q / q.norm());
  }

  // Triangle (a, b, c): its face (edge < 0 and vertex < 0), edge `edge`
  // (from vertex edge to edge + 1) or vertex `vertex`.
  static Vec3 polygonPoint(const Vec3& a, const Vec3& b, const Vec3& c, int edge, int vertex, double s,
                           double t) noexcept {
    const Vec3* v[3] = {&a, &b, &c};
    if (vertex >= 0) return *v[vertex];
    if (edge >= 0) return *v[edge] + s * (*v[(edge + 1) % 3] - *v[edge]);
    return trianglePoint(a, b, c, s, t);
  }
  static void polygonBounds(const Vec3& a, const Vec3& b, const Vec3& c, int edge, int vertex,
                            const Cell& cell, double& ls, double& lt) noexcept {
    const Vec3* v[3] = {&a, &b, &c};
    if (vertex >= 0) return;
    if (edge >= 0) {
      ls = (*v[(edge + 1) % 3] - *v[edge]).norm();
      return;
    }
    triangleBounds(a, b, c, cell.s1, ls, lt);
  }

  const Shape& shape_;
};

// The pair in the model's frame.
struct VoxelConvexPair {
  const Shape& shape;
  ConvexSurface surface;
  Isometry3 toModel;  // shape frame → model frame
  const VoxelModel& model;
  double spacing;  // sample spacing h, m

  VoxelConvexPair(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb) noexcept
      : shape(a),
        surface(a),
        toModel(pb.inverse() * pa),
        model(modelOf(b)),
        spacing(model.indexToWorld().linear().colwise().norm().minCoeff()) {}

  // Visits every surface sample whose distance may be ≤ `cutoff` (which
  // `visit(p, d, g)` may lower; it returns false to stop): model-frame
  // point, distance, gradient. Returns false when stopped.
  // With kGradient false the gradient passed is zero (cheaper samples).
  template <bool kGradient, class Visit>
  bool walk(double& cutoff, Visit&& visit) const noexcept {
    const double k = model.lipschitz();
    // Whole-shape prune by the bounding sphere.
    const BoundingSphere bs = shape.boundingSphere();
    if (!(model.distance(toModel * bs.center) - k * bs.radius <= cutoff)) return true;
    Cell stack[kCellStackSize];
    const int patches = surface.patchCount();
    for (int patch = 0; patch < patches; ++patch) {
      const int dim = surface.dim(patch);
      if (dim < 0) continue;
      int top = 0;
      stack[top++] = {0.0, 1.0, 0.0, 1.0};
      while (top > 0) {
        const Cell c = stack[--top];
        double ls = 0, lt = 0;
        surface.bounds(patch, c, ls, lt);
        const double es = dim >= 1 ? ls * (c.s1 - c.s0) : 0.0;
        const double et = dim == 2 ? lt * (c.t1 - c.t0) : 0.0;
        const double sm = 0.5 * (c.s0 + c.s1), tm = 0.5 * (c.t0 + c.t1);
        const Vec3 p = toModel * surface.eval(patch, sm, tm);
        const double d = model.distance(p);
        if (!(d - k * 0.5 * (es + et) <= cutoff)) continue;
        if ((es <= spacing && et <= spacing) || top + 2 > kCellStackSize) {
          Vec3 g = Vec3::Zero();
          const double dl = kGradient ? model.distance(p, g) : d;
          if (!visit(p, dl, g)) return false;
          continue;
        }
        if (es >= et) {
          stack[top++] = {sm, c.s1, c.t0, c.t1};
          stack[top++] = {c.s0, sm, c.t0, c.t1};
        } else {
          stack[top++] = {c.s0, c.s1, tm, c.t1};
          stack[top++] = {c.s0, c.s1, c.t0, tm};
        }
      }
    }
    return true;
  }

  // A point (shape frame) inside both the shape and the model's solid, by
  // the pruned octree of the file comment; false when none is found down to
  // cells of one voxel.
  bool engulfed(Vec3& found) const noexcept {
    if (!surface.hasInterior()) return false;
    const double k = model.lipschitz();
    struct Box3 {
      Vec3 center, half;
    };
    Box3 stack[kCellStackSize];
    int top = 0;
    const Aabb box = surface.localAabb();
    stack[top++] = {box.center(), 0.5 * box.sizes()};
    while (top > 0) {
      const Box3 c = stack[--top];
      const double r = c.half.norm();
      const double dm = model.distance(toModel * c.center);
      if (!(dm - k * r <= 0)) continue;
      const double ds = surface.signedDistanceBound(c.center);
      if (!(ds <= r)) continue;
      if (ds <= 0 && dm <= 0) {
        found = c.center;
        return true;
      }
      int axis = 0;
      const double longest = c.half.maxCoeff(&axis);
      if (longest < 0.5 * spacing || top + 2 > kCellStackSize) continue;
      Box3 lo = c, hi = c;
      lo.half[axis] = hi.half[axis] = 0.5 * longest;
      lo.center[axis] -= 0.5 * longest;
      hi.center[axis] += 0.5 * longest;
      stack[top++] = hi;
      stack[top++] = lo;
    }
    return false;
  }

  // Outward unit normal of the shape nearest to local point p (central
  // differences of the signed-distance bound, exact where it is exact).
  Vec3 shapeNormal(const Vec3& p) const noexcept {
    const double e = 1e-3 * spacing;
    Vec3 g;
    for (int i = 0; i < 3; ++i) {
      const Vec3 u = e * Vec3::Unit(i);
      g[i] = surface.signedDistanceBound(p + u) - surface.signedDistanceBound(p - u);
    }
    const double n = g.norm();
    return n > 0 && std::isfinite(n) ? Vec3(g / n) : Vec3::UnitZ();
  }
};

// World direction from A's origin to world point x (unit; +z if they coincide).
Vec3 outwardGuess(const Isometry3& pa, const Vec3& x) noexcept {
  const Vec3 v = x - pa.translation();
  return v.squaredNorm() > 0 ? Vec3(v.normalized()) : Vec3::UnitZ();
}

bool convexModelHit(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                    PairCache*) noexcept {
  const VoxelConvexPair pair(a, pa, b, pb);
  double cutoff = 0.0;
  if (!pair.walk<false>(cutoff, [](const Vec3&, double d, const Vec3&) { return !(d <= 0); })) return true;
  Vec3 inside;
  return pair.engulfed(inside);
}

// The engulfed answer (see the file comment) at shape-frame point q: world
// point, normal A → B and depth.
detail::SignedContact engulfedContact(const VoxelConvexPair& pair, const Isometry3& pa,
                                      const Vec3& q) noexcept {
  detail::SignedContact s;
  s.normal = pa.linear() * pair.shapeNormal(q);
  s.distance = std::min(0.0, pair.surface.signedDistanceBound(q));
  s.pointB = pa * q;
  s.pointA = s.pointB - s.distance * s.normal;
  return s;
}

void convexModelContacts(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                         const CollisionRequest& req, CollisionResult& out, PairCache*) {
  const VoxelConvexPair pair(a, pa, b, pb);
  const std::size_t first = out.contacts.size();
  bool any = false;
  double cutoff = 0.0;
  pair.walk<true>(cutoff, [&](const Vec3& p, double d, const Vec3& g) {
    if (!(d <= 0)) return true;
    any = true;
    out.colliding = true;
    if (!req.contacts) return false;
    const Vec3 x = pb * p;
    const Vec3 n = normalFromGradient(pb, g, outwardGuess(pa, x));
    // x is on A's surface; B's surface lies |d| along −n from it.
    out.contacts.push_back({x + 0.5 * d * n, n, -d});
    return true;
  });
  if (any) {
    detail::reduceContacts(out, first, req.maxContacts);
    return;
  }
  Vec3 q;
  if (pair.engulfed(q)) detail::appendContact(engulfedContact(pair, pa, q), req, out);
}

DistanceResult convexModelDist(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                               PairCache*) noexcept {
  const VoxelConvexPair pair(a, pa, b, pb);
  DistanceResult r;
  double best = kInf;
  Vec3 bestP = Vec3::Zero(), bestG = Vec3::Zero();
  pair.walk<true>(best, [&](const Vec3& p, double d, const Vec3& g) {
    if (d < best) best = d, bestP = p, bestG = g;
    return true;
  });
  if (!(best <= 0)) {
    Vec3 q;
    if (pair.engulfed(q)) return detail::toDistanceResult(engulfedContact(pair, pa, q));
  }
  if (!std::isfinite(best)) return r;  // NaN: non-finite pose
  const Vec3 x = pb * bestP;
  const Vec3 n = normalFromGradient(pb, bestG, outwardGuess(pa, x));
  r.distance = best;
  r.pointA = x;
  r.pointB = x + best * n;
  return r;
}

}  // namespace

namespace detail {

void registerVoxelConvexColliders(ColliderTable& table) {
  const Collider c{&convexModelHit, &convexModelContacts, &convexModelDist};
  for (ShapeType t : {ShapeType::Box, ShapeType::Cylinder, ShapeType::Ellipsoid, ShapeType::ConvexHull,
                      ShapeType::TriangleShape}) {
    const Status s = table.registerCollider(t, ShapeType::VoxelModel, c);
    DM_DEMAND(s.ok(), "built-in collider registration");
  }
}

}  // namespace detail
}  // namespace dm
