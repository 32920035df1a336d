// Impulse-based bone fragment placement; see dm/haptics/bone_placement.hpp.
#include <dm/haptics/bone_placement.hpp>
#include <dm/haptics/safety.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

#include "option_rules.hpp"

namespace dm {

namespace {

constexpr const char* kWhere = "dm::BonePlacementRenderer::create";

Status checkOptions(const BonePlacementOptions& o) {
  using haptics_detail::OptionRule;
  const auto finite = [](double v) { return std::isfinite(v); };
  const auto coupling = haptics_detail::couplingRules(o.couplingStiffness, o.couplingDamping,
                                                      o.couplingAngularStiffness, o.couplingAngularDamping);
  const OptionRule rules[] = {
      {"mass", o.mass, finite(o.mass) && o.mass >= 0, "finite and >= 0 kg (0: from the voxels)"},
      {"density", o.density, finite(o.density) && o.density > 0, "finite and > 0 kg/m^3"},
      {"threshold", o.threshold, finite(o.threshold), "finite"},
      {"maxContacts", static_cast<double>(o.maxContacts), o.maxContacts >= 1 && o.maxContacts <= 4096,
       "between 1 and 4096"},
      {"iterations", static_cast<double>(o.iterations), o.iterations >= 1 && o.iterations <= 100,
       "between 1 and 100"},
      {"contactLevel", static_cast<double>(o.contactLevel), o.contactLevel >= 0 && o.contactLevel <= 4,
       "between 0 (voxels) and 4 (cells of 16^3 voxels)"},
      {"slop", o.slop, finite(o.slop), "finite (negative: automatic)"},
      {"baumgarte", o.baumgarte, finite(o.baumgarte) && o.baumgarte >= 0 && o.baumgarte <= 1, "in [0, 1]"},
      {"maxForce", o.maxForce, !std::isnan(o.maxForce) && o.maxForce > 0, "> 0 N (infinity allowed)"},
      {"maxTorque", o.maxTorque, !std::isnan(o.maxTorque) && o.maxTorque > 0, "> 0 N*m (infinity allowed)"},
      {"stackCapacity", static_cast<double>(o.stackCapacity),
       o.stackCapacity >= 64 && o.stackCapacity <= (std::size_t{1} << 20), "between 64 and 1048576"},
  };
  if (auto s = haptics_detail::checkOptionRules(coupling, kWhere, "BonePlacementOptions"); !s) return s;
  return haptics_detail::checkOptionRules(rules, kWhere, "BonePlacementOptions");
}

// Min-heap on depth: the shallowest kept contact sits at the front.
bool deeper(const BoneContact& a, const BoneContact& b) noexcept { return a.depth > b.depth; }

}  // namespace

Result<VoxelMassProperties> voxelMassProperties(const Volume& volume, double threshold, double density) {
  const char* where = "dm::voxelMassProperties";
  if (volume.empty())
    return fail(ErrorCode::InvalidArgument, "occupancy volume is empty", where,
                "pass a non-empty label volume");
  if (!std::isfinite(density) || density <= 0)
    return fail(ErrorCode::InvalidArgument, formatString("density is %g; it must be finite and > 0", density),
                std::string(where) + ": density", "pass kg/m^3, e.g. 1900 for cortical bone");
  const Vec3i& dims = volume.dims();
  const Affine3& a = volume.indexToWorld();
  const Mat3 lin = a.linear();
  // First pass: count and first moments; second: second moments about the
  // centroid (two passes keep the sums well conditioned far from the origin).
  std::size_t n = 0;
  Vec3 sum = Vec3::Zero();
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i)
        if (volume.valueAt(volume.linearIndex(i, j, k)) > threshold) {
          ++n;
          sum += a * Vec3(i, j, k);
        }
  if (n == 0)
    return fail(ErrorCode::InvalidArgument,
                formatString("no voxel of the occupancy volume is above the threshold %g", threshold),
                std::string(where) + ": volume", "check the label volume and options.threshold");
  VoxelMassProperties mp;
  mp.voxels = n;
  const double voxelMass = density * std::abs(lin.determinant());
  mp.mass = voxelMass * static_cast<double>(n);
  mp.centerOfMass = sum / static_cast<double>(n);
  Mat3 second = Mat3::Zero();  // Σ (p − c)(p − c)ᵀ
  for (int k = 0; k < dims.z(); ++k)
    for (int j = 0; j < dims.y(); ++j)
      for (int i = 0; i < dims.x(); ++i)
        if (volume.valueAt(volume.linearIndex(i, j, k)) > threshold) {
          const Vec3 d = a * Vec3(i, j, k) - mp.centerOfMass;
          second += d * d.transpose();
        }
  // Covariance of the voxels' uniform parallelepipeds about their centres.
  const Mat3 own = static_cast<double>(n) * lin * lin.transpose() / 12.0;
  const Mat3 c = voxelMass * (second + own);
  mp.inertia = c.trace() * Mat3::Identity() - c;
  return mp;
}

Result<std::unique_ptr<BonePlacementRenderer>> BonePlacementRenderer::create(
    std::shared_ptr<const ImplicitSphereTree> fixed, const Isometry3& fixedPose,
    std::shared_ptr<const ImplicitSphereTree> moving, const Volume& movingOccupancy,
    const BonePlacementOptions& options) {
  const std::string where = kWhere;
  if (!fixed)
    return fail(ErrorCode::InvalidArgument, "fixed fragment tree is null", where + ": fixed",
                "build one with dm::ImplicitSphereTree::create(labels, threshold)");
  if (!moving)
    return fail(ErrorCode::InvalidArgument, "moving fragment tree is null", where + ": moving",
                "build one with dm::ImplicitSphereTree::create(labels, threshold)");
  if (!isRigidPose(fixedPose))
    return fail(ErrorCode::InvalidArgument, "fixedPose is not finite or not a rigid transform",
                where + ": fixedPose", "pass a rotation (orthonormal, det +1) and a finite translation");
  if (Status s = checkOptions(options); !s) return s.error();
  auto mp = voxelMassProperties(movingOccupancy, options.threshold, options.density);
  if (!mp)
    return fail(ErrorCode::InvalidArgument, mp.error().what, where + ": movingOccupancy",
                "pass the volume the moving tree was built from, with options.threshold/density");

  std::unique_ptr<BonePlacementRenderer> r(new BonePlacementRenderer());
  r->fixed_ = std::move(fixed);
  r->moving_ = std::move(moving);
  r->fixedPose_ = fixedPose;
  r->options_ = options;
  r->massProps_ = *mp;
  if (options.mass > 0) {
    r->massProps_.inertia *= options.mass / r->massProps_.mass;
    r->massProps_.mass = options.mass;
  }
  r->inertiaBodyInverse_ = r->massProps_.inertia.inverse();
  r->contactDepthF_ = std::max(0, r->fixed_->depth() - options.contactLevel);
  r->contactDepthM_ = std::max(0, r->moving_->depth() - options.contactLevel);
  if (options.slop >= 0) {
    r->slop_ = options.slop;
  } else {
    const double rf = r->fixed_->cellSphere(r->contactDepthF_, 0, 0, 0).radius;
    const double rm = r->moving_->cellSphere(r->contactDepthM_, 0, 0, 0).radius;
    // Cubic cells: radius = h·√3/2; face neighbours are the smaller h apart.
    r->slop_ = std::max(0.0, rf + rm - 2.0 * std::min(rf, rm) / std::sqrt(3.0));
  }
  r->stack_.resize(options.stackCapacity);
  r->contacts_.resize(static_cast<std::size_t>(options.maxContacts));
  r->rows_.resize(r->contacts_.size());
  r->active_.resize(r->contacts_.size());
  r->reset(Isometry3::Identity());
  return r;
}

void BonePlacementRenderer::reset(const Isometry3& devicePose) noexcept {
  if (!devicePose.matrix().allFinite()) return;
  orientation_ = Quat(devicePose.linear()).normalized();
  position_ = devicePose * massProps_.centerOfMass;
  velocity_.setZero();
  angularVelocity_.setZero();
  contactCount_ = 0;
  maxDepth_ = 0.0;
}

void BonePlacementRenderer::setObjectPose(std::size_t index, const Isometry3& pose) noexcept {
  if (index != 0 || !isRigidPose(pose)) return;
  fixedPose_ = pose;
}

Isometry3 BonePlacementRenderer::fragmentPose() const noexcept {
  Isometry3 p = Isometry3::Identity();
  p.linear() = orientation_.toRotationMatrix();
  p.translation() = position_ - p.linear() * massProps_.centerOfMass;
  return p;
}

double BonePlacementRenderer::alignmentError(std::span<const Vec3> referencePointsInMovingFrame,
                                             const Isometry3& targetPose) const noexcept {
  return boneAlignmentError(referencePointsInMovingFrame, fragmentPose(), targetPose);
}

double boneAlignmentError(std::span<const Vec3> points, const Isometry3& pose,
                          const Isometry3& target) noexcept {
  if (points.empty()) return 0.0;
  double sum = 0.0;
  for (const Vec3& p : points) sum += (pose * p - target * p).squaredNorm();
  return std::sqrt(sum / static_cast<double>(points.size()));
}

void BonePlacementRenderer::offerContact(const Vec3& cFixed, double rFixed, const Vec3& cMoving,
                                         double rMoving) noexcept {
  const Vec3 a = fixedPose_ * cFixed;
  const Vec3 b = fixedPose_ * cMoving;
  const Vec3 d = b - a;
  const double dist = d.norm();
  BoneContact c;
  if (dist > 1e-12 * (rFixed + rMoving)) {
    c.normal = d / dist;
  } else {
    // Coincident centres: push away from the fixed fragment's root sphere.
    const Vec3 away = position_ - fixedPose_ * fixed_->cellSphere(0, 0, 0, 0).center;
    c.normal = away.norm() > 0 ? Vec3(away.normalized()) : Vec3::UnitZ();
  }
  c.depth = rFixed + rMoving - dist;
  c.point = a + c.normal * (rFixed - 0.5 * c.depth);
  const std::size_t cap = contacts_.size();
  BoneContact* heap = contacts_.data();
  if (contactCount_ < cap) {
    heap[contactCount_++] = c;
    std::push_heap(heap, heap + contactCount_, deeper);
  } else if (c.depth > heap[0].depth) {
    std::pop_heap(heap, heap + cap, deeper);
    heap[cap - 1] = c;
    std::push_heap(heap, heap + cap, deeper);
  }
}

namespace {

// The sphere of cell (l, i, j, k) of an implicit tree mapped by a rigid
// transform, as an affine function of the cell's indices: centre =
// a·(i, j, k) + b, radius r. One per level, set up once a tick, so the
// descent computes a sphere with nine multiplications.
struct LevelMap {
  Mat3 a;
  Vec3 b;
  double r;
  Vec3 centre(int i, int j, int k) const noexcept {
    const double x = i, y = j, z = k;
    return {a(0, 0) * x + a(0, 1) * y + a(0, 2) * z + b.x(), a(1, 0) * x + a(1, 1) * y + a(1, 2) * z + b.y(),
            a(2, 0) * x + a(2, 1) * y + a(2, 2) * z + b.z()};
  }
};
using LevelMaps = std::array<LevelMap, ImplicitSphereTree::kMaxDepth + 1>;

void mapLevels(const ImplicitSphereTree& tree, const Isometry3& pose, LevelMaps& out) noexcept {
  for (int l = 0; l <= tree.depth(); ++l) {
    const BoundingSphere o = tree.cellSphere(l, 0, 0, 0);
    LevelMap& m = out[static_cast<std::size_t>(l)];
    m.b = pose * o.center;
    m.r = o.radius;
    m.a.col(0) = pose.linear() * (tree.cellSphere(l, 1, 0, 0).center - o.center);
    m.a.col(1) = pose.linear() * (tree.cellSphere(l, 0, 1, 0).center - o.center);
    m.a.col(2) = pose.linear() * (tree.cellSphere(l, 0, 0, 1).center - o.center);
  }
}

// The occupied contact cells under one cell of a tree at the contact level
// or the one above (the cell itself, or its occupied children: ≤ 8), with
// their centres. The descent meets the same cell with several partners in a
// row (a split pushes one side's children against the same other node), so
// the last cell's are kept.
struct BlockCells {
  ImplicitSphereTree::NodeId node = ~ImplicitSphereTree::NodeId{0};
  int count = 0;
  std::array<Vec3, 8> centres;

  void fill(const ImplicitSphereTree& tree, int contactDepth, const LevelMap& leaf,
            ImplicitSphereTree::NodeId id, int l, int i, int j, int k) noexcept {
    if (id == node) return;
    node = id;
    count = 0;
    if (l == contactDepth) {
      centres[0] = leaf.centre(i, j, k);
      count = 1;
      return;
    }
    const unsigned mask = tree.childMask(l, i, j, k);
    for (unsigned q = 0; q < 8; ++q)
      if (mask >> q & 1u)
        centres[static_cast<std::size_t>(count++)] =
            leaf.centre(2 * i + int(q & 1u), 2 * j + int(q >> 1 & 1u), 2 * k + int(q >> 2 & 1u));
  }
  // Those closer than `reach` to `other` into `out`; their number.
  int near(const Vec3& other, double reach, std::array<Vec3, 8>& out) const noexcept {
    int n = 0;
    for (int q = 0; q < count; ++q) {
      const Vec3& c = centres[static_cast<std::size_t>(q)];
      if ((c - other).squaredNorm() < reach * reach) out[static_cast<std::size_t>(n++)] = c;
    }
    return n;
  }
};

}  // namespace

void BonePlacementRenderer::findContacts() noexcept {
  contactCount_ = 0;
  maxDepth_ = 0.0;
  // Both trees' spheres in the fixed fragment's frame.
  movingToFixed_ = fixedPose_.inverse(Eigen::Isometry) * fragmentPose();
  const ImplicitSphereTree& tf = *fixed_;
  const ImplicitSphereTree& tm = *moving_;
  // The contact level: the voxels, or cells `contactLevel` levels above them.
  const int depthF = contactDepthF_;
  const int depthM = contactDepthM_;
  LevelMaps mapF, mapM;
  mapLevels(tf, Isometry3::Identity(), mapF);
  mapLevels(tm, movingToFixed_, mapM);
  // Only leaf pairs deeper than 0.9·slop act (the shallower ones are the
  // resting overlap of touching voxels), so every test asks for that much
  // overlap: a leaf lies within (R − r) of its ancestor's centre, so two
  // cells closer than R1 + R2 − 0.9·slop are the only ones that can hold
  // such a pair. Most overlapping pairs of a face in contact are shallow
  // diagonal neighbours: this prunes them, and the cells above them.
  const double margin = 0.9 * slop_;
  const auto overlap = [margin](const Vec3& c1, double r1, const Vec3& c2, double r2) {
    const double s = r1 + r2 - margin;
    return s > 0.0 && (c1 - c2).squaredNorm() < s * s;
  };
  if (!overlap(mapF[0].b, mapF[0].r, mapM[0].b, mapM[0].r)) return;
  // A second, tighter test where spheres are loose (along the grid axes a
  // cell's sphere reaches √3 times its half-width): the contact-cell centres
  // under a cell lie in a box, cell centre ± (n − 1)/2 contact steps along
  // its tree's axes (n contact cells a side). Projected on the fixed grid's
  // axes u_k, two such boxes come no closer than |u_k·(c₁ − c₂)| − h₁ − h₂,
  // and an acting pair is closer than `reach` on every axis.
  const LevelMap& contactF = mapF[static_cast<std::size_t>(depthF)];
  const LevelMap& contactM = mapM[static_cast<std::size_t>(depthM)];
  Mat3 axes;
  for (int k = 0; k < 3; ++k) axes.row(k) = contactF.a.col(k).normalized().transpose();
  const Vec3 stepF = (axes * contactF.a).cwiseAbs().rowwise().sum();
  const Vec3 stepM = (axes * contactM.a).cwiseAbs().rowwise().sum();
  std::array<Vec3, ImplicitSphereTree::kMaxDepth + 1> boxF, boxM;
  for (int l = 0; l <= depthF; ++l)
    boxF[static_cast<std::size_t>(l)] = 0.5 * ((1 << (depthF - l)) - 1) * stepF;
  for (int l = 0; l <= depthM; ++l)
    boxM[static_cast<std::size_t>(l)] = 0.5 * ((1 << (depthM - l)) - 1) * stepM;
  const double reach = contactF.r + contactM.r - margin;
  const auto boxesMeet = [&](const Vec3& cf, int lf, const Vec3& cm, int lm) {
    const Vec3 gap = (axes * (cf - cm)).cwiseAbs();
    return (gap.array() <
            (boxF[static_cast<std::size_t>(lf)] + boxM[static_cast<std::size_t>(lm)]).array() + reach)
        .all();
  };
  std::size_t top = 0;
  stack_[top++] = {tf.root(), tm.root()};
  std::array<Vec3, 8> centresF, centresM;
  BlockCells blockF, blockM;
  while (top > 0) {
    const Pair p = stack_[--top];
    int lf = 0, fi = 0, fj = 0, fk = 0, lm = 0, mi = 0, mj = 0, mk = 0;
    ImplicitSphereTree::unpack(p.fixedNode, lf, fi, fj, fk);
    ImplicitSphereTree::unpack(p.movingNode, lm, mi, mj, mk);
    const LevelMap& mf = mapF[static_cast<std::size_t>(lf)];
    const LevelMap& mm = mapM[static_cast<std::size_t>(lm)];
    if (lf >= depthF - 1 && lm >= depthM - 1) {
      // Near the leaves: the occupied leaves under one that come near the
      // other's sphere against those of the other, without the stack.
      const LevelMap& leafF = mapF[static_cast<std::size_t>(depthF)];
      const LevelMap& leafM = mapM[static_cast<std::size_t>(depthM)];
      const Vec3 cf = mf.centre(fi, fj, fk), cm = mm.centre(mi, mj, mk);
      blockF.fill(tf, depthF, leafF, p.fixedNode, lf, fi, fj, fk);
      const int nf = blockF.near(cm, leafF.r + mm.r - margin, centresF);
      if (nf == 0) continue;
      blockM.fill(tm, depthM, leafM, p.movingNode, lm, mi, mj, mk);
      const int nm = blockM.near(cf, leafM.r + mf.r - margin, centresM);
      for (int a = 0; a < nf; ++a)
        for (int b = 0; b < nm; ++b)
          if (overlap(centresF[static_cast<std::size_t>(a)], leafF.r, centresM[static_cast<std::size_t>(b)],
                      leafM.r))
            offerContact(centresF[static_cast<std::size_t>(a)], leafF.r,
                         centresM[static_cast<std::size_t>(b)], leafM.r);
      continue;
    }
    // Split the larger sphere (the only one left with children otherwise);
    // skip a level when it is much larger than the other.
    const bool splitFixed = lm == depthM || (lf < depthF && mf.r >= mm.r);
    const ImplicitSphereTree& t = splitFixed ? tf : tm;
    const int level = splitFixed ? lf : lm;
    const int leafLevel = splitFixed ? depthF : depthM;
    const double big = splitFixed ? mf.r : mm.r;
    const double small = splitFixed ? mm.r : mf.r;
    const Vec3 other = splitFixed ? mm.centre(mi, mj, mk) : mf.centre(fi, fj, fk);
    const int skip = (big > 4.0 * small && leafLevel - level >= 2) ? 2 : 1;
    const int childLevel = level + skip;
    const LevelMap& mc = (splitFixed ? mapF : mapM)[static_cast<std::size_t>(childLevel)];
    const int otherLevel = splitFixed ? lm : lf;
    const auto visit = [&](int i, int j, int k) {
      const Vec3 c = mc.centre(i, j, k);
      if (!overlap(c, mc.r, other, small)) return;
      if (!(splitFixed ? boxesMeet(c, childLevel, other, otherLevel)
                       : boxesMeet(other, otherLevel, c, childLevel)))
        return;
      if (top == stack_.size()) {
        ++stackOverflows_;
        return;
      }
      const ImplicitSphereTree::NodeId child = ImplicitSphereTree::nodeId(childLevel, i, j, k);
      stack_[top++] = splitFixed ? Pair{child, p.movingNode} : Pair{p.fixedNode, child};
    };
    // The occupied children (or grandchildren) from the tree's child masks.
    const int pi = splitFixed ? fi : mi, pj = splitFixed ? fj : mj, pk = splitFixed ? fk : mk;
    const unsigned mask = t.childMask(level, pi, pj, pk);
    for (unsigned q = 0; q < 8; ++q) {
      if (!(mask >> q & 1u)) continue;
      const int ci = 2 * pi + int(q & 1u), cj = 2 * pj + int(q >> 1 & 1u), ck = 2 * pk + int(q >> 2 & 1u);
      if (skip == 1) {
        visit(ci, cj, ck);
        continue;
      }
      const unsigned grand = t.childMask(level + 1, ci, cj, ck);
      for (unsigned g = 0; g < 8; ++g)
        if (grand >> g & 1u)
          visit(2 * ci + int(g & 1u), 2 * cj + int(g >> 1 & 1u), 2 * ck + int(g >> 2 & 1u));
    }
  }
  for (std::size_t i = 0; i < contactCount_; ++i) maxDepth_ = std::max(maxDepth_, contacts_[i].depth);
}

void BonePlacementRenderer::solveContacts(double dt, Vec3& pseudoVelocity, Vec3& pseudoAngular) noexcept {
  pseudoVelocity.setZero();
  pseudoAngular.setZero();
  if (contactCount_ == 0) return;
  const Mat3 rot = orientation_.toRotationMatrix();
  const Mat3 inertiaInv = rot * inertiaBodyInverse_ * rot.transpose();
  const double invMass = 1.0 / massProps_.mass;
  // Each pair's lever arm, angular response and effective mass hold for the
  // whole tick (the pose moves after the solve).
  for (std::size_t i = 0; i < contactCount_; ++i) {
    BoneContact& c = contacts_[i];
    c.impulse = c.correction = 0.0;
    SolverRow& row = rows_[i];
    row.r = c.point - position_;
    row.angular = inertiaInv * row.r.cross(c.normal);
    row.effMass = 1.0 / (invMass + row.r.cross(c.normal).dot(row.angular));
  }
  // Pass 0: velocity impulses (restitution 0); pass 1: split impulses that
  // push out the depth beyond the slop through a pseudo-velocity used for
  // this tick's pose update only, so the correction adds no momentum.
  for (int pass = 0; pass < 2; ++pass) {
    Vec3& v = pass == 0 ? velocity_ : pseudoVelocity;
    Vec3& w = pass == 0 ? angularVelocity_ : pseudoAngular;
    // Pairs within the resting overlap of touching voxels do not stop motion
    // (the 0.9 margin keeps a resting contact active) and only the depth
    // beyond the slop is pushed out: each pass sweeps its own pairs, in order.
    std::size_t count = 0;
    for (std::size_t i = 0; i < contactCount_; ++i)
      if (contacts_[i].depth > (pass == 0 ? 0.9 * slop_ : slop_))
        active_[count++] = static_cast<std::uint32_t>(i);
    for (int it = 0; it < options_.iterations; ++it) {
      for (std::size_t n = 0; n < count; ++n) {
        const std::uint32_t i = active_[n];
        BoneContact& c = contacts_[i];
        double& accumulated = pass == 0 ? c.impulse : c.correction;
        const double target = pass == 0 ? 0.0 : options_.baumgarte * std::max(0.0, c.depth - slop_) / dt;
        const SolverRow& row = rows_[i];
        const double vn = c.normal.dot(v + w.cross(row.r));
        const double next = std::max(0.0, accumulated + row.effMass * (target - vn));
        const double delta = next - accumulated;
        accumulated = next;
        v += (delta * invMass) * c.normal;
        w += delta * row.angular;
      }
    }
  }
}

HapticResponse BonePlacementRenderer::tick(const HapticInput& input) noexcept {
  HapticResponse out;
  out.proxyPose = fragmentPose();
  if (!input.devicePose.matrix().allFinite() || !input.linearVelocity.allFinite() ||
      !input.angularVelocity.allFinite() || !std::isfinite(input.dt) || input.dt <= 0.0)
    return out;
  const double dt = input.dt;
  const double m = massProps_.mass;
  const BonePlacementOptions& o = options_;
  const Isometry3& device = input.devicePose;
  const Vec3 target = device * massProps_.centerOfMass;
  const Vec3 targetVelocity =
      input.linearVelocity + input.angularVelocity.cross(target - device.translation());

  // 1. Coupling, linearly implicit (spring and damper at the end of the step).
  velocity_ = (m * velocity_ +
               dt * (o.couplingStiffness * (target - position_) + o.couplingDamping * targetVelocity)) /
              (m + dt * o.couplingDamping + dt * dt * o.couplingStiffness);
  {
    const Mat3 rot = orientation_.toRotationMatrix();
    const Mat3 inertia = rot * massProps_.inertia * rot.transpose();
    const Vec3 theta = rotationDelta(out.proxyPose, device);
    const Mat3 lhs =
        inertia + (dt * o.couplingAngularDamping + dt * dt * o.couplingAngularStiffness) * Mat3::Identity();
    const Vec3 rhs = inertia * angularVelocity_ + dt * (o.couplingAngularStiffness * theta +
                                                        o.couplingAngularDamping * input.angularVelocity);
    angularVelocity_ = lhs.inverse() * rhs;
  }

  // 2. Contacts at the current pose, simultaneous normal impulses.
  findContacts();
  Vec3 pseudoVelocity, pseudoAngular;
  solveContacts(dt, pseudoVelocity, pseudoAngular);

  // 3. Pose, with the position correction's pseudo-velocities.
  position_ += dt * (velocity_ + pseudoVelocity);
  const Vec3 spin = angularVelocity_ + pseudoAngular;
  const double angle = spin.norm() * dt;
  if (angle > 0.0) orientation_ = Quat(AngleAxis(angle, spin.normalized())) * orientation_;
  orientation_.normalize();

  const Isometry3 pose = fragmentPose();
  const Vec3 couplingForce =
      o.couplingStiffness * (target - position_) + o.couplingDamping * (targetVelocity - velocity_);
  const Vec3 couplingTorque = o.couplingAngularStiffness * rotationDelta(pose, device) +
                              o.couplingAngularDamping * (input.angularVelocity - angularVelocity_);
  out.force = -couplingForce;
  out.torque = -couplingTorque;
  sanitizeWrench(out.force, out.torque, o.maxForce, o.maxTorque);
  out.proxyPose = pose;
  out.contacts = static_cast<int>(contactCount_);
  out.penetration = contactCount_ > 0 ? (device.translation() - pose.translation()).norm() : 0.0;
  return out;
}

std::vector<Vec3> boneReferencePoints(const Volume& volume, double threshold) {
  std::vector<Vec3> voxels;
  const Vec3i d = volume.dims();
  for (int k = 0; k < d.z(); ++k)
    for (int j = 0; j < d.y(); ++j)
      for (int i = 0; i < d.x(); ++i)
        if (volume.value(i, j, k) > threshold) voxels.push_back(volume.indexToWorld() * Vec3(i, j, k));
  std::vector<Vec3> points;
  if (voxels.empty()) return points;
  Vec3 centroid = Vec3::Zero();
  for (const Vec3& p : voxels) centroid += p;
  centroid /= static_cast<double>(voxels.size());
  for (int axis = 0; axis < 3; ++axis)
    for (double sign : {-1.0, 1.0})
      points.push_back(*std::max_element(voxels.begin(), voxels.end(), [&](const Vec3& a, const Vec3& b) {
        return sign * a[axis] < sign * b[axis];
      }));
  points.push_back(*std::min_element(voxels.begin(), voxels.end(), [&](const Vec3& a, const Vec3& b) {
    return (a - centroid).squaredNorm() < (b - centroid).squaredNorm();
  }));
  return points;
}

}  // namespace dm
