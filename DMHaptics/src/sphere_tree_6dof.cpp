// 6-DOF constraint-based sphere-tree haptic rendering (Wang et al.); see
// dm/haptics/sphere_tree_6dof.hpp for the method.
//
// Per tick:
//  1. step = motion bound (translation + rotation × reach of the tool
//     spheres) of the handle since the last tick + the objects' motion +
//     marginEpsilon, at most maxStep; margin = step + marginEpsilon;
//  2. candidate pairs (tool sphere on the chosen level, environment leaf)
//     with gap < margin at the previous graphic pose, by simultaneous descent
//     of the tool tree (with bounds recomputed for the chosen level) and each
//     object's tree; a max-heap on the gap keeps the maxConstraints deepest;
//  3. up to `linearizations` times: linearise the constraints at the current
//     base pose, solve the QP by projected Gauss–Seidel on the dual, clamp the
//     motion so the total stays within the margin, and sweep every candidate
//     pair along the straight motion; at the first time of impact the base
//     pose stops there and the next linearisation starts from the contact;
//  4. force and torque K (q_g − q_h), material damping while touching.
#include <dm/haptics/sphere_tree_6dof.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <span>
#include <tuple>
#include <utility>

namespace dm {

namespace {

using NodeId = SphereHierarchy::NodeId;
constexpr int kStackSize = 512;           // each pop pushes ≤ 8; descents are ≤ 11 + 11 levels deep
constexpr double kTouchTolerance = 1e-9;  // m: pairs closer than this count as touching in the sweep
// Surface patches (see the file comment): a node's patch is used when its
// normals agree within about 25° ...
constexpr double kMinCoherence = 0.9;
// ... a tool point counts against an environment patch when it lies over the
// patch's disc (with this slack) ...
constexpr double kLateralSlack = 1.05;
// ... and no deeper below it than this share of the patch's half-width
// (deeper points are beside or under the patch, e.g. past a box's edge:
// they collide through the spheres, conservatively).
constexpr double kMaxPatchDepth = 0.25;

// Rotation vector (axis · angle, rad) of a unit quaternion.
Vec3 logRotation(const Quat& qIn) noexcept {
  Quat q = qIn;
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const Vec3 v = q.vec();
  const double s = v.norm();
  if (s < 1e-300) return 2.0 * v;
  return v * (2.0 * std::atan2(s, q.w()) / s);
}

// Unit quaternion of a rotation vector.
Quat expRotation(const Vec3& w) noexcept {
  const double a = w.norm();
  if (a < 1e-300) return Quat::Identity();
  return Quat(AngleAxis(a, w / a));
}

bool finitePose(const Isometry3& p) noexcept { return p.matrix().allFinite(); }

// Stored trees: direct node reads.
struct StoredEnv {
  const SphereTreeNode* nodes;
  BoundingSphere bound(NodeId n) const noexcept { return {nodes[n].center, nodes[n].boundRadius}; }
  int children(NodeId n, NodeId out[8]) const noexcept {
    const SphereTreeNode& x = nodes[n];
    for (int i = 0; i < x.childCount; ++i) out[i] = x.firstChild + static_cast<NodeId>(i);
    return x.childCount;
  }
  NodeId root() const noexcept { return 0; }
};

// A soft object's deformed tree (SphereTreeDeformation): the rest topology,
// bounds evaluated on demand.
struct DeformedEnv {
  const SphereTreeNode* nodes;
  const SphereTreeDeformation* def;
  BoundingSphere bound(NodeId n) const noexcept { return def->bound(static_cast<std::uint32_t>(n)); }
  int children(NodeId n, NodeId out[8]) const noexcept { return StoredEnv{nodes}.children(n, out); }
  NodeId root() const noexcept { return 0; }
};

// Any hierarchy (implicit voxel trees): through the virtual interface.
struct GenericEnv {
  const SphereHierarchy* tree;
  BoundingSphere bound(NodeId n) const noexcept { return tree->bound(n); }
  int children(NodeId n, NodeId out[8]) const noexcept { return tree->children(n, out); }
  NodeId root() const noexcept { return tree->root(); }
};

}  // namespace

struct SphereTree6DofRenderer::State {
  // ---- model (read-only after create) ----
  std::shared_ptr<const SphereTree> tool;
  SphereTree6DofOptions opt;
  int level = 0;
  std::uint32_t levelBegin = 0, levelEnd = 0;  // node range of the used level
  // Nodes [0, levelEnd): centre (tool frame), radius for the descent (the
  // used level: the sphere; above: a bound of the used level's spheres below).
  std::vector<Vec3> toolCenter;
  std::vector<double> toolBound;
  std::vector<const SurfacePatch*> toolPatch;  // the used level's usable patches (else null)
  // m: radius of each tool patch's osculating ball (the mean curvature's
  // inverse; a flat or concave patch: 1000 times the node's radius), for
  // contacts with creases.
  std::vector<double> toolRho;
  double toolReach = 0.0;                      // max |centre| of the used level's spheres
  double toolMaxRadius = 0.0;
  double envMaxLeafRadius = 0.0;
  double mass = 1.0, inertia = 1.0;
  Vec3 kLin = Vec3::Zero(), kAng = Vec3::Zero();

  struct Object {
    std::shared_ptr<const SphereHierarchy> tree;
    const SphereTree* stored = nullptr;
    Isometry3 pose = Isometry3::Identity();
    HapticMaterial material;
    double reach = 0.0;  // max distance of a leaf point from the local origin
    double moved = 0.0;  // motion bound since the last tick, m
    // The stored tree's nodes and patches (a soft object's at rest: its
    // deformation displaces them).
    const SphereTreeNode* nodes = nullptr;
    std::span<const SurfacePatch> patches;
    std::shared_ptr<SphereTreeDeformation> deformation;
    double releaseForce = std::numeric_limits<double>::infinity();
    bool released = false;
    Vec3 force = Vec3::Zero();  // on the object in the last tick, world
    Vec3 torque = Vec3::Zero();  // its moment about the world origin
  };
  std::vector<Object> objects;

  // ---- per-tick state (preallocated) ----
  // One pair's contact at a tool pose: unit normal from the environment to
  // the tool (world), the tool point (tool frame: a patch's support point or
  // a sphere's centre) and its radius (0 for a patch point), the distance.
  struct Contact {
    Vec3 n = Vec3::UnitZ();
    Vec3 point = Vec3::Zero();
    double radius = 0.0;
    double dist = 0.0;
    bool envPatch = false;
    bool strict = true;       // within the strict lateral gate (collection widens it)
    double centrality = 0.0;  // environment patch: the tool point's lateral offset / the patch's half-width
  };
  struct Pair {
    double gap = 0.0;  // at collection; heap key
    std::uint32_t toolNode = 0;
    std::uint32_t object = 0;
    NodeId envNode = 0;
    Vec3 envCenter = Vec3::Zero();  // world
    double envRadius = 0.0;
    const SurfacePatch* envPatch = nullptr;  // object local frame; null: collide with the sphere
    bool envCrease = false;                  // envPatch's crease, not its quadric
    // A soft object's patch is carried by x ↦ o + u + F (x − o) (o its rest
    // origin): u its displacement, F⁻¹ kept (object local frame).
    bool soft = false;
    Vec3 envShift = Vec3::Zero();
    Mat3 envInvF = Mat3::Identity();
    bool collected = false;  // `atCollection` holds the contact at the collection pose
    Contact atCollection;
  };
  std::vector<Pair> pairs;             // capacity maxConstraints
  std::vector<std::uint32_t> scratch;  // capacity maxConstraints
  std::vector<std::uint8_t> drop;      // per pair, all 0 between ticks
  std::size_t pairCount = 0;
  std::size_t candidates = 0;
  // Smallest gap of a candidate dropped by the truncation: no tool sphere may
  // move farther than this in the tick, or it could hit a pair not solved for.
  double minDropped = std::numeric_limits<double>::infinity();
  // Constraint rows of one linearisation, and each row's contact (what the
  // sweep moves along the chord; rowActive 0: no constraint this time).
  std::vector<Vec3> rowN, rowRxN;
  std::vector<double> rowD, rowLambda, rowInvA;
  std::vector<Contact> rowContact;
  std::vector<std::uint8_t> rowActive;

  Vec3 pg = Vec3::Zero();  // graphic tool
  Quat qg = Quat::Identity();
  Vec3 lastHandleP = Vec3::Zero();  // handle at the previous tick
  Quat lastHandleQ = Quat::Identity();

  // ---------------------------------------------------------------------
  // A node's patch when it is usable: valid, coherent, and within
  // surfaceTolerance × radius of its surface; else, where `crease` is given
  // (environment nodes), its crease when that is within the tolerance
  // (*crease = true); else null.
  const SurfacePatch* usablePatch(std::span<const SurfacePatch> patches, NodeId node, double radius,
                                  bool* crease = nullptr) const noexcept {
    if (node >= patches.size()) return nullptr;
    const SurfacePatch& sp = patches[node];
    const double tolerance = opt.surfaceTolerance * radius;
    if (sp.valid() && sp.coherence >= kMinCoherence && sp.deviation <= tolerance) return &sp;
    if (crease && sp.hasCrease() && sp.crease.deviation <= tolerance) {
      *crease = true;
      return &sp;
    }
    return nullptr;
  }

  // Where the object-frame point x is relative to pair pr's patch (its
  // crease or its quadric), and the patch's extent from its origin.
  static SurfacePatch::Query envQuery(const Pair& pr, const Vec3& x) noexcept {
    return pr.envCrease ? pr.envPatch->creaseQuery(x) : pr.envPatch->query(x);
  }
  static double envWidth(const Pair& pr) noexcept {
    return pr.envCrease ? pr.envPatch->crease.reach : pr.envPatch->halfWidth;
  }

  void addCandidate(const Pair& p) noexcept {
    const double gap = p.gap;
    ++candidates;
    const auto less = [](const Pair& a, const Pair& b) { return a.gap < b.gap; };
    if (pairCount < pairs.size()) {
      pairs[pairCount++] = p;
      std::push_heap(pairs.begin(), pairs.begin() + static_cast<std::ptrdiff_t>(pairCount), less);
    } else if (gap < pairs.front().gap) {
      minDropped = std::min(minDropped, pairs.front().gap);
      std::pop_heap(pairs.begin(), pairs.end(), less);
      pairs.back() = p;
      std::push_heap(pairs.begin(), pairs.end(), less);
    } else {
      minDropped = std::min(minDropped, gap);
    }
  }

  // Pairs of object `k` within `margin` of the tool at (p, q).
  template <class Env>
  void collect(const Env& env, std::uint32_t k, const Vec3& p, const Quat& q, double margin) noexcept {
    const Object& o = objects[k];
    // Tool frame → object frame.
    const Mat3 rObj = o.pose.linear();
    const Mat3 rot = rObj.transpose() * q.toRotationMatrix();
    const Vec3 tr = rObj.transpose() * (p - o.pose.translation());
    const Mat3 rWorld = q.toRotationMatrix();
    struct Entry {
      std::uint32_t t;
      NodeId e;
    };
    std::array<Entry, kStackSize> stack;
    int top = 0;
    stack[top++] = {0, env.root()};
    while (top > 0) {
      const Entry en = stack[--top];
      const Vec3 ct = rot * toolCenter[en.t] + tr;
      const double rt = toolBound[en.t];
      const BoundingSphere be = env.bound(en.e);
      const double gap = (ct - be.center).norm() - rt - be.radius;
      if (gap > margin) continue;
      const bool toolLeaf = en.t >= levelBegin;
      NodeId kids[8];
      const int nk = env.children(en.e, kids);
      if (toolLeaf && nk == 0) {
        Pair pr{gap, en.t, k, en.e, o.pose * be.center, be.radius};
        pr.envPatch = usablePatch(o.patches, en.e, be.radius, &pr.envCrease);
        if (o.deformation && pr.envPatch) {
          const auto node = static_cast<std::uint32_t>(en.e);
          const Mat3 f = o.deformation->deformationGradient(node);
          pr.soft = true;
          pr.envShift = o.deformation->displacement(node);
          if (f.determinant() > 0.1) pr.envInvF = f.inverse();  // else (crushed): translated only
        }
        if (pr.envPatch || toolPatch[en.t]) {
          // Through a patch the pair is as near as its contact, which the
          // spheres only bound: keep it when that is within the margin
          // (its tool point may move up to the margin over the patch).
          Contact& c = pr.atCollection;
          if (!contact(pr, p, rWorld, c, margin) || c.dist > margin) continue;
          pr.gap = c.dist;
          pr.collected = true;
        }
        addCandidate(pr);
        continue;
      }
      const bool splitTool = nk == 0 || (!toolLeaf && rt >= be.radius);
      if (splitTool) {
        const SphereTreeNode& n = tool->nodes()[en.t];
        for (int i = 0; i < n.childCount && top < kStackSize; ++i)
          stack[top++] = {n.firstChild + static_cast<std::uint32_t>(i), en.e};
      } else {
        for (int i = 0; i < nk && top < kStackSize; ++i) stack[top++] = {en.t, kids[i]};
      }
    }
  }

  void collectAll(double margin) noexcept {
    pairCount = 0;
    candidates = 0;
    minDropped = std::numeric_limits<double>::infinity();
    for (std::uint32_t k = 0; k < objects.size(); ++k) {
      if (objects[k].released) continue;
      if (objects[k].nodes && !objects[k].deformation)
        collect(StoredEnv{objects[k].nodes}, k, pg, qg, margin);
      else if (objects[k].deformation)
        collect(DeformedEnv{objects[k].nodes, objects[k].deformation.get()}, k, pg, qg, margin);
      else
        collect(GenericEnv{objects[k].tree.get()}, k, pg, qg, margin);
    }
    // Deepest first: Gauss–Seidel resolves the worst overlaps first.
    std::sort_heap(pairs.begin(), pairs.begin() + static_cast<std::ptrdiff_t>(pairCount),
                   [](const Pair& a, const Pair& b) { return a.gap < b.gap; });
    dropOverlappingPatches();
  }

  // A tool point over several environment patches of one object (they
  // overlap at their rims, by kLateralSlack) is constrained by the one it
  // lies most centrally over: the patches fit the same surface, the others
  // repeat its constraint (to their deviation) and only cost solver sweeps.
  // A crease comes before any quadric: its planes continue the faces beside
  // it, while a face's patch near a convex edge reaches past the edge (a
  // disc about its centre covers its corners) and there would hold the tool
  // off by the height of the face's plane over the edge's far side.
  void dropOverlappingPatches() noexcept {
    std::size_t n = 0;
    for (std::size_t i = 0; i < pairCount; ++i)
      if (pairs[i].collected && pairs[i].atCollection.envPatch) scratch[n++] = static_cast<std::uint32_t>(i);
    if (n < 2) return;
    const auto key = [&](std::uint32_t i) {
      const Pair& p = pairs[i];
      return std::tuple(p.object, p.toolNode, !p.envCrease, p.atCollection.centrality, i);
    };
    std::sort(scratch.begin(), scratch.begin() + static_cast<std::ptrdiff_t>(n),
              [&](std::uint32_t a, std::uint32_t b) { return key(a) < key(b); });
    for (std::size_t k = 1; k < n; ++k) {
      const Pair &a = pairs[scratch[k - 1]], &b = pairs[scratch[k]];
      if (a.object == b.object && a.toolNode == b.toolNode) drop[scratch[k]] = 1;
    }
    std::size_t out = 0;
    for (std::size_t i = 0; i < pairCount; ++i) {
      if (drop[i]) {
        drop[i] = 0;
        continue;
      }
      if (out != i) pairs[out] = pairs[i];
      ++out;
    }
    pairCount = out;
  }

  // Contact of tool point `c.point` (radius c.radius) with the environment
  // sphere of `pr` at the tool pose (p, R).
  static void sphereContact(const Pair& pr, const Vec3& p, const Mat3& r, Contact& c) noexcept {
    const Vec3 lv = r * c.point;
    const Vec3 diff = p + lv - pr.envCenter;
    const double dist = diff.norm();
    // Coincident centres: push along the lever (away from the tool origin), else up.
    c.n = dist > 1e-12 ? Vec3(diff / dist) : (lv.norm() > 1e-12 ? Vec3(lv.normalized()) : Vec3::UnitZ());
    c.dist = dist - c.radius - pr.envRadius;
    c.envPatch = false;
  }

  // A soft object's patch: the object-frame point `x` mapped back to the
  // patch's rest frame, and a rest normal carried to the deformed one.
  static Vec3 restPoint(const Pair& pr, const Vec3& x) noexcept {
    if (!pr.soft) return x;
    const Vec3& o = pr.envPatch->origin;
    return o + pr.envInvF * (x - o - pr.envShift);
  }
  static Vec3 restNormal(const Pair& pr, const Vec3& n) noexcept {
    return pr.soft ? Vec3((pr.envInvF.transpose() * n).normalized()) : n;
  }

  // The contact of pair `pr` at the tool pose (p, R); false when the pair
  // constrains nothing there (a tool patch facing away from the
  // environment's surface, or a tool point beside an environment patch).
  // Environment patch: the tool's support point along the patch normal (two
  // passes: the normal at the first point, then at the second) or the tool
  // sphere, against the patch; deeper than kMaxPatchDepth, the spheres.
  // Environment sphere: the tool's support point towards its centre, or the
  // tool sphere. `lateralExtra` (m) widens the lateral gate (collection).
  bool contact(const Pair& pr, const Vec3& p, const Mat3& r, Contact& c,
               double lateralExtra = 0.0) const noexcept {
    const SurfacePatch* tp = toolPatch[pr.toolNode];
    c.point = toolCenter[pr.toolNode];
    c.radius = toolBound[pr.toolNode];
    c.strict = true;
    if (pr.envCrease) return creaseContact(pr, p, r, c, lateralExtra);
    if (pr.envPatch) {
      const Isometry3& pose = objects[pr.object].pose;
      const Mat3 ro = pose.linear();
      const auto at = [&](const Vec3& toolPoint) {
        return envQuery(pr, restPoint(pr, ro.transpose() * (p + r * toolPoint - pose.translation())));
      };
      Vec3 nEnv = ro * pr.envPatch->normal;
      SurfacePatch::Query q;
      for (int pass = 0; pass < (tp ? 2 : 1); ++pass) {
        if (tp) {
          const Vec3 d = -(r.transpose() * nEnv);
          if (d.dot(tp->normal) <= 0.0) return false;
          c.point = tp->support(d);
          c.radius = 0.0;
        }
        q = at(c.point);
        nEnv = ro * restNormal(pr, q.normal);
      }
      return patchContact(pr, p, r, q, nEnv, q.distance - c.radius, c, lateralExtra);
    }
    if (tp) {
      const Vec3 toEnv = r.transpose() * (pr.envCenter - p) - tp->origin;
      if (toEnv.squaredNorm() > 0.0 && toEnv.dot(tp->normal) > 0.0) {
        c.point = tp->support(toEnv.normalized());
        c.radius = 0.0;
      }
    }
    sphereContact(pr, p, r, c);
    return true;
  }

  // contact() against an environment crease. At an edge or a corner the
  // normal is not the environment's (it has none there) but the direction
  // from the crease's nearest point to the tool's centre of curvature: the
  // tool point alone is on the edge at contact, where its direction from
  // the edge is undefined, so iterating on it (as on a quadric) diverges.
  // A tool patch is taken as its osculating ball (radius toolRho, about the
  // point ρ inside its support point along the normal), starting from the
  // centre of curvature at the patch's origin; three passes of normal →
  // support point → centre → nearest crease point → normal (a ball's centre
  // is its first). A tool sphere is its own ball.
  bool creaseContact(const Pair& pr, const Vec3& p, const Mat3& r, Contact& c,
                     double lateralExtra) const noexcept {
    const SurfacePatch* tp = toolPatch[pr.toolNode];
    const Isometry3& pose = objects[pr.object].pose;
    const Mat3 ro = pose.linear();
    const auto local = [&](const Vec3& toolPoint) {
      return restPoint(pr, ro.transpose() * (p + r * toolPoint - pose.translation()));
    };
    const double rho = tp ? toolRho[pr.toolNode] : 0.0;
    // The first centre: the tool patch's own centre of curvature (a ball's centre).
    Vec3 center = local(tp ? Vec3(tp->origin - rho * tp->normal) : c.point);
    SurfacePatch::Query q = pr.envPatch->creaseQuery(center);
    Vec3 toolPoint = center;  // object (rest) frame
    if (tp) {
      for (int pass = 0; pass < 3; ++pass) {
        const Vec3 d = -(r.transpose() * (ro * restNormal(pr, q.normal)));
        if (d.dot(tp->normal) <= 0.0) return false;
        c.point = tp->support(d);
        c.radius = 0.0;
        toolPoint = local(c.point);
        center = local(c.point - rho * d);
        q = pr.envPatch->creaseQuery(center);
      }
    }
    // The tool point's own distance to the crease: never less than the
    // tool's (the tool's is the least over its points), equal at the
    // converged point; a rim point of a patch that does not hold the
    // contact stays above it and so does not bind.
    const double dist = tp ? pr.envPatch->creaseQuery(toolPoint).distance : q.distance - c.radius;
    return patchContact(pr, p, r, q, ro * restNormal(pr, q.normal), dist, c, lateralExtra);
  }

  // The end of a contact through an environment patch or crease whose
  // query at the tool point is q: false when the tool point lies beside it
  // (the lateral gate); the contact (normal n, distance dist) unless it is
  // deeper than kMaxPatchDepth of the patch's width, where the spheres
  // collide instead.
  bool patchContact(const Pair& pr, const Vec3& p, const Mat3& r, const SurfacePatch::Query& q, const Vec3& n,
                    double dist, Contact& c, double lateralExtra) const noexcept {
    const double width = envWidth(pr);
    const double gate = kLateralSlack * width + c.radius;
    if (q.lateral > gate + lateralExtra) return false;
    c.strict = q.lateral <= gate;
    c.centrality = q.lateral / std::max(width, 1e-300);
    if (dist >= -kMaxPatchDepth * width) {
      c.n = n;
      c.dist = dist;
      c.envPatch = true;
      return true;
    }
    c.point = toolCenter[pr.toolNode];
    c.radius = toolBound[pr.toolNode];
    sphereContact(pr, p, r, c);
    return true;
  }

  // Distance of row i's contact (the same tool point and feature) at the tool pose (p, R).
  double rowDistance(std::size_t i, const Vec3& p, const Mat3& r) const noexcept {
    const Pair& pr = pairs[i];
    const Contact& c = rowContact[i];
    if (c.envPatch) {
      const Isometry3& pose = objects[pr.object].pose;
      return envQuery(pr, restPoint(pr, pose.linear().transpose() * (p + r * c.point - pose.translation())))
                 .distance -
             c.radius;
    }
    return (p + r * c.point - pr.envCenter).norm() - c.radius - pr.envRadius;
  }

  // Linearises every pair at (p, R) into the constraint rows.
  // At the collection pose (`atCollection`) the patch pairs' contacts from
  // the collection are reused.
  void linearize(const Vec3& p, const Mat3& r, bool atCollection) noexcept {
    for (std::size_t i = 0; i < pairCount; ++i) {
      Contact& c = rowContact[i];
      rowLambda[i] = 0.0;
      if (atCollection && pairs[i].collected) {
        c = pairs[i].atCollection;
        rowActive[i] = c.strict ? 1 : 0;
      } else {
        rowActive[i] = contact(pairs[i], p, r, c) ? 1 : 0;
      }
      if (!rowActive[i]) {  // a row that never binds
        rowN[i] = Vec3::Zero();
        rowRxN[i] = Vec3::Zero();
        rowD[i] = std::numeric_limits<double>::max();
        rowInvA[i] = mass;
        continue;
      }
      rowN[i] = c.n;
      rowRxN[i] = (r * c.point).cross(c.n);
      rowD[i] = c.dist;
      rowInvA[i] = 1.0 / (1.0 / mass + rowRxN[i].squaredNorm() / inertia);
    }
  }

  // Projected Gauss–Seidel on the dual of
  //   min ½(Δ − Δh)ᵀ M (Δ − Δh)  s.t.  n·Δx + (r × n)·Δθ + d ≥ 0.
  // Returns the number of rows with λ > 0.
  int solve(Vec3& dx, Vec3& dth) noexcept {
    const double invM = 1.0 / mass, invI = 1.0 / inertia;
    double* lambda = rowLambda.data();
    for (int sweep = 0; sweep < opt.solverIterations; ++sweep) {
      double change = 0.0;
      for (std::size_t i = 0; i < pairCount; ++i) {
        const double res = rowN[i].dot(dx) + rowRxN[i].dot(dth) + rowD[i];
        const double next = std::max(0.0, lambda[i] - res * rowInvA[i]);
        const double dl = next - lambda[i];
        if (dl == 0.0) continue;
        lambda[i] = next;
        dx += (dl * invM) * rowN[i];
        dth += (dl * invI) * rowRxN[i];
        change = std::max(change, std::abs(dl) / rowInvA[i]);  // m moved along the row
      }
      if (change < 1e-12) break;
    }
    int active = 0;
    for (std::size_t i = 0; i < pairCount; ++i) active += lambda[i] > 0.0 ? 1 : 0;
    return active;
  }

  // Earliest time t ∈ [0, 1] at which a candidate tool sphere, moving on the
  // straight chord between its centres at (p0, r0) and (p1, r1), touches its
  // environment sphere; 2 when none does. Pairs already overlapping at t = 0
  // are being pushed out and are not swept.
  double sweep(const Vec3& p0, const Mat3& r0, const Vec3& p1, const Mat3& r1) const noexcept {
    double tFirst = 2.0;
    for (std::size_t i = 0; i < pairCount; ++i) {
      if (!rowActive[i]) continue;
      const Pair& pr = pairs[i];
      const Contact& ct = rowContact[i];
      if (ct.envPatch) {
        // The point's distance from the patch along the chord, linearly
        // (exact for a plane, and the motion is within the margin).
        const double d0 = ct.dist - kTouchTolerance;
        if (d0 <= 0.0) continue;
        const double d1 = rowDistance(i, p1, r1) - kTouchTolerance;
        if (d1 < 0.0) tFirst = std::min(tFirst, d0 / (d0 - d1));
        continue;
      }
      const Vec3 c0 = p0 + r0 * ct.point;
      const Vec3 c1 = p1 + r1 * ct.point;
      const double rr = ct.radius + pr.envRadius - kTouchTolerance;
      const Vec3 m = c0 - pr.envCenter;
      const double cq = m.squaredNorm() - rr * rr;
      if (cq <= 0.0) continue;
      const Vec3 v = c1 - c0;
      const double a = v.squaredNorm();
      if (a < 1e-300) continue;
      const double b = m.dot(v);
      if (b >= 0.0) continue;  // moving away
      const double disc = b * b - a * cq;
      if (disc < 0.0) continue;
      const double t = cq / (-b + std::sqrt(disc));  // smaller root, stable form
      if (t <= 1.0) tFirst = std::min(tFirst, t);
    }
    return tFirst;
  }

  // The force on the objects: the user's force `userForce` (on the tool,
  // from the objects) shared over the touching rows (rowActive, rowContact
  // at the final pose) by their multipliers: row i pushes its object with
  // −c λ_i n_i, c = F·S / |S|² with S = Σ λ_i n_i (the projection of F on
  // the constraints' resultant). Soft objects take it on the node touched;
  // a bonded piece whose force exceeds its bond comes off.
  void shareForce(const Vec3& userForce, const Vec3& lambdaN) noexcept {
    for (Object& o : objects) o.force = o.torque = Vec3::Zero();
    const double ln2 = lambdaN.squaredNorm();
    const double c = ln2 > 0.0 ? std::max(0.0, userForce.dot(lambdaN)) / ln2 : 0.0;
    if (c == 0.0) return;
    for (std::size_t i = 0; i < pairCount; ++i) {
      if (!rowActive[i] || rowLambda[i] <= 0.0) continue;
      const Pair& pr = pairs[i];
      Object& o = objects[pr.object];
      const Contact& ct = rowContact[i];
      const Vec3 f = -(c * rowLambda[i]) * ct.n;
      o.force += f;
      // Where it acts: the tool's point (a sphere's surface toward the
      // object, or a patch's support point) at the final pose.
      o.torque += (pg + qg * ct.point - ct.radius * ct.n).cross(f);
      if (o.deformation)
        o.deformation->addForce(static_cast<std::uint32_t>(pr.envNode), o.pose.linear().transpose() * f);
    }
    for (Object& o : objects)
      if (o.force.norm() > o.releaseForce) o.released = true;
  }

  double motionBound(const Vec3& dx, const Vec3& dth) const noexcept {
    return dx.norm() + dth.norm() * toolReach;
  }
};

SphereTree6DofRenderer::SphereTree6DofRenderer(std::unique_ptr<State> state) noexcept
    : s_(std::move(state)) {}
SphereTree6DofRenderer::~SphereTree6DofRenderer() = default;

Result<std::unique_ptr<SphereTree6DofRenderer>> SphereTree6DofRenderer::create(
    std::shared_ptr<const SphereTree> tool, std::vector<SphereTreeObject> objects,
    const SphereTree6DofOptions& options) {
  const auto bad = [](std::string what, std::string where, std::string hint) -> Error {
    return fail(ErrorCode::InvalidArgument, std::move(what), std::move(where), std::move(hint));
  };
  const auto finite = [](double x) { return std::isfinite(x); };
  const SphereTree6DofOptions& o = options;
  if (!tool) return bad("the tool sphere tree is null", "tool", "build it with dm::buildSphereTreeFitted()");
  if (o.toolLevel < 0 || o.toolLevel >= tool->levelCount())
    return bad(formatString("toolLevel is %d but the tool tree has %d levels (0..%d)", o.toolLevel,
                            tool->levelCount(), tool->levelCount() - 1),
               "options.toolLevel", "use a smaller level or build the tool tree with more levels");
  if (!finite(o.mass) || o.mass <= 0)
    return bad(formatString("mass is %g kg; it must be finite and > 0", o.mass), "options.mass", "");
  if (!finite(o.inertia) || o.inertia < 0)
    return bad(formatString("inertia is %g kg*m^2; it must be finite and >= 0 (0 = automatic)", o.inertia),
               "options.inertia", "");
  if (!o.linearStiffness.allFinite() || (o.linearStiffness.array() <= 0).any())
    return bad("linearStiffness has a component that is not finite and > 0 N/m", "options.linearStiffness",
               "");
  if (!o.angularStiffness.allFinite() || (o.angularStiffness.array() < 0).any())
    return bad("angularStiffness has a component that is not finite and >= 0 N*m/rad",
               "options.angularStiffness", "all three 0 selects K proportional to M");
  if (o.maxConstraints < 1 || o.maxConstraints > 65536)
    return bad(formatString("maxConstraints is %d; it must be in 1..65536", o.maxConstraints),
               "options.maxConstraints", "");
  if (o.solverIterations < 1 || o.solverIterations > 10000)
    return bad(formatString("solverIterations is %d; it must be in 1..10000", o.solverIterations),
               "options.solverIterations", "");
  if (o.linearizations < 1 || o.linearizations > 16)
    return bad(formatString("linearizations is %d; it must be in 1..16", o.linearizations),
               "options.linearizations", "");
  if (!finite(o.marginEpsilon) || o.marginEpsilon < 0)
    return bad(formatString("marginEpsilon is %g m; it must be finite and >= 0", o.marginEpsilon),
               "options.marginEpsilon", "");
  if (!finite(o.maxStep) || o.maxStep <= 0)
    return bad(formatString("maxStep is %g m; it must be finite and > 0", o.maxStep), "options.maxStep", "");
  if (!finite(o.surfaceTolerance) || o.surfaceTolerance < 0)
    return bad(formatString("surfaceTolerance is %g; it must be finite and >= 0 (0 = spheres only)",
                            o.surfaceTolerance),
               "options.surfaceTolerance", "");

  auto s = std::make_unique<State>();
  s->opt = o;
  s->level = o.toolLevel;
  const std::vector<SphereTreeNode>& nodes = tool->nodes();
  const std::span<const SphereTreeNode> lv = tool->level(o.toolLevel);
  s->levelBegin = static_cast<std::uint32_t>(lv.data() - nodes.data());
  s->levelEnd = s->levelBegin + static_cast<std::uint32_t>(lv.size());
  s->toolCenter.resize(s->levelEnd);
  s->toolBound.resize(s->levelEnd);
  s->toolPatch.assign(s->levelEnd, nullptr);
  s->toolRho.assign(s->levelEnd, 0.0);
  for (std::uint32_t i = s->levelEnd; i-- > 0;) {
    const SphereTreeNode& n = nodes[i];
    s->toolCenter[i] = n.center;
    if (i >= s->levelBegin) {
      s->toolBound[i] = n.radius;
      s->toolPatch[i] = s->usablePatch(tool->patches(), i, n.radius);
      if (const SurfacePatch* tp = s->toolPatch[i]) {
        const double kappa = -0.5 * (tp->coeff[3] + tp->coeff[5]);  // outward-convex: h curves down
        s->toolRho[i] = std::min(kappa > 0.0 ? 1.0 / kappa : HUGE_VAL, 1e3 * n.radius);
      }
      s->toolReach = std::max(s->toolReach, n.center.norm());
      s->toolMaxRadius = std::max(s->toolMaxRadius, n.radius);
      continue;
    }
    // Bound of the used level's spheres below (children come later in the array).
    double b = 0.0;
    for (std::uint32_t c = n.firstChild; c < n.firstChild + n.childCount; ++c)
      b = std::max(b, (nodes[c].center - n.center).norm() + s->toolBound[c]);
    s->toolBound[i] = b;
  }
  s->tool = std::move(tool);
  s->mass = o.mass;
  const double rootR = s->tool->nodes()[0].radius;
  s->inertia = o.inertia > 0 ? o.inertia : 0.4 * o.mass * std::max(rootR * rootR, 1e-12);
  s->kLin = o.linearStiffness;
  s->kAng =
      o.angularStiffness.isZero() ? Vec3(o.linearStiffness * (s->inertia / s->mass)) : o.angularStiffness;

  s->objects.reserve(objects.size());
  for (std::size_t k = 0; k < objects.size(); ++k) {
    SphereTreeObject& src = objects[k];
    const std::string where =
        formatString("objects[%zu]", k) + (src.name.empty() ? "" : " (" + src.name + ")");
    if (!src.tree)
      return bad("the object's sphere tree is null", where + ".tree", "give every object a tree");
    if (!finitePose(src.pose)) return bad("the object's pose is not finite", where + ".pose", "");
    if (Status st = src.material.validate(where + ".material"); !st.ok()) return st.error();
    if (!(src.releaseForce > 0))
      return bad(
          formatString("releaseForce is %g N; it must be > 0 (infinity: never released)", src.releaseForce),
          where + ".releaseForce", "");
    State::Object ob;
    ob.stored = dynamic_cast<const SphereTree*>(src.tree.get());
    if (src.deformation && &src.deformation->rest() != ob.stored)
      return bad("the deformation was built on another sphere tree than the object's", where + ".deformation",
                 "create it from the object's tree: SphereTreeDeformation::create(tree, ...)");
    if (ob.stored) {
      ob.nodes = ob.stored->nodes().data();
      ob.patches = ob.stored->patches();
    }
    ob.deformation = std::move(src.deformation);
    ob.releaseForce = src.releaseForce;
    const BoundingSphere root = src.tree->bound(src.tree->root());
    ob.reach = root.center.norm() + root.radius;
    if (ob.stored) {
      for (const SphereTreeNode& n : ob.stored->level(ob.stored->levelCount() - 1))
        s->envMaxLeafRadius = std::max(s->envMaxLeafRadius, n.radius);
    } else {
      const std::vector<SphereTreeLevelStats> st = src.tree->levelStats();
      if (!st.empty()) s->envMaxLeafRadius = std::max(s->envMaxLeafRadius, st.back().maxRadius);
    }
    ob.tree = std::move(src.tree);
    ob.pose = src.pose;
    ob.material = src.material;
    s->objects.push_back(std::move(ob));
  }
  const auto m = static_cast<std::size_t>(o.maxConstraints);
  s->pairs.resize(m);
  s->scratch.resize(m);
  s->drop.assign(m, 0);
  s->rowN.resize(m);
  s->rowRxN.resize(m);
  s->rowD.resize(m);
  s->rowLambda.resize(m);
  s->rowInvA.resize(m);
  s->rowContact.resize(m);
  s->rowActive.resize(m);
  return std::unique_ptr<SphereTree6DofRenderer>(new SphereTree6DofRenderer(std::move(s)));
}

void SphereTree6DofRenderer::reset(const Isometry3& devicePose) noexcept {
  if (!finitePose(devicePose)) return;
  s_->pg = devicePose.translation();
  s_->qg = Quat(devicePose.linear()).normalized();
  s_->lastHandleP = s_->pg;
  s_->lastHandleQ = s_->qg;
  s_->pairCount = 0;
  s_->candidates = 0;
  for (State::Object& o : s_->objects) {
    o.moved = 0.0;
    o.force = o.torque = Vec3::Zero();
  }
}

HapticResponse SphereTree6DofRenderer::tick(const HapticInput& input) noexcept {
  State& s = *s_;
  HapticResponse out;
  const Isometry3& hp = input.devicePose;
  if (!finitePose(hp) || !std::isfinite(input.dt) || input.dt <= 0 || !input.linearVelocity.allFinite() ||
      !input.angularVelocity.allFinite()) {
    out.proxyPose = graphicPose();
    return out;
  }
  const Vec3 ph = hp.translation();
  const Quat qh = Quat(hp.linear()).normalized();

  // 1. Margin: how far the tool may move this tick. The handle's own motion
  // (the tool tracks it), the objects' motion (they push the tool) and
  // marginEpsilon (catching up with a handle that drew ahead, e.g. off an
  // edge); never more than maxStep.
  const double handleMoved = s.motionBound(ph - s.lastHandleP, logRotation(qh * s.lastHandleQ.conjugate()));
  s.lastHandleP = ph;
  s.lastHandleQ = qh;
  double objectMotion = 0.0;
  for (State::Object& o : s.objects) {
    if (o.deformation) o.moved += o.deformation->step(input.dt);  // under last tick's contact forces
    objectMotion = std::max(objectMotion, o.moved);
    o.moved = 0.0;
  }
  double step = std::min(handleMoved + objectMotion + s.opt.marginEpsilon, s.opt.maxStep);
  // 2. Candidates.
  s.collectAll(step + s.opt.marginEpsilon);
  // Truncated: stay clear of the dropped pairs (a speed limit only while
  // more than maxConstraints pairs are near). When even dropped pairs overlap
  // (a tool reset deep inside), no clearance exists: resolve the deepest.
  if (s.minDropped > kTouchTolerance) step = std::min(step, s.minDropped - kTouchTolerance);

  // 3. Linearise, solve, clamp, sweep.
  Vec3 p = s.pg;
  Quat q = s.qg;
  double travelled = 0.0;
  for (int it = 0; it < s.opt.linearizations; ++it) {
    const Mat3 r0 = q.toRotationMatrix();
    s.linearize(p, r0, it == 0);
    Vec3 dx = ph - p;
    Vec3 dth = logRotation(qh * q.conjugate());
    s.solve(dx, dth);
    const double allowed = std::max(0.0, step - travelled);
    const double mb = s.motionBound(dx, dth);
    if (mb > allowed) {
      const double f = mb > 0 ? allowed / mb : 0.0;
      dx *= f;
      dth *= f;
    }
    Vec3 p1 = p + dx;
    Quat q1 = (expRotation(dth) * q).normalized();
    const double tHit = s.sweep(p, r0, p1, q1.toRotationMatrix());
    if (tHit <= 1.0) {
      dx *= tHit;
      dth *= tHit;
      p1 = p + dx;
      q1 = (expRotation(dth) * q).normalized();
    }
    travelled += s.motionBound(dx, dth);
    p = p1;
    q = q1;
    if (s.motionBound(dx, dth) < 1e-12) break;
  }
  if (!p.allFinite() || !q.coeffs().allFinite()) {  // defensive: never hand out a NaN pose or force
    out.proxyPose = graphicPose();
    return out;
  }
  s.pg = p;
  s.qg = q;

  // 4. Contacts at the final pose, force, torque, damping.
  const Mat3 rg = q.toRotationMatrix();
  double damping = 0.0;
  int touching = 0;
  Vec3 lambdaN = Vec3::Zero();  // Σ λ n over the touching rows
  for (std::size_t i = 0; i < s.pairCount; ++i) {
    const State::Pair& pr = s.pairs[i];
    State::Contact& c = s.rowContact[i];
    s.rowActive[i] = s.contact(pr, p, rg, c) && c.dist <= s.opt.marginEpsilon ? 1 : 0;
    if (!s.rowActive[i]) continue;
    ++touching;
    damping = std::max(damping, s.objects[pr.object].material.damping);
    lambdaN += s.rowLambda[i] * c.n;
  }
  out.force = s.kLin.cwiseProduct(p - ph);
  out.torque = s.kAng.cwiseProduct(logRotation(q * qh.conjugate()));
  s.shareForce(out.force, lambdaN);
  if (touching > 0) {
    out.force -= damping * input.linearVelocity;
    out.penetration = (p - ph).norm();
  }
  out.contacts = touching;
  out.proxyPose = graphicPose();
  return out;
}

std::size_t SphereTree6DofRenderer::objectCount() const noexcept { return s_->objects.size(); }

void SphereTree6DofRenderer::setObjectPose(std::size_t index, const Isometry3& pose) noexcept {
  if (index >= s_->objects.size() || !finitePose(pose)) return;
  State::Object& o = s_->objects[index];
  const Quat dq = Quat(pose.linear() * o.pose.linear().transpose());
  o.moved += (pose.translation() - o.pose.translation()).norm() + logRotation(dq).norm() * o.reach;
  o.pose = pose;
}

Isometry3 SphereTree6DofRenderer::graphicPose() const noexcept {
  Isometry3 pose = Isometry3::Identity();
  pose.linear() = s_->qg.toRotationMatrix();
  pose.translation() = s_->pg;
  return pose;
}

int SphereTree6DofRenderer::toolLevel() const noexcept { return s_->level; }
std::size_t SphereTree6DofRenderer::toolSphereCount() const noexcept { return s_->levelEnd - s_->levelBegin; }
double SphereTree6DofRenderer::toolSphereMaxRadius() const noexcept { return s_->toolMaxRadius; }
double SphereTree6DofRenderer::environmentLeafMaxRadius() const noexcept { return s_->envMaxLeafRadius; }
std::size_t SphereTree6DofRenderer::lastCandidateCount() const noexcept { return s_->candidates; }
Vec3 SphereTree6DofRenderer::objectForce(std::size_t index) const noexcept {
  return index < s_->objects.size() ? s_->objects[index].force : Vec3::Zero();
}
Vec3 SphereTree6DofRenderer::objectTorque(std::size_t index) const noexcept {
  return index < s_->objects.size() ? s_->objects[index].torque : Vec3::Zero();
}
bool SphereTree6DofRenderer::objectReleased(std::size_t index) const noexcept {
  return index < s_->objects.size() && s_->objects[index].released;
}

}  // namespace dm
