// The god-object renderer (dm/haptics/god_object.hpp): constrained proxy
// motion by swept casts and a closed-form active-set solve, friction cone,
// two-pass force shading, moving objects.
#include <dm/collide/mesh_query.hpp>
#include <dm/collide/toi.hpp>
#include <dm/haptics/god_object.hpp>
#include <dm/math/geometry.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <string>
#include <utility>

namespace dm {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Closest point to `goal` on the intersection of the k planes in `idx`
// treated as equalities: goal + Σ λ_i n_i with the Gram system G λ = rhs.
// False when the planes are (nearly) dependent.
bool projectOnPlanes(const Vec3& goal, const GodObjectRenderer::Plane* planes, const int* idx, int k,
                     double* lambda, Vec3& out) noexcept {
  if (k == 0) {
    out = goal;
    return true;
  }
  Eigen::Matrix3d g = Eigen::Matrix3d::Identity();
  Vec3 rhs = Vec3::Zero();
  for (int i = 0; i < k; ++i) {
    rhs[i] = planes[idx[i]].offset - planes[idx[i]].normal.dot(goal);
    for (int j = 0; j < k; ++j) g(i, j) = planes[idx[i]].normal.dot(planes[idx[j]].normal);
  }
  Vec3 l = Vec3::Zero();
  if (k == 1) {
    l[0] = rhs[0];
  } else if (k == 2) {
    const double det = g(0, 0) * g(1, 1) - g(0, 1) * g(1, 0);
    if (!(det > 1e-10)) return false;
    l[0] = (g(1, 1) * rhs[0] - g(0, 1) * rhs[1]) / det;
    l[1] = (g(0, 0) * rhs[1] - g(1, 0) * rhs[0]) / det;
  } else {
    const double det = g.determinant();
    if (!(std::abs(det) > 1e-12)) return false;
    l = g.inverse() * rhs;
  }
  out = goal;
  for (int i = 0; i < k; ++i) {
    lambda[i] = l[i];
    out += l[i] * planes[idx[i]].normal;
  }
  return true;
}

// The proxy at the first contact of a sweep from → to at fraction t, moved
// back along the motion so that it stays `skin` off the plane of normal n
// (facing the proxy), but never behind `from`.
Vec3 stopBefore(const Vec3& from, const Vec3& to, double t, const Vec3& n, double skin) noexcept {
  const Vec3 d = to - from;
  const double len = d.norm();
  if (!(len > 0)) return from;
  const double approach = std::max(-n.dot(d) / len, 1e-6);
  const double along = std::max(t * len - skin / approach, 0.0);
  return from + d * (along / len);
}

}  // namespace

bool GodObjectRenderer::solveConstraints(const Vec3& goal, Plane* planes, int& count, double* lambda,
                                         Vec3& out) noexcept {
  constexpr double kFeasTol = 1e-10;  // m
  double bestDist = kInf;
  int bestIdx[3] = {0, 0, 0};
  int bestK = -1;
  double bestLambda[3] = {0, 0, 0};
  Vec3 best = goal;
  for (unsigned mask = 0; mask < (1u << count); ++mask) {
    const int k = std::popcount(mask);
    if (k > 3) continue;
    int idx[3] = {0, 0, 0};
    int m = 0;
    for (int i = 0; i < count; ++i)
      if (mask & (1u << i)) idx[m++] = i;
    double l[3] = {0, 0, 0};
    Vec3 x;
    if (!projectOnPlanes(goal, planes, idx, k, l, x)) continue;
    bool okay = true;
    for (int i = 0; i < k && okay; ++i) okay = l[i] >= -1e-12;
    for (int j = 0; j < count && okay; ++j) okay = planes[j].normal.dot(x) >= planes[j].offset - kFeasTol;
    if (!okay) continue;
    const double dist = (x - goal).squaredNorm();
    // Ties (a plane through the optimum with zero load): the smaller set.
    if (dist < bestDist - 1e-24 || (dist <= bestDist + 1e-24 && bestK >= 0 && k < bestK)) {
      bestDist = dist;
      bestK = k;
      best = x;
      for (int i = 0; i < 3; ++i) {
        bestIdx[i] = idx[i];
        bestLambda[i] = l[i];
      }
    }
  }
  if (bestK < 0) return false;
  Plane active[3];
  int n = 0;
  for (int i = 0; i < bestK; ++i) {
    if (bestLambda[i] > 0) {
      active[n] = planes[bestIdx[i]];
      lambda[n] = bestLambda[i];
      ++n;
    }
  }
  for (int i = 0; i < n; ++i) planes[i] = active[i];
  count = n;
  out = best;
  return true;
}

Result<std::unique_ptr<GodObjectRenderer>> GodObjectRenderer::create(std::vector<GodObjectObject> objects,
                                                                     const GodObjectOptions& options) {
  const auto bad = [](const std::string& what, const std::string& where, const char* hint) {
    return fail(ErrorCode::InvalidArgument, what, where, hint);
  };
  if (!std::isfinite(options.proxyRadius) || options.proxyRadius < 0)
    return bad(formatString("proxyRadius is %g m; it must be finite and >= 0", options.proxyRadius),
               "GodObjectOptions.proxyRadius", "use 0 for a point proxy");
  if (!std::isfinite(options.skin) || options.skin <= 0 || options.skin > 1e-3)
    return bad(formatString("skin is %g m; it must be in (0, 1e-3]", options.skin), "GodObjectOptions.skin",
               "keep the default 1e-6 m");
  if (options.maxIterations < 1 || options.maxIterations > 64)
    return bad(formatString("maxIterations is %d; it must be in [1, 64]", options.maxIterations),
               "GodObjectOptions.maxIterations", "8 is plenty for three constraint planes");
  if (std::isnan(options.maxForce) || options.maxForce <= 0)
    return bad(formatString("maxForce is %g N; it must be > 0 (may be +inf)", options.maxForce),
               "GodObjectOptions.maxForce", "use the device's peak force");
  if (objects.empty()) return bad("no objects", "objects", "give at least one GodObjectObject");
  if (objects.size() > 0xffffffffu) return bad("too many objects", "objects", "use fewer than 2^32 objects");

  std::vector<ObjectState> states;
  states.reserve(objects.size());
  for (std::size_t i = 0; i < objects.size(); ++i) {
    GodObjectObject& o = objects[i];
    const std::string at = formatString("objects[%zu]", i);
    if (!o.bvh) return bad("the BVH is null", at + ".bvh", "build it with dm::MeshBvh::build(mesh)");
    if (o.bvh->triangleCount() == 0)
      return bad("the BVH has no triangles", at + ".bvh", "give a non-empty mesh");
    if (!isRigidPose(o.pose))
      return bad("the pose is not finite or not a rotation plus translation", at + ".pose",
                 "give a rigid local-to-world transform");
    if (Status s = o.material.validate(at + ".material"); !s) return s.error();
    ObjectState st;
    st.bvh = o.bvh;
    st.tree = st.bvh.get();
    st.pose = o.pose;
    st.pendingPose = o.pose;
    st.material = o.material;
    if (!o.vertexNormals.empty()) {
      if (o.vertexNormals.size() != o.bvh->vertexCount())
        return bad(
            formatString("%zu vertex normals for %zu vertices", o.vertexNormals.size(), o.bvh->vertexCount()),
            at + ".vertexNormals", "give one normal per mesh vertex, or none");
      for (std::size_t v = 0; v < o.vertexNormals.size(); ++v) {
        const double len = o.vertexNormals[v].norm();
        if (!std::isfinite(len) || len < 1e-12)
          return bad("vertex normal is zero or not finite",
                     formatString("%s.vertexNormals[%zu]", at.c_str(), v), "give unit normals");
        o.vertexNormals[v] /= len;
      }
      st.vertexNormals = std::move(o.vertexNormals);
    }
    st.shaded = options.forceShading && (!st.vertexNormals.empty() || st.bvh->isClosed());
    // Mesh triangle → leaf order, for shading and for carrying a proxy with
    // a deforming surface (refit keeps the leaf order).
    st.leafOf.resize(st.bvh->triangleCount());
    for (std::uint32_t k = 0; k < st.bvh->triangleCount(); ++k) st.leafOf[st.bvh->originalTriangle(k)] = k;
    states.push_back(std::move(st));
  }
  return std::unique_ptr<GodObjectRenderer>(new GodObjectRenderer(std::move(states), options));
}

GodObjectRenderer::GodObjectRenderer(std::vector<ObjectState> objects,
                                     const GodObjectOptions& options) noexcept
    : objects_(std::move(objects)), options_(options) {}

void GodObjectRenderer::reset(const Isometry3& devicePose) noexcept {
  if (devicePose.translation().allFinite()) proxy_ = devicePose.translation();
  // A device point inside (or within the tip radius of) a closed object puts
  // the proxy on the object's nearest surface point instead, just outside,
  // so the proxy starts where it could have got to without penetrating.
  // A few rounds settle overlapping objects.
  for (int round = 0; round < 4; ++round) {
    bool moved = false;
    for (const ObjectState& o : objects_) moved |= pushOutOf(o);
    if (!moved) break;
  }
  inContact_ = false;
  sliding_ = false;
  contactObject_ = 0;
  contact_ = {};
  planeCount_ = 0;
}

void GodObjectRenderer::setObjectPose(std::size_t index, const Isometry3& pose) noexcept {
  if (index >= objects_.size() || !isRigidPose(pose)) return;
  objects_[index].pendingPose = pose;
  objects_[index].posePending = true;
}

bool GodObjectRenderer::deformObject(std::size_t index, const MeshBvh* tree) noexcept {
  if (index >= objects_.size() || tree == nullptr) return false;
  ObjectState& o = objects_[index];
  if (!o.vertexNormals.empty() || tree->triangleCount() != o.bvh->triangleCount() ||
      tree->vertexCount() != o.bvh->vertexCount())
    return false;
  // The previous tree is not read again: the contact was recorded by value
  // at the end of the last tick (its owner may already be rewriting it).
  o.tree = tree;
  if (inContact_ && index == contactObject_ && contact_.triangle < o.leafOf.size()) {
    // Carried with the surface: the touched point keeps its barycentric
    // coordinates on its triangle, and the proxy's offset from it turns
    // with the triangle's normal.
    const Vec3* c = tree->corners(o.leafOf[contact_.triangle]);
    const Vec3& bc = contact_.barycentric;
    const Vec3 moved = bc[0] * c[0] + bc[1] * c[1] + bc[2] * c[2];
    const Vec3 n1 = (c[1] - c[0]).cross(c[2] - c[0]);
    Vec3 offset = contactOffset_;
    if (contactFaceNormal_.squaredNorm() > 0 && n1.squaredNorm() > 0)
      offset = Eigen::Quaterniond::FromTwoVectors(contactFaceNormal_, n1) * offset;
    proxy_ = o.pose * (moved + offset);
    contact_.point = o.pose * moved;
    recordContactGeometry();
    return true;
  }
  // A free proxy the surface moved over is put back just outside, as
  // reset() does.
  pushOutOf(o);
  return true;
}

bool GodObjectRenderer::pushOutOf(const ObjectState& o) noexcept {
  if (!o.tree->isClosed()) return false;  // open meshes have no inside
  const double clearance = options_.proxyRadius + options_.skin;
  const MeshPointQuery q = closestPointOnMesh(*o.tree, o.pose, proxy_, clearance + 1.0);
  if (q.triangle == kNoTriangle || !(q.distance < clearance) || !q.normal.allFinite()) return false;
  proxy_ = q.point + (clearance * 2.0) * q.normal;
  return true;
}

void GodObjectRenderer::recordContactGeometry() noexcept {
  const ObjectState& o = objects_[contact_.object];
  const std::uint32_t k = o.leafOf[contact_.triangle];
  const Vec3* c = o.tree->corners(k);
  const Triangle& tri = o.tree->triangleIndices(k);
  const Vec3 local = o.pose.inverse() * contact_.point;
  contact_.barycentric = closestPointOnTriangle(local, c[0], c[1], c[2]).barycentric;
  contact_.vertices = {tri[0], tri[1], tri[2]};
  contactFaceNormal_ = (c[1] - c[0]).cross(c[2] - c[0]);
  contactOffset_ = o.pose.inverse() * proxy_ - local;
}

GodObjectRenderer::Sweep GodObjectRenderer::sweepAll(const Vec3& from, const Vec3& to) const noexcept {
  Sweep best;
  const double r = options_.proxyRadius;
  for (std::size_t i = 0; i < objects_.size(); ++i) {
    const ObjectState& o = objects_[i];
    const SweepHit h =
        r > 0 ? sweepSphere(*o.tree, o.pose, r, from, to) : sweepPoint(*o.tree, o.pose, from, to);
    if (!h.hit() || (best.hit && h.t >= best.t)) continue;
    best.hit = true;
    best.t = h.t;
    Vec3 n = h.normal;
    // sweepPoint gives the outward face normal; an open mesh is felt from
    // both sides, so face the side the proxy comes from.
    if (r == 0 && n.dot(to - from) > 0) n = -n;
    best.plane.normal = n;
    best.plane.point = h.point;
    best.plane.offset = n.dot(h.point) + r + options_.skin;
    best.plane.object = static_cast<std::uint32_t>(i);
    best.plane.triangle = h.triangle;
  }
  return best;
}

bool GodObjectRenderer::move(Vec3& p, const Vec3& to, Plane& hit) const noexcept {
  const Vec3 d = to - p;
  const double len = d.norm();
  if (!(len > 0)) return false;
  // Sweep a skin further than asked, so the proxy never ends closer than the
  // skin to a surface it moves toward (a proxy left exactly on a triangle
  // would hit it at t = 0 whichever way it moves next).
  const Vec3 end = to + d * (options_.skin / len);
  const Sweep s = sweepAll(p, end);
  if (!s.hit) {
    p = to;
    return false;
  }
  p = stopBefore(p, end, s.t, s.plane.normal, options_.skin);
  hit = s.plane;
  return true;
}

Vec3 GodObjectRenderer::constrainedMove(const Vec3& start, const Vec3& goal) noexcept {
  const double skin = options_.skin;
  Vec3 p = start;
  planeCount_ = 0;
  const auto addPlane = [&](const Plane& pl) {
    for (int i = 0; i < planeCount_; ++i)
      if (planes_[i].object == pl.object && planes_[i].triangle == pl.triangle) return false;
    if (planeCount_ >= 4) return false;
    planes_[planeCount_++] = pl;
    return true;
  };
  for (int it = 0; it < options_.maxIterations; ++it) {
    Vec3 target = goal;
    if (planeCount_ > 0 && !solveConstraints(goal, planes_.data(), planeCount_, lambda_.data(), target))
      break;
    if ((target - p).norm() <= 1e-12) break;
    Plane hit;
    if (move(p, target, hit)) {
      if (!addPlane(hit)) break;
      continue;
    }
    if (planeCount_ == 0 || ++it >= options_.maxIterations) break;
    // Slid to the optimum of the current planes. On a convex surface the
    // real surface falls away under a sliding proxy: try the straight way
    // to the goal again and start a fresh plane set where it leads.
    const Vec3 slid = p;
    if (!move(p, goal, hit)) {
      planeCount_ = 0;
      break;
    }
    if ((p - slid).norm() > skin) {
      planeCount_ = 0;
      addPlane(hit);
    } else if (!addPlane(hit)) {
      break;  // blocked at once by a plane already held: p is the constrained optimum
    }
  }
  // The multipliers of the planes left, relative to the goal (which planes
  // carry the load decides the contact object and material).
  if (planeCount_ > 0) {
    Vec3 unused;
    if (!solveConstraints(goal, planes_.data(), planeCount_, lambda_.data(), unused)) planeCount_ = 0;
  }
  return p;
}

Vec3 GodObjectRenderer::shadedNormal(const Plane& plane) const noexcept {
  const ObjectState& o = objects_[plane.object];
  if (!o.shaded || plane.triangle >= o.leafOf.size()) return Vec3::Zero();
  const std::uint32_t k = o.leafOf[plane.triangle];
  const Vec3* c = o.tree->corners(k);
  const Triangle& tri = o.tree->triangleIndices(k);
  const Vec3 local = o.pose.inverse() * plane.point;
  const Vec3 bc = closestPointOnTriangle(local, c[0], c[1], c[2]).barycentric;
  Vec3 n = Vec3::Zero();
  for (int i = 0; i < 3; ++i)
    n += bc[i] * (o.vertexNormals.empty() ? o.tree->vertexNormal(tri[i]) : o.vertexNormals[tri[i]]);
  n = o.pose.linear() * n;
  const double len = n.norm();
  if (!(len > 1e-12)) return Vec3::Zero();
  n /= len;
  return n.dot(plane.normal) < 0 ? Vec3(-n) : n;  // open mesh felt from behind
}

void GodObjectRenderer::applyPendingPoses() noexcept {
  const double r = options_.proxyRadius;
  for (std::size_t i = 0; i < objects_.size(); ++i) {
    ObjectState& o = objects_[i];
    if (!o.posePending) continue;
    o.posePending = false;
    const Isometry3 oldPose = o.pose;
    o.pose = o.pendingPose;
    if (inContact_ && i == contactObject_) {
      proxy_ = o.pose * (oldPose.inverse() * proxy_);  // carried with the surface
      continue;
    }
    // A free proxy is pushed by the object: sweep the proxy's motion
    // relative to the object in its local frame.
    const Vec3 from = oldPose.inverse() * proxy_, to = o.pose.inverse() * proxy_;
    const SweepHit h = r > 0 ? sweepSphere(*o.tree, Isometry3::Identity(), r, from, to)
                             : sweepPoint(*o.tree, Isometry3::Identity(), from, to);
    if (!h.hit()) continue;
    Vec3 n = h.normal;
    if (r == 0 && n.dot(to - from) > 0) n = -n;
    proxy_ = o.pose * stopBefore(from, to, h.t, n, options_.skin);
  }
}

HapticResponse GodObjectRenderer::tick(const HapticInput& input) noexcept {
  HapticResponse out;
  const Vec3 hip = input.devicePose.translation();
  out.proxyPose.linear() = input.devicePose.linear();
  if (!hip.allFinite() || !input.devicePose.linear().allFinite() || !std::isfinite(input.dt) ||
      !(input.dt > 0)) {
    out.proxyPose = Isometry3::Identity();
    out.proxyPose.translation() = proxy_;
    return out;
  }
  applyPendingPoses();
  const Vec3 previous = proxy_;

  // Pass 1: the real constraints toward the device point.
  Vec3 p = constrainedMove(previous, hip);
  const int contacts = planeCount_;
  Plane contactPlanes[4];
  double contactLambda[4] = {0, 0, 0, 0};
  for (int i = 0; i < contacts; ++i) {
    contactPlanes[i] = planes_[i];
    contactLambda[i] = lambda_[i];
  }
  int primary = 0;
  for (int i = 1; i < contacts; ++i)
    if (contactLambda[i] > contactLambda[primary]) primary = i;

  // Pass 2 (force shading): the goal on the plane through the proxy with the
  // interpolated normal, reached under the real constraints.
  if (contacts > 0 && options_.forceShading) {
    Vec3 shaded = Vec3::Zero();
    for (int i = 0; i < contacts; ++i) shaded += contactLambda[i] * shadedNormal(contactPlanes[i]);
    const double len = shaded.norm();
    if (len > 1e-12) {
      shaded /= len;
      const double depth = shaded.dot(p - hip);
      if (depth > 0) p = constrainedMove(p, hip + depth * shaded);
    }
  }

  // Friction cone, against the frictionless proxy p.
  const HapticMaterial& mat =
      contacts > 0 ? objects_[contactPlanes[primary].object].material : objects_[contactObject_].material;
  if (contacts > 0 && inContact_ && mat.staticFriction > 0) {
    const Vec3 free = p - hip;
    const double freeDepth = free.norm();
    if (freeDepth > 0) {
      const Vec3 n = free / freeDepth;
      const Vec3 spring = previous - hip;
      const double fn = n.dot(spring);
      const double ft = (spring - fn * n).norm();
      const double mu = sliding_ ? mat.dynamicFriction : mat.staticFriction;
      // (1 + 1e-9): a proxy left exactly on the cone's edge by the last
      // sliding step sticks despite rounding.
      if (fn > 0 && ft <= mu * fn * (1 + 1e-9)) {
        p = previous;  // stuck
        sliding_ = false;
      } else {
        sliding_ = true;
        Vec3 u = previous - p;
        u -= u.dot(n) * n;
        const double lag = mat.dynamicFriction * freeDepth;
        const double ulen = u.norm();
        if (ulen > lag && ulen > 0 && lag > 0) {
          p = constrainedMove(p, p + u * (lag / ulen));
        }
      }
    }
  } else {
    sliding_ = false;
  }

  proxy_ = p;
  inContact_ = contacts > 0;
  contact_ = {};
  if (inContact_) {
    const Plane& pl = contactPlanes[primary];
    contactObject_ = pl.object;
    contact_.active = true;
    contact_.object = pl.object;
    contact_.triangle = pl.triangle;
    // Under the proxy where it ended (it may have slid since the sweep hit
    // pl.point): its projection on the contact plane.
    contact_.point = proxy_ - pl.normal * pl.normal.dot(proxy_ - pl.point);
    contact_.normal = pl.normal;
    recordContactGeometry();
  }
  out.proxyPose.translation() = proxy_;
  out.contacts = contacts;
  if (inContact_) {
    Vec3 f = mat.stiffness * (proxy_ - hip);
    if (input.linearVelocity.allFinite()) f -= mat.damping * input.linearVelocity;
    const double fn = f.norm();
    if (fn > options_.maxForce) f *= options_.maxForce / fn;
    out.force = f;
    out.penetration = (proxy_ - hip).norm();
  }
  return out;
}

}  // namespace dm
