// The spring–sphere-tree soft object; see
// dm/haptics/sphere_tree_deformation.hpp for the model.
#include <dm/haptics/sphere_tree_deformation.hpp>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <utility>

namespace dm {

namespace {

constexpr double kTouching = 1.05;  // skeleton spheres this close (× r_i + r_j) are linked
constexpr int kWeights = SphereTreeDeformation::kWeights;  // skeleton nodes per interpolated point
using Index = std::array<std::uint32_t, kWeights>;
using Weights = std::array<double, kWeights>;
using Gradients = std::array<Vec3, kWeights>;
constexpr double kRidge = 0.02;  // the slope's regularisation, a share of the weights' sum

// The interpolation at `x` over its kWeights nearest skeleton centres:
// linear moving least squares (weights (1 − (r/h)²)², h 1.5 × the farthest
// of them), so that an affine displacement field is reproduced exactly,
// value and gradient (the fitted slope: a bent tongue's surface turns as
// its skeleton does). u(x) = Σ w_k d_k, ∇u(x) = Σ d_k g_kᵀ. Where the
// centres cannot fix a plane (fewer than four, or coplanar), Shepard
// weights and a zero gradient.
void interpolation(const Vec3& x, std::span<const Vec3> centres, Index& idx, Weights& w, Gradients& g) {
  Weights d2;
  d2.fill(std::numeric_limits<double>::infinity());
  idx.fill(0);
  for (std::size_t j = 0; j < centres.size(); ++j) {
    double dj = (x - centres[j]).squaredNorm();
    auto id = static_cast<std::uint32_t>(j);
    for (std::size_t k = 0; k < kWeights; ++k)
      if (dj < d2[k]) {
        std::swap(dj, d2[k]);
        std::swap(id, idx[k]);
      }
  }
  std::size_t n = 0;
  while (n < kWeights && std::isfinite(d2[n])) ++n;
  const double h = 1.5 * std::sqrt(d2[n - 1]) + 1e-300;
  Eigen::Matrix4d m = Eigen::Matrix4d::Zero();
  Weights kernel{};
  for (std::size_t k = 0; k < n; ++k) {
    const double q = 1.0 - d2[k] / (h * h);
    kernel[k] = q * q;
    Eigen::Vector4d p;
    p << 1.0, (centres[idx[k]] - x) / h;
    m += kernel[k] * p * p.transpose();
  }
  // Ridge on the slope: a surface tree's skeleton is a shell, nearly
  // coplanar around a point, and its slope along the normal is not
  // determined by it (unregularised, the weights grow without bound).
  double kernelSum = 0.0;
  for (std::size_t k = 0; k < n; ++k) kernelSum += kernel[k];
  m.diagonal().tail<3>() += Eigen::Vector3d::Constant(kRidge * kernelSum);
  w.fill(0.0);
  g.fill(Vec3::Zero());
  const Eigen::JacobiSVD<Eigen::Matrix4d> svd(m);
  const auto sv = svd.singularValues();
  if (n >= 4 && sv(3) > 1e-8 * sv(0)) {
    const Eigen::Matrix4d a = m.inverse();
    for (std::size_t k = 0; k < n; ++k) {
      Eigen::Vector4d p;
      p << 1.0, (centres[idx[k]] - x) / h;
      const Eigen::Vector4d c = kernel[k] * (a * p);
      w[k] = c(0);
      g[k] = c.tail<3>() / h;
    }
    return;
  }
  if (d2[0] == 0.0) {  // on a centre: that node's displacement
    w[0] = 1.0;
    return;
  }
  double sum = 0.0;
  for (std::size_t k = 0; k < n; ++k) sum += w[k] = 1.0 / d2[k];
  for (std::size_t k = 0; k < n; ++k) w[k] /= sum;
}

}  // namespace

struct SphereTreeDeformation::State {
  std::shared_ptr<const SphereTree> rest;
  SphereTreeDeformationOptions opt;
  // Skeleton.
  std::vector<std::uint32_t> skel;  // tree node of skeleton node i
  std::vector<Vec3> skelCentre;     // rest centres
  std::vector<std::uint8_t> isFixed;
  std::vector<int> freeIndex;                    // skeleton → row of the system (−1: fixed)
  std::vector<std::uint32_t> freeSkel;           // row → skeleton
  std::vector<double> mass;                      // per skeleton node
  std::vector<std::uint32_t> linkStart, linkTo;  // CSR over skeleton nodes
  Eigen::MatrixXd ainv;                          // (M + hC + h²K)⁻¹ over the free rows
  // Dynamics (per skeleton node; fixed ones stay zero).
  std::vector<Vec3> d, v, f;
  std::vector<Vec3> rhs, prev;  // per free row
  double acc = 0.0;
  Vec3 support = Vec3::Zero();
  // Every tree node: weights, displacement, deformed copy.
  std::vector<Index> wIdx;
  std::vector<Weights> w;
  std::vector<Gradients> wGrad;  // the gradient weights at the node's rest centre
  // Σ|w| (1 for convex weights; MLS weights may be negative): per internal
  // node the largest of the leaves below (their motion relative to it is at
  // most that times the skeleton's), and the largest of all.
  std::vector<double> reachScale;
  double maxScale = 1.0;
  // Per internal node: the skeleton nodes any leaf below it is weighted on
  // (CSR), so |disp(leaf) − disp(node)| ≤ max over them of |d_j − disp(node)|.
  std::vector<std::uint32_t> reachStart, reach;
  // Deformed bounds, evaluated when first asked for in an epoch (a step).
  std::uint32_t epoch = 1;
  mutable std::vector<std::uint32_t> cacheEpoch;
  mutable std::vector<BoundingSphere> cache;

  // k_a d_i + Σ_j k_l (d_i − d_j): the springs' force on skeleton node i, negated.
  Vec3 springForce(std::size_t i) const noexcept {
    Vec3 s = opt.anchorStiffness * d[i];
    for (std::uint32_t e = linkStart[i]; e < linkStart[i + 1]; ++e)
      s += opt.linkStiffness * (d[i] - d[linkTo[e]]);
    return s;
  }

  void substep() noexcept {
    const double h = opt.timeStep;
    const std::size_t nf = freeSkel.size();
    for (std::size_t r = 0; r < nf; ++r) {
      const std::uint32_t i = freeSkel[r];
      rhs[r] = mass[i] * v[i] + h * (f[i] - springForce(i));
    }
    for (std::size_t r = 0; r < nf; ++r) {
      Vec3 vn = Vec3::Zero();
      const double* row = ainv.data() + r * nf;  // symmetric: column r is row r
      for (std::size_t c = 0; c < nf; ++c) vn += row[c] * rhs[c];
      v[freeSkel[r]] = vn;
    }
    for (std::size_t r = 0; r < nf; ++r) d[freeSkel[r]] += h * v[freeSkel[r]];
  }

  void updateSupport() noexcept {
    support = Vec3::Zero();
    for (std::size_t i = 0; i < skel.size(); ++i) {
      if (isFixed[i]) continue;
      support -= opt.anchorStiffness * d[i];
      for (std::uint32_t e = linkStart[i]; e < linkStart[i + 1]; ++e)
        if (isFixed[linkTo[e]]) support -= opt.linkStiffness * d[i];
    }
  }

  Vec3 disp(std::size_t n) const noexcept {
    Vec3 x = Vec3::Zero();
    for (std::size_t k = 0; k < kWeights; ++k) x += w[n][k] * d[wIdx[n][k]];
    return x;
  }

  // The deformed node's bound: its centre displaced, its radius grown by
  // how far the leaves below can have moved relative to it (0 at a leaf,
  // whose sphere moves rigidly).
  BoundingSphere bound(std::size_t n) const noexcept {
    if (cacheEpoch[n] == epoch) return cache[n];
    const SphereTreeNode& r = rest->nodes()[n];
    const Vec3 x = disp(n);
    double g = 0.0;
    for (std::uint32_t e = reachStart[n]; e < reachStart[n + 1]; ++e)
      g = std::max(g, (d[reach[e]] - x).norm());
    cacheEpoch[n] = epoch;
    cache[n] = {r.center + x, r.boundRadius + reachScale[n] * g};
    return cache[n];
  }
};

SphereTreeDeformation::SphereTreeDeformation(std::unique_ptr<State> s) noexcept : s_(std::move(s)) {}
SphereTreeDeformation::~SphereTreeDeformation() = default;

Result<std::shared_ptr<SphereTreeDeformation>> SphereTreeDeformation::create(
    std::shared_ptr<const SphereTree> rest, const SphereTreeDeformationOptions& options) {
  const auto bad = [](std::string what, std::string field, std::string hint = "") -> Error {
    return fail(ErrorCode::InvalidArgument, std::move(what), std::move(field), std::move(hint));
  };
  const SphereTreeDeformationOptions& o = options;
  if (!rest) return bad("the rest sphere tree is null", "tree", "build it with dm::buildSphereTreeFitted()");
  if (o.skeletonLevel < 0 || o.skeletonLevel >= rest->levelCount())
    return bad(formatString("skeletonLevel is %d but the tree has levels 0..%d", o.skeletonLevel,
                            rest->levelCount() - 1),
               "options.skeletonLevel");
  const std::span<const SphereTreeNode> level = rest->level(o.skeletonLevel);
  if (level.size() > static_cast<std::size_t>(kMaxSkeletonNodes))
    return bad(formatString("skeleton level %d has %zu nodes; at most %d", o.skeletonLevel, level.size(),
                            kMaxSkeletonNodes),
               "options.skeletonLevel", "use a coarser level");
  const auto check = [&](double x, bool positive, const char* name, const char* unit) -> Status {
    if (std::isfinite(x) && (positive ? x > 0 : x >= 0)) return {};
    return bad(
        formatString("%s is %g %s; it must be finite and %s", name, x, unit, positive ? "> 0" : ">= 0"),
        std::string("options.") + name);
  };
  if (Status s = check(o.mass, true, "mass", "kg"); !s) return s.error();
  if (Status s = check(o.anchorStiffness, false, "anchorStiffness", "N/m"); !s) return s.error();
  if (Status s = check(o.linkStiffness, false, "linkStiffness", "N/m"); !s) return s.error();
  if (Status s = check(o.damping, false, "damping", "N*s/m"); !s) return s.error();
  if (Status s = check(o.timeStep, true, "timeStep", "s"); !s) return s.error();
  if (o.fixedRegion && !(o.fixedRegion->min().allFinite() && o.fixedRegion->max().allFinite()))
    return bad("fixedRegion is not finite", "options.fixedRegion");

  auto st = std::make_unique<State>();
  State& s = *st;
  s.opt = o;
  const std::size_t n = level.size();
  const auto first = static_cast<std::uint32_t>(level.data() - rest->nodes().data());
  double volumeSum = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    s.skel.push_back(first + static_cast<std::uint32_t>(i));
    s.skelCentre.push_back(level[i].center);
    s.isFixed.push_back(o.fixedRegion && o.fixedRegion->contains(level[i].center) ? 1 : 0);
    volumeSum += std::pow(level[i].radius, 3);
  }
  for (std::size_t i = 0; i < n; ++i)
    s.mass.push_back(volumeSum > 0 ? o.mass * std::pow(level[i].radius, 3) / volumeSum : o.mass / n);
  s.linkStart.push_back(0);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = 0; j < n; ++j)
      if (j != i &&
          (level[i].center - level[j].center).norm() <= kTouching * (level[i].radius + level[j].radius))
        s.linkTo.push_back(static_cast<std::uint32_t>(j));
    s.linkStart.push_back(static_cast<std::uint32_t>(s.linkTo.size()));
  }
  s.freeIndex.assign(n, -1);
  for (std::size_t i = 0; i < n; ++i)
    if (!s.isFixed[i]) {
      s.freeIndex[i] = static_cast<int>(s.freeSkel.size());
      s.freeSkel.push_back(static_cast<std::uint32_t>(i));
    }
  if (s.freeSkel.empty())
    return bad("every skeleton node lies in fixedRegion: nothing can move", "options.fixedRegion",
               "fix only the region the object is attached by");
  if (o.anchorStiffness == 0 && s.freeSkel.size() == n)
    return bad("anchorStiffness is 0 and no node is fixed: the object would float away",
               "options.anchorStiffness", "give an anchor stiffness or a fixedRegion");

  // A = M + hC + h²K over the free nodes.
  const double h = o.timeStep;
  const auto nf = static_cast<Eigen::Index>(s.freeSkel.size());
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(nf, nf);
  for (Eigen::Index r = 0; r < nf; ++r) {
    const std::uint32_t i = s.freeSkel[static_cast<std::size_t>(r)];
    const double degree = s.linkStart[i + 1] - s.linkStart[i];
    a(r, r) = s.mass[i] + h * o.damping + h * h * (o.anchorStiffness + o.linkStiffness * degree);
    for (std::uint32_t e = s.linkStart[i]; e < s.linkStart[i + 1]; ++e)
      if (const int c = s.freeIndex[s.linkTo[e]]; c >= 0) a(r, c) -= h * h * o.linkStiffness;
  }
  const Eigen::LLT<Eigen::MatrixXd> llt(a);
  if (llt.info() != Eigen::Success)
    return bad("the spring network's system is not positive definite", "options",
               "check the stiffness and mass values");
  s.ainv = llt.solve(Eigen::MatrixXd::Identity(nf, nf));
  if (!s.ainv.allFinite()) return bad("the spring network's system is singular", "options", "");

  const std::vector<SphereTreeNode>& rn = rest->nodes();
  s.wIdx.resize(rn.size());
  s.w.resize(rn.size());
  s.wGrad.resize(rn.size());
  for (std::size_t k = 0; k < rn.size(); ++k)
    interpolation(rn[k].center, s.skelCentre, s.wIdx[k], s.w[k], s.wGrad[k]);
  s.d.assign(n, Vec3::Zero());
  s.v.assign(n, Vec3::Zero());
  s.f.assign(n, Vec3::Zero());
  s.rhs.assign(s.freeSkel.size(), Vec3::Zero());
  s.prev.assign(s.freeSkel.size(), Vec3::Zero());
  // Reach sets and scales, leaves up (children come after their parents).
  std::vector<std::vector<std::uint32_t>> reach(rn.size());
  s.reachScale.assign(rn.size(), 1.0);
  for (std::size_t k = rn.size(); k-- > 0;) {
    std::vector<std::uint32_t>& r = reach[k];
    double l1 = 0.0;
    for (const double x : s.w[k]) l1 += std::abs(x);
    s.maxScale = std::max(s.maxScale, l1);
    for (std::uint32_t c = rn[k].firstChild; c < rn[k].firstChild + rn[k].childCount; ++c) {
      if (rn[c].childCount == 0) {
        double lc = 0.0;
        for (std::size_t j = 0; j < kWeights; ++j)
          if (s.w[c][j] != 0) r.push_back(s.wIdx[c][j]), lc += std::abs(s.w[c][j]);
        s.reachScale[k] = std::max(s.reachScale[k], lc);
      } else {
        r.insert(r.end(), reach[c].begin(), reach[c].end());
        s.reachScale[k] = std::max(s.reachScale[k], s.reachScale[c]);
      }
    }
    std::sort(r.begin(), r.end());
    r.erase(std::unique(r.begin(), r.end()), r.end());
  }
  s.reachStart.push_back(0);
  for (const auto& r : reach) {
    s.reach.insert(s.reach.end(), r.begin(), r.end());
    s.reachStart.push_back(static_cast<std::uint32_t>(s.reach.size()));
  }
  s.cacheEpoch.assign(rn.size(), 0);
  s.cache.resize(rn.size());
  s.rest = std::move(rest);
  return std::shared_ptr<SphereTreeDeformation>(new SphereTreeDeformation(std::move(st)));
}

void SphereTreeDeformation::addForce(std::uint32_t node, const Vec3& force) noexcept {
  State& s = *s_;
  if (node >= s.w.size() || !force.allFinite()) return;
  for (std::size_t k = 0; k < kWeights; ++k) {
    const std::uint32_t j = s.wIdx[node][k];
    if (!s.isFixed[j]) s.f[j] += s.w[node][k] * force;
  }
}

double SphereTreeDeformation::step(double dt) noexcept {
  State& s = *s_;
  if (!std::isfinite(dt) || dt <= 0) return 0.0;
  s.acc += dt;
  int steps = 0;
  double moved = 0.0;  // the skeleton's largest move bounds every node's (convex weights)
  while (s.acc >= s.opt.timeStep * (1 - 1e-9) && steps < kMaxSubsteps) {
    for (std::size_t r = 0; r < s.freeSkel.size(); ++r) s.prev[r] = s.d[s.freeSkel[r]];
    s.substep();
    for (std::size_t r = 0; r < s.freeSkel.size(); ++r)
      moved = std::max(moved, (s.d[s.freeSkel[r]] - s.prev[r]).norm());
    s.acc -= s.opt.timeStep;
    ++steps;
  }
  if (steps == kMaxSubsteps) s.acc = std::min(s.acc, s.opt.timeStep);
  for (Vec3& x : s.f) x = Vec3::Zero();
  if (steps > 0) {
    ++s.epoch;
    s.updateSupport();
  }
  return s.maxScale * moved;
}

void SphereTreeDeformation::reset() noexcept {
  State& s = *s_;
  for (std::size_t i = 0; i < s.d.size(); ++i) s.d[i] = s.v[i] = s.f[i] = Vec3::Zero();
  s.acc = 0.0;
  ++s.epoch;
  s.updateSupport();
}

const SphereTree& SphereTreeDeformation::rest() const noexcept { return *s_->rest; }
BoundingSphere SphereTreeDeformation::bound(std::uint32_t node) const noexcept {
  return node < s_->w.size() ? s_->bound(node) : BoundingSphere{};
}
Vec3 SphereTreeDeformation::displacement(std::uint32_t node) const noexcept {
  return node < s_->w.size() ? s_->disp(node) : Vec3::Zero();
}
Mat3 SphereTreeDeformation::deformationGradient(std::uint32_t node) const noexcept {
  Mat3 f = Mat3::Identity();
  if (node >= s_->w.size()) return f;
  for (std::size_t k = 0; k < kWeights; ++k) f += s_->d[s_->wIdx[node][k]] * s_->wGrad[node][k].transpose();
  return f;
}
std::span<const std::uint32_t> SphereTreeDeformation::skeleton() const noexcept { return s_->skel; }
bool SphereTreeDeformation::fixed(std::size_t i) const noexcept {
  return i < s_->isFixed.size() && s_->isFixed[i] != 0;
}
Vec3 SphereTreeDeformation::supportForce() const noexcept { return s_->support; }

SphereTreeDeformation::Binding SphereTreeDeformation::bind(std::span<const Vec3> restPoints) const {
  Binding b;
  b.index.resize(restPoints.size());
  b.weight.resize(restPoints.size());
  Gradients unused;
  for (std::size_t i = 0; i < restPoints.size(); ++i)
    interpolation(restPoints[i], s_->skelCentre, b.index[i], b.weight[i], unused);
  return b;
}

bool SphereTreeDeformation::deform(const Binding& b, std::span<const Vec3> restPoints,
                                   std::span<Vec3> out) const noexcept {
  if (b.index.size() != restPoints.size() || b.weight.size() != restPoints.size() ||
      out.size() != restPoints.size())
    return false;
  for (std::size_t i = 0; i < restPoints.size(); ++i) {
    Vec3 x = restPoints[i];
    for (std::size_t k = 0; k < kWeights; ++k) x += b.weight[i][k] * s_->d[b.index[i][k]];
    out[i] = x;
  }
  return true;
}

}  // namespace dm
