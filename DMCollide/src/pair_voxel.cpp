// Voxel-model pairs of the collider table: the Voxmap–PointShell contact
// (point shell against voxel model), round shapes (point, segment, sphere,
// capsule) against voxel models, the voxel-model raycaster and
// dm::voxmapPenalty(); see dm/collide/voxel_model.hpp.
//
// Box, cylinder, ellipsoid, hull and triangle against a voxel model are in
// pair_voxel_convex.cpp. Meshes, planes and voxel models have no collider:
// sample them into a PointShell (PointShell::fromMesh(...)) and collide that.
//
// All functions here are real-time safe: no allocation (contacts append to
// the caller's vector, whose capacity it keeps between calls), no lock, no
// throw.
#include <dm/collide/point_shell.hpp>
#include <dm/collide/voxel_model.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

#include "collide_internal.hpp"
#include "pair_colliders.hpp"

namespace dm {

namespace {

using detail::kInf;
using detail::modelOf;
using detail::normalFromGradient;

// Depth-first walk over the shell's sphere hierarchy that visits, in the
// model's frame, every point whose distance may be ≤ `cutoff`: a node whose
// centre has distance dc is skipped when dc − K·radius > cutoff, K being the
// model's Lipschitz bound. `visit(k, p, d, g)` gets the point index, its
// position and distance/gradient in the model's frame and returns false to
// stop; it may lower `cutoff`.
template <class Visit>
void walkShell(const PointShell& shell, const Isometry3& shellToModel, const VoxelModel& model,
               double& cutoff, Visit&& visit) noexcept {
  const auto nodes = shell.nodes();
  const auto points = shell.points();
  const double k = model.lipschitz();
  std::uint32_t stack[2 * PointShell::kMaxDepth + 2];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const PointShellNode& node = nodes[stack[--top]];
    const double dc = model.distance(shellToModel * node.center);
    if (!(dc - k * node.radius <= cutoff)) continue;
    if (!node.isLeaf()) {
      stack[top++] = node.first + 1;
      stack[top++] = node.first;
      continue;
    }
    for (std::uint32_t i = node.first; i < node.first + node.count; ++i) {
      const Vec3 p = shellToModel * points[i];
      Vec3 g;
      const double d = model.distance(p, g);
      if (!visit(i, p, d, g)) return;
    }
  }
}

// --- point shell (A) – voxel model (B) -------------------------------------

bool shellModelHit(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                   PairCache*) noexcept {
  bool hit = false;
  double cutoff = 0.0;
  walkShell(static_cast<const PointShell&>(a), pb.inverse() * pa, modelOf(b), cutoff,
            [&](std::uint32_t, const Vec3&, double d, const Vec3&) {
              hit = d <= 0;
              return !hit;
            });
  return hit;
}

void shellModelContacts(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                        const CollisionRequest& req, CollisionResult& out, PairCache*) {
  const auto& shell = static_cast<const PointShell&>(a);
  const std::size_t first = out.contacts.size();
  double cutoff = 0.0;
  walkShell(shell, pb.inverse() * pa, modelOf(b), cutoff,
            [&](std::uint32_t i, const Vec3& p, double d, const Vec3& g) {
              if (!(d <= 0)) return true;
              out.colliding = true;
              if (!req.contacts) return false;
              const Vec3 n = normalFromGradient(pb, g, pa.linear() * shell.normals()[i]);
              // p is on A's surface; B's surface lies |d| along −n from it.
              out.contacts.push_back({pb * p + 0.5 * d * n, n, -d});
              return true;
            });
  detail::reduceContacts(out, first, req.maxContacts);
}

DistanceResult shellModelDist(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                              PairCache*) noexcept {
  const auto& shell = static_cast<const PointShell&>(a);
  DistanceResult r;
  double best = kInf;
  std::uint32_t bestIndex = 0;
  Vec3 bestP = Vec3::Zero(), bestG = Vec3::Zero();
  walkShell(shell, pb.inverse() * pa, modelOf(b), best,
            [&](std::uint32_t i, const Vec3& p, double d, const Vec3& g) {
              if (d < best) best = d, bestIndex = i, bestP = p, bestG = g;
              return true;
            });
  if (!std::isfinite(best)) return r;  // NaN: non-finite pose
  const Vec3 n = normalFromGradient(pb, bestG, pa.linear() * shell.normals()[bestIndex]);
  r.distance = best;
  r.pointA = pb * bestP;
  r.pointB = r.pointA + best * n;
  return r;
}

// --- round shapes (A: point, segment, sphere, capsule) – voxel model (B) ----

struct RoundCore {
  Vec3 p0, p1;  // core segment in B's frame
  double radius;
};

RoundCore roundCore(const Shape& a, const Isometry3& aToB) noexcept {
  switch (a.type()) {
    case ShapeType::Point: {
      const Vec3 p = aToB * static_cast<const Point&>(a).position();
      return {p, p, 0.0};
    }
    case ShapeType::Segment: {
      const auto& s = static_cast<const Segment&>(a);
      return {aToB * s.a(), aToB * s.b(), 0.0};
    }
    case ShapeType::Sphere:
      return {aToB.translation(), aToB.translation(), static_cast<const Sphere&>(a).radius()};
    default: {
      const auto& c = static_cast<const Capsule&>(a);
      const Vec3 h = aToB.linear().col(2) * c.halfLength();
      return {aToB.translation() - h, aToB.translation() + h, c.radius()};
    }
  }
}

// Deepest (smallest-distance) point of the core segment in the model, model
// frame: a march along the segment that skips, by the Lipschitz bound, the
// stretches that cannot beat the best so far (at least half a voxel per
// step), then a golden-section refinement around the best sample. Exact to
// the refinement tolerance where the minimum is the only one within half a
// voxel of the best sample; O(length / voxel) in the worst case.
struct CoreMin {
  Vec3 point;
  double distance;
  Vec3 gradient;
};

CoreMin coreMinimum(const VoxelModel& model, const RoundCore& core) noexcept {
  const Vec3 axis = core.p1 - core.p0;
  const double len = axis.norm();
  CoreMin best{core.p0, 0.0, Vec3::Zero()};
  best.distance = model.distance(core.p0, best.gradient);
  if (!(len > 0) || !std::isfinite(best.distance)) return best;
  const Vec3 dir = axis / len;
  const Vec3 spacing = model.indexToWorld().linear().colwise().norm().transpose();
  const double maxStep = 0.5 * spacing.minCoeff();
  const double k = model.lipschitz();
  double bestT = 0.0;
  for (double t = 0.0; t < len;) {
    const double d = model.distance(core.p0 + t * dir);
    if (d < best.distance) best.distance = d, bestT = t;
    t += std::max(maxStep, (d - best.distance) / k);
    if (t >= len) {
      const double de = model.distance(core.p1);
      if (de < best.distance) best.distance = de, bestT = len;
    }
  }
  double lo = std::max(0.0, bestT - maxStep), hi = std::min(len, bestT + maxStep);
  constexpr double kGolden = 0.6180339887498949;
  double x1 = hi - kGolden * (hi - lo), x2 = lo + kGolden * (hi - lo);
  double f1 = model.distance(core.p0 + x1 * dir), f2 = model.distance(core.p0 + x2 * dir);
  for (int it = 0; it < 40 && hi - lo > 1e-7 * maxStep; ++it) {
    if (f1 < f2) {
      hi = x2, x2 = x1, f2 = f1;
      x1 = hi - kGolden * (hi - lo);
      f1 = model.distance(core.p0 + x1 * dir);
    } else {
      lo = x1, x1 = x2, f1 = f2;
      x2 = lo + kGolden * (hi - lo);
      f2 = model.distance(core.p0 + x2 * dir);
    }
  }
  const double tRefined = f1 < f2 ? x1 : x2;
  if (std::min(f1, f2) < best.distance) bestT = tRefined;
  best.point = core.p0 + bestT * dir;
  best.distance = model.distance(best.point, best.gradient);
  return best;
}

detail::SignedContact roundModel(const Shape& a, const Isometry3& pa, const Shape& b,
                                 const Isometry3& pb) noexcept {
  const VoxelModel& model = modelOf(b);
  const RoundCore core = roundCore(a, pb.inverse() * pa);
  const CoreMin m = coreMinimum(model, core);
  detail::SignedContact s;
  const Vec3 c = pb * m.point;
  const Vec3 toModel = pb * model.localAabb().center() - c;
  const Vec3 fallback = toModel.squaredNorm() > 0 ? Vec3(toModel.normalized()) : Vec3::UnitZ();
  s.normal = normalFromGradient(pb, m.gradient, fallback);
  s.distance = m.distance - core.radius;
  s.pointA = c + core.radius * s.normal;
  s.pointB = c + m.distance * s.normal;
  return s;
}

std::optional<RayHit> rayModel(const Shape& s, const Ray& ray) { return modelOf(s).raycast(ray); }

}  // namespace

VoxmapPenalty voxmapPenalty(const PointShell& shell, const Isometry3& poseShell, const VoxelModel& model,
                            const Isometry3& poseModel) noexcept {
  VoxmapPenalty sum;
  double cutoff = 0.0;
  walkShell(shell, poseModel.inverse() * poseShell, model, cutoff,
            [&](std::uint32_t i, const Vec3& p, double d, const Vec3& g) {
              if (!(d <= 0)) return true;
              const Vec3 n = normalFromGradient(poseModel, g, poseShell.linear() * shell.normals()[i]);
              const Vec3 f = -d * n;
              ++sum.count;
              sum.maxDepth = std::max(sum.maxDepth, -d);
              sum.force += f;
              sum.torque += (poseModel * p - poseShell.translation()).cross(-f);
              return true;
            });
  return sum;
}

namespace detail {

void registerVoxelColliders(ColliderTable& table) {
  auto reg = [&](ShapeType x, ShapeType y, const Collider& c) {
    const Status s = table.registerCollider(x, y, c);
    DM_DEMAND(s.ok(), "built-in collider registration");
  };
  reg(ShapeType::PointShell, ShapeType::VoxelModel, {&shellModelHit, &shellModelContacts, &shellModelDist});
  const Collider round = analyticCollider<&roundModel>();
  for (ShapeType t : {ShapeType::Point, ShapeType::Segment, ShapeType::Sphere, ShapeType::Capsule})
    reg(t, ShapeType::VoxelModel, round);
  DM_DEMAND(table.registerRaycaster(ShapeType::VoxelModel, &rayModel).ok(),
            "built-in raycaster registration");
}

}  // namespace detail
}  // namespace dm
