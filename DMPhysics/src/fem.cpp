// Co-rotational linear FEM on tetrahedra with implicit integration; see
// dm/physics/fem.hpp for the model, the references and the step equations.
#include <dm/collide/bvh.hpp>
#include <dm/collide/mesh_query.hpp>
#include <dm/core/assert.hpp>
#include <dm/core/pose.hpp>
#include <dm/core/tasks.hpp>
#include <dm/physics/fem.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "fem_shared.hpp"

namespace dm {

// Positions and velocities are handed to the solver as one vector of 3n doubles.
static_assert(sizeof(Vec3) == 3 * sizeof(double), "Vec3 must be three packed doubles");

namespace {

// y += B·x and y += Bᵀ·x on three-double rows of a stacked vector: the
// solver's inner loops. Plain arithmetic on pointers rather than Eigen
// block expressions (segment<3>() of a VecX times a Mat3): the same code at
// -O2, but at the sanitizer trees' -O1 each expression is a chain of calls
// and stack temporaries that ASan checks, which made the FEM tests run 40
// times slower than the plain build (7 times, measured, once replaced).
inline void addMul(const Mat3& B, const double* x, double* y) {
  const double* b = B.data();
  y[0] += b[0] * x[0] + b[3] * x[1] + b[6] * x[2];
  y[1] += b[1] * x[0] + b[4] * x[1] + b[7] * x[2];
  y[2] += b[2] * x[0] + b[5] * x[1] + b[8] * x[2];
}
inline void addMulT(const Mat3& B, const double* x, double* y) {
  const double* b = B.data();
  y[0] += b[0] * x[0] + b[1] * x[1] + b[2] * x[2];
  y[1] += b[3] * x[0] + b[4] * x[1] + b[5] * x[2];
  y[2] += b[6] * x[0] + b[7] * x[1] + b[8] * x[2];
}

}  // namespace

// ---------------------------------------------------------------------------
// FemBody: creation
// ---------------------------------------------------------------------------

Result<FemBody> FemBody::create(const TetMesh& mesh, const FemMaterial& material, const FemDamping& damping,
                                const FemSolverOptions& options) {
  constexpr const char* where = "FemBody::create";
  if (Status s = mesh.validate(); !s) return std::move(s).error().within(where);
  if (!(material.youngsModulus > 0.0) || !std::isfinite(material.youngsModulus))
    return femimpl::invalid("material.youngsModulus = " + femimpl::num(material.youngsModulus) + " Pa is not positive", where,
                   "soft tissue is ~1e3–1e5 Pa");
  if (!(material.poissonRatio > -1.0 && material.poissonRatio < 0.5))
    return femimpl::invalid("material.poissonRatio = " + femimpl::num(material.poissonRatio) + " is outside (−1, 0.5)", where,
                   "use 0.45–0.49 for nearly incompressible tissue (< 0.5)");
  if (!(material.density > 0.0) || !std::isfinite(material.density))
    return femimpl::invalid("material.density = " + femimpl::num(material.density) + " kg/m³ is not positive", where);
  if (!(damping.alpha >= 0.0) || !(damping.beta >= 0.0) || !std::isfinite(damping.alpha) ||
      !std::isfinite(damping.beta))
    return femimpl::invalid("damping (alpha = " + femimpl::num(damping.alpha) + ", beta = " + femimpl::num(damping.beta) +
                       ") must be finite and ≥ 0",
                   where);
  FemBody body;
  body.material_ = material;
  body.damping_ = damping;
  if (!(options.tolerance > 0.0) || options.maxIterations < 1 || options.polarIterations < 1)
    return femimpl::invalid("solver options: tolerance = " + femimpl::num(options.tolerance) +
                       ", maxIterations = " + std::to_string(options.maxIterations) +
                       ", polarIterations = " + std::to_string(options.polarIterations) + " must be positive",
                   where);
  body.options_ = options;

  auto resolved = femimpl::resolveHanging(mesh, where);
  if (!resolved) return std::move(resolved).error();
  const std::size_t n = mesh.nodes.size(), T = mesh.tets.size();
  body.hanging_.assign(n, 0);
  for (std::uint32_t h : resolved->node) body.hanging_[h] = 1;
  body.hangNode_ = std::move(resolved->node);
  body.hangStart_ = std::move(resolved->start);
  body.hangMaster_ = std::move(resolved->master);
  body.hangWeight_ = std::move(resolved->weight);
  body.x0_ = mesh.nodes;
  body.tets_ = mesh.tets;
  body.x_ = mesh.nodes;
  body.v_.assign(n, Vec3::Zero());
  body.fext_.assign(n, Vec3::Zero());
  body.force_.assign(n, Vec3::Zero());
  body.fixed_.assign(n, 0);
  body.mass_.assign(n, 0.0);
  body.rot_.assign(T, Quat::Identity());
  body.restInverse_.resize(T);
  body.restVolume_.resize(T);

  // Rest shape (D_m⁻¹, whose rows are the shape-function gradients g₁..g₃)
  // and lumped mass. The element stiffness is never stored: K_ij =
  // V(μ(g_i·g_j)I + μ g_j g_iᵀ + λ g_i g_jᵀ) is rebuilt from the gradients.
  const double E = material.youngsModulus, nu = material.poissonRatio;
  body.mu_ = E / (2.0 * (1.0 + nu));
  body.lambda_ = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
  for (std::size_t e = 0; e < T; ++e) {
    const Tet& t = mesh.tets[e];
    Mat3 Dm;
    Dm << mesh.nodes[t[1]] - mesh.nodes[t[0]], mesh.nodes[t[2]] - mesh.nodes[t[0]],
        mesh.nodes[t[3]] - mesh.nodes[t[0]];
    const double V = Dm.determinant() / 6.0 * (mesh.fractions.empty() ? 1.0 : mesh.fractions[e]);
    body.restInverse_[e] = Dm.inverse();
    body.restVolume_[e] = V;
    for (int i = 0; i < 4; ++i) body.mass_[t[i]] += material.density * V / 4.0;
  }
  body.totalMass_ = 0.0;
  for (double m : body.mass_) body.totalMass_ += m;
  for (std::size_t i = 0; i < n; ++i)
    if (!(body.mass_[i] > 0.0))
      return femimpl::invalid("node " + std::to_string(i) + " belongs to no tetrahedron (zero mass)", where,
                     "remove unreferenced nodes from the mesh");

  // Node-by-node block pattern: the upper triangle (column ≥ row, rows
  // sorted, so a row's first block is its diagonal), each element's 10
  // slots (transposed ones as ~slot), and per row the blocks below the
  // diagonal as the transposes of stored ones.
  std::vector<std::uint64_t> pairs;
  pairs.reserve(T * 10);
  for (const Tet& t : mesh.tets)
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j)
        if (t[i] <= t[j]) pairs.push_back((std::uint64_t(t[i]) << 32) | t[j]);
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  if (pairs.size() > std::size_t(std::numeric_limits<int>::max() / 2))
    return femimpl::invalid("the mesh is too large for the solver's index type", where);
  body.rowStart_.assign(n + 1, 0);
  body.colIndex_.resize(pairs.size());
  for (std::size_t p = 0; p < pairs.size(); ++p) {
    ++body.rowStart_[(pairs[p] >> 32) + 1];
    body.colIndex_[p] = int(pairs[p] & 0xffffffffu);
  }
  for (std::size_t i = 0; i < n; ++i) body.rowStart_[i + 1] += body.rowStart_[i];
  body.buildLowerBlocks();
  body.slot_.resize(T);
  for (std::size_t e = 0; e < T; ++e) body.setElementSlots(e);
  body.blocks_.assign(pairs.size(), Mat3::Zero());
  body.colourAll();

  body.surface_ = tetMeshSurface(mesh);
  body.contactOf_.assign(n, -1);
  for (const Triangle& t : body.surface_)
    body.surfaceNodes_.insert(body.surfaceNodes_.end(), t.begin(), t.end());
  std::sort(body.surfaceNodes_.begin(), body.surfaceNodes_.end());
  body.surfaceNodes_.erase(std::unique(body.surfaceNodes_.begin(), body.surfaceNodes_.end()),
                           body.surfaceNodes_.end());
  const Eigen::Index dofs = Eigen::Index(3 * n);
  body.rhs_.setZero(dofs);
  body.dv_.setZero(dofs);
  body.tmp_.setZero(dofs);
  if (!body.hangNode_.empty()) body.full_.setZero(dofs);
  body.invBlockDiag_.assign(n, Mat3::Identity());
  body.sweepSkip_.assign(n, 0);
  body.pcg_.reserve(dofs);
  return body;
}

// Per row, the blocks left of the diagonal as the stored blocks (col, row)
// to transpose, from the upper-triangular pattern.
void FemBody::buildLowerBlocks() {
  const std::size_t n = rowStart_.size() - 1;
  lowerStart_.assign(n + 1, 0);
  for (std::size_t row = 0; row < n; ++row)
    for (int s = rowStart_[row] + 1; s < rowStart_[row + 1]; ++s)
      ++lowerStart_[std::size_t(colIndex_[std::size_t(s)]) + 1];
  for (std::size_t i = 0; i < n; ++i) lowerStart_[i + 1] += lowerStart_[i];
  lower_.resize(std::size_t(lowerStart_[n]));
  std::vector<int> fill(lowerStart_.begin(), lowerStart_.end() - 1);
  for (std::size_t row = 0; row < n; ++row)
    for (int s = rowStart_[row] + 1; s < rowStart_[row + 1]; ++s)
      lower_[std::size_t(fill[std::size_t(colIndex_[std::size_t(s)])]++)] = {s, int(row)};
}

// The stored block of node pair (a, b): its slot, or ~slot where the pair
// is stored transposed (a > b). The pair must be in the pattern.
int FemBody::slotOf(std::uint32_t a, std::uint32_t b) const {
  const int slot = findBlock(std::min(a, b), std::max(a, b));
  return a > b ? ~slot : slot;
}

// The slot of block (row, col), row ≤ col, or -1 where the pattern lacks it.
int FemBody::findBlock(std::uint32_t row, std::uint32_t col) const {
  const int* begin = colIndex_.data() + rowStart_[row];
  const int* end = colIndex_.data() + rowStart_[row + 1];
  const int* it = std::lower_bound(begin, end, int(col));
  return it != end && *it == int(col) ? int(it - colIndex_.data()) : -1;
}

void FemBody::setElementSlots(std::size_t e) {
  for (int i = 0, k = 0; i < 4; ++i)
    for (int j = i; j < 4; ++j) slot_[e][std::size_t(k++)] = slotOf(tets_[e][i], tets_[e][j]);
}

// Greedy colouring: elements sharing a node get different colours, so one
// colour's elements can scatter into nodes and blocks concurrently.
void FemBody::colourAll() {
  const std::size_t n = x_.size(), T = tets_.size();
  std::vector<int> nodeTetStart(n + 1, 0), nodeTets(T * 4);
  for (const Tet& t : tets_)
    for (std::uint32_t v : t) ++nodeTetStart[v + 1];
  for (std::size_t i = 0; i < n; ++i) nodeTetStart[i + 1] += nodeTetStart[i];
  {
    std::vector<int> fill(nodeTetStart.begin(), nodeTetStart.end() - 1);
    for (std::size_t e = 0; e < T; ++e)
      for (std::uint32_t v : tets_[e]) nodeTets[std::size_t(fill[v]++)] = int(e);
  }
  colour_.assign(T, -1);
  std::vector<std::size_t> lastSeen;  // lastSeen[c] == e + 1: colour c is taken for element e
  int colours = 0;
  for (std::size_t e = 0; e < T; ++e) {
    for (std::uint32_t v : tets_[e])
      for (int k = nodeTetStart[v]; k < nodeTetStart[v + 1]; ++k)
        if (const int c = colour_[std::size_t(nodeTets[std::size_t(k)])]; c >= 0)
          lastSeen[std::size_t(c)] = e + 1;
    int c = 0;
    while (c < colours && lastSeen[std::size_t(c)] == e + 1) ++c;
    if (c == colours) ++colours, lastSeen.push_back(0);
    colour_[e] = c;
  }
  nodeColours_.clear();  // rebuilt by applyCut when it needs them
  groupColours(colours);
}

// colourStart_/colourOrder_ from colour_ (a counting sort: elements of a
// colour in ascending order).
void FemBody::groupColours(int colours) {
  colourStart_.assign(std::size_t(colours) + 1, 0);
  for (int c : colour_) ++colourStart_[std::size_t(c) + 1];
  for (int c = 0; c < colours; ++c) colourStart_[std::size_t(c) + 1] += colourStart_[std::size_t(c)];
  colourOrder_.resize(colour_.size());
  std::vector<std::size_t> fill(colourStart_.begin(), colourStart_.end() - 1);
  for (std::size_t e = 0; e < colour_.size(); ++e)
    colourOrder_[fill[std::size_t(colour_[e])]++] = std::uint32_t(e);
}

// ---------------------------------------------------------------------------
// FemBody: state access
// ---------------------------------------------------------------------------

void FemBody::setPositions(std::span<const Vec3> x) {
  DM_DEMAND(x.size() == x_.size(), "FemBody::setPositions: one position per node");
  std::copy(x.begin(), x.end(), x_.begin());
  syncHanging();
}

void FemBody::setVelocities(std::span<const Vec3> v) {
  DM_DEMAND(v.size() == v_.size(), "FemBody::setVelocities: one velocity per node");
  std::copy(v.begin(), v.end(), v_.begin());
  syncHanging();
}

void FemBody::syncHanging() {
  for (std::size_t k = 0; k < hangNode_.size(); ++k) {
    Vec3 x = Vec3::Zero(), v = Vec3::Zero();
    for (std::uint32_t s = hangStart_[k]; s < hangStart_[k + 1]; ++s)
      x += hangWeight_[s] * x_[hangMaster_[s]], v += hangWeight_[s] * v_[hangMaster_[s]];
    x_[hangNode_[k]] = x;
    v_[hangNode_[k]] = v;
  }
}

void FemBody::setVelocity(std::size_t i, const Vec3& v) {
  DM_DEMAND(i < v_.size(), "FemBody::setVelocity: node index out of range");
  DM_DEMAND(!hanging_[i], "FemBody::setVelocity: the node hangs (it follows its masters)");
  DM_DEMAND(v.allFinite(), "FemBody::setVelocity: velocity must be finite");
  v_[i] = v;
}

void FemBody::setFixed(std::size_t i, bool fixed) {
  DM_DEMAND(i < fixed_.size(), "FemBody::setFixed: node index out of range");
  DM_DEMAND(!hanging_[i], "FemBody::setFixed: the node hangs (it follows its masters: fix those)");
  fixed_[i] = fixed ? 1 : 0;
  if (fixed) v_[i].setZero();
}

void FemBody::setExternalForce(std::size_t i, const Vec3& f) {
  DM_DEMAND(i < fext_.size(), "FemBody::setExternalForce: node index out of range");
  fext_[i] = f;
}

void FemBody::clearExternalForces() { std::fill(fext_.begin(), fext_.end(), Vec3::Zero()); }

namespace {

// Checks one spring's nodes, weights and anchor (the contact spring's and
// the point springs'); `name` says which spring, for the message.
Status checkSpring(const FemPointSpring& s, std::size_t nodeCount, const std::string& name,
                   const char* where) {
  double sum = 0.0;
  for (std::size_t i = 0; i < 4; ++i) {
    const double w = s.weights[i];
    if (!std::isfinite(w) || w < 0.0)
      return femimpl::invalid(
          name + " weight " + std::to_string(i) + " = " + femimpl::num(w) + " is negative or not finite",
          where, "give barycentric weights >= 0");
    if (w > 0.0 && s.nodes[i] >= nodeCount)
      return femimpl::invalid(
          formatString("%s node %u is out of range (%zu nodes)", name.c_str(), s.nodes[i], nodeCount), where,
          "use indices of positions()");
    sum += w;
  }
  if (std::abs(sum - 1.0) > 1e-6)
    return femimpl::invalid(name + " weights sum to " + femimpl::num(sum) + ", not 1", where,
                            "give barycentric weights that sum to 1");
  if (!s.anchor.allFinite())
    return femimpl::invalid(name + " anchor is not finite", where, "give a point in metres");
  return ok();
}

}  // namespace

Status FemBody::setContactSpring(const std::array<std::uint32_t, 3>& nodes, const Vec3& weights,
                                 const Vec3& anchor, double stiffness) {
  constexpr const char* where = "FemBody::setContactSpring";
  const FemPointSpring spring{.nodes = {nodes[0], nodes[1], nodes[2], nodes[0]},
                              .weights = {weights.x(), weights.y(), weights.z(), 0.0},
                              .anchor = anchor,
                              .stiffness = stiffness * Mat3::Identity()};
  for (int i = 0; i < 3; ++i)  // every node must exist, weighted or not
    if (nodes[std::size_t(i)] >= x_.size())
      return femimpl::invalid(
          formatString("node %u is out of range (%zu nodes)", nodes[std::size_t(i)], x_.size()), where,
          "use indices of positions()");
  if (Status st = checkSpring(spring, x_.size(), "the contact spring's", where); !st) return st;
  if (!std::isfinite(stiffness) || stiffness < 0.0)
    return femimpl::invalid("stiffness " + femimpl::num(stiffness) + " N/m is negative or not finite", where,
                            "give k >= 0");
  spring_ = {.active = true, .spring = spring};
  return ok();
}

Status FemBody::setPointSprings(std::span<const FemPointSpring> springs) {
  constexpr const char* where = "FemBody::setPointSprings";
  for (std::size_t j = 0; j < springs.size(); ++j) {
    const FemPointSpring& s = springs[j];
    const std::string name = "springs[" + std::to_string(j) + "]";
    if (Status st = checkSpring(s, x_.size(), name, where); !st) return st;
    const Mat3& k = s.stiffness;
    const double scale = k.cwiseAbs().maxCoeff();
    if (!s.load.allFinite())
      return femimpl::invalid(name + " load is not finite", where, "give a force in newtons");
    if (!k.allFinite())
      return femimpl::invalid(name + " stiffness is not finite", where, "give a symmetric 3x3 matrix in N/m");
    if ((k - k.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale)
      return femimpl::invalid(name + " stiffness is not symmetric", where,
                              "use FemPointSpring::axial or a symmetric matrix");
    // Positive semi-definite: the leading minors of K + εI (ε a round-off
    // allowance) are positive.
    const Mat3 kk = k + 1e-12 * scale * Mat3::Identity();
    const double m1 = kk(0, 0), m2 = kk(0, 0) * kk(1, 1) - kk(0, 1) * kk(1, 0), m3 = kk.determinant();
    if (scale > 0.0 && !(m1 > 0.0 && m2 > 0.0 && m3 > 0.0))
      return femimpl::invalid(name + " stiffness is not positive semi-definite", where,
                              "a spring cannot push away from its anchor: give stiffnesses >= 0");
  }
  points_.assign(springs.begin(), springs.end());
  return ok();
}

Status FemBody::setObstacles(std::span<const FemObstacle> obstacles) {
  for (std::size_t j = 0; j < obstacles.size(); ++j) {
    const FemObstacle& o = obstacles[j];
    const std::string where = formatString("FemBody::setObstacles: obstacles[%zu]", j);
    if (o.tree == nullptr || !o.tree->isClosed())
      return femimpl::invalid(o.tree == nullptr ? "the tree is null" : "the tree's mesh is not closed", where,
                     "give the tree of a closed, consistently oriented mesh (signed distances)");
    if (!isRigidPose(o.pose))
      return femimpl::invalid("the pose is not rigid and finite", where, "give a rotation and a translation");
    if (!std::isfinite(o.stiffness) || !(o.stiffness > 0))
      return femimpl::invalid("stiffness " + femimpl::num(o.stiffness) + " N/m is not positive", where, "e.g. 1e4 N/m");
    if (!std::isfinite(o.friction) || o.friction < 0)
      return femimpl::invalid("friction " + femimpl::num(o.friction) + " N·s/m is negative or not finite",
                              where, "0 = frictionless");
    if (!std::isfinite(o.mass) || o.mass < 0)
      return femimpl::invalid("mass " + femimpl::num(o.mass) + " kg is negative or not finite", where, "0 = kinematic, > 0 = dynamic");
    if (!o.centerOfMass.allFinite()) return femimpl::invalid("centerOfMass is not finite", where);
    if (o.mass > 0 && (!o.inertia.allFinite() || !o.inertia.isApprox(o.inertia.transpose(), 1e-9) ||
                       o.inertia.llt().info() != Eigen::Success))
      return femimpl::invalid("inertia is not symmetric positive definite", where,
                     "give the tensor about the centre of mass, kg·m² (e.g. from dm::computeMassProperties)");
  }
  for (const NodeContact& c : contacts_) contactOf_[c.node] = -1;
  contacts_.clear();
  contacts_.reserve(surfaceNodes_.size());
  obstacles_.assign(obstacles.begin(), obstacles.end());
  const std::size_t m = obstacles_.size();
  obstacleInverse_.resize(m);
  for (std::size_t j = 0; j < m; ++j) obstacleInverse_[j] = obstacles_[j].pose.inverse();
  obstacleWrench_.assign(m, Wrench{});
  obstacleVelocity_.assign(m, Twist{});
  obstacleCenter_.assign(m, Vec3::Zero());
  obstacleInertia_.assign(m, Mat3::Zero());
  obstacleRow_.assign(m, -1);
  rigidRows_ = 0;
  for (std::size_t j = 0; j < m; ++j)
    if (obstacles_[j].mass > 0) obstacleRow_[j] = std::int32_t(3 * x_.size() + rigidRows_), rigidRows_ += 6;
  obstaclePre_.assign(rigidRows_ / 6, Eigen::Matrix<double, 6, 6>::Identity());
  const Eigen::Index rows = Eigen::Index(3 * x_.size() + rigidRows_);
  if (rhs_.size() != rows) {
    rhs_.setZero(rows);
    dv_.setZero(rows);
    if (!hangNode_.empty()) full_.setZero(rows);
    pcg_.reserve(rows);
  }
  return ok();
}

bool FemBody::setObstaclePose(std::size_t i, const Isometry3& pose) noexcept {
  if (i >= obstacles_.size() || !isRigidPose(pose)) return false;
  obstacles_[i].pose = pose;
  obstacleInverse_[i] = pose.inverse();
  return true;
}

bool FemBody::setObstacleVelocity(std::size_t i, const Twist& velocity) noexcept {
  if (i >= obstacles_.size() || !velocity.linear.allFinite() || !velocity.angular.allFinite()) return false;
  obstacleVelocity_[i] = velocity;
  return true;
}

Twist FemBody::obstacleVelocity(std::size_t i) const noexcept {
  return i < obstacleVelocity_.size() ? obstacleVelocity_[i] : Twist{};
}

Vec3 FemBody::obstacleForce(std::size_t i) const noexcept {
  return i < obstacleWrench_.size() ? obstacleWrench_[i].force : Vec3::Zero();
}

Wrench FemBody::obstacleWrench(std::size_t i) const noexcept {
  return i < obstacleWrench_.size() ? obstacleWrench_[i] : Wrench{};
}

// The boundary nodes inside an obstacle, each with its deepest obstacle.
// contacts_ holds at most one entry per boundary node (its reserved size).
void FemBody::findObstacleContacts() {
  for (const NodeContact& c : contacts_) contactOf_[c.node] = -1;
  contacts_.clear();
  if (obstacles_.empty()) return;
  for (const std::uint32_t i : surfaceNodes_) {
    if (fixed_[i]) continue;
    NodeContact best;
    for (std::size_t j = 0; j < obstacles_.size(); ++j) {
      const FemObstacle& o = obstacles_[j];
      if (!o.tree->bounds().contains(obstacleInverse_[j] * x_[i])) continue;
      const MeshPointQuery q = closestPointOnMesh(*o.tree, o.pose, x_[i]);
      if (!(q.distance < 0.0) || !(-q.distance > best.depth) || !q.normal.allFinite()) continue;
      best = {.node = i,
              .obstacle = std::uint32_t(j),
              .normal = q.normal,
              .depth = -q.distance,
              .stiffness = o.stiffness,
              .friction = o.friction,
              .arm = x_[i] - obstacleCenter_[j]};
    }
    if (best.depth > 0.0) {
      contactOf_[i] = std::int32_t(contacts_.size());
      contacts_.push_back(best);
    }
  }
}

// k·(n·(v_node − u)): how fast contact c closes, times its stiffness, with
// u the obstacle's velocity at the contact (V + Ω × arm).
double FemBody::contactRate(const NodeContact& c) const noexcept {
  const Twist& u = obstacleVelocity_[c.obstacle];
  return c.stiffness * c.normal.dot(v_[c.node] - u.linear - u.angular.cross(c.arm));
}

// The penalty force on contact c's node over a step of h at the current
// velocities: k·depth·n less the damping-like term h·k·(n·(v − u))·n.
Vec3 FemBody::contactForce(const NodeContact& c, double h) const noexcept {
  return (c.stiffness * c.depth - h * contactRate(c)) * c.normal;
}

// The tangential damper on contact c's node at the current velocities:
// −c_t·(I − n nᵀ)(v_node − u).
Vec3 FemBody::contactFriction(const NodeContact& c) const noexcept {
  if (c.friction == 0.0) return Vec3::Zero();
  const Twist& u = obstacleVelocity_[c.obstacle];
  const Vec3 slip = v_[c.node] - u.linear - u.angular.cross(c.arm);
  return -c.friction * (slip - c.normal.dot(slip) * c.normal);
}

Vec3 FemBody::springPoint(const FemPointSpring& s) const noexcept {
  Vec3 point = Vec3::Zero();
  for (std::size_t i = 0; i < 4; ++i)
    if (s.weights[i] != 0.0) point += s.weights[i] * x_[s.nodes[i]];
  return point;
}

Vec3 FemBody::contactSpringForce() const noexcept {
  if (!spring_.active) return Vec3::Zero();
  return spring_.spring.stiffness * (spring_.spring.anchor - springPoint(spring_.spring));
}

Vec3 FemBody::pointSpringForce(std::size_t i) const noexcept {
  if (i >= points_.size()) return Vec3::Zero();
  return points_[i].stiffness * (points_[i].anchor - springPoint(points_[i])) + points_[i].load;
}

void FemBody::setSolverOptions(const FemSolverOptions& options) {
  DM_DEMAND(options.tolerance > 0.0 && options.maxIterations >= 1 && options.polarIterations >= 1,
            "FemBody::setSolverOptions: tolerance and iteration counts must be positive");
  options_ = options;
}

double FemBody::kineticEnergy() const {
  double k = 0.0;
  for (std::size_t i = 0; i < v_.size(); ++i) k += 0.5 * mass_[i] * v_[i].squaredNorm();
  return k;
}

Vec3 FemBody::linearMomentum() const {
  Vec3 p = Vec3::Zero();
  for (std::size_t i = 0; i < v_.size(); ++i) p += mass_[i] * v_[i];
  return p;
}

Vec3 FemBody::centerOfMass() const {
  Vec3 c = Vec3::Zero();
  for (std::size_t i = 0; i < x_.size(); ++i) c += mass_[i] * x_[i];
  return c / totalMass_;
}

void FemBody::surfaceMesh(Mesh& out) const {
  out.positions.assign(x_.begin(), x_.end());
  out.triangles.assign(surface_.begin(), surface_.end());
  out.normals.clear();
  out.uvs.clear();
  out.colors.clear();
}

// ---------------------------------------------------------------------------
// FemBody: elements
// ---------------------------------------------------------------------------

template <class F>
void FemBody::forRange(std::size_t n, std::size_t grain, F&& fn) const {
  if (options_.parallel && n > grain)
    parallelFor(0, n, grain, fn);
  else
    fn(std::size_t{0}, n);
}

// Rotational part R of F = D_s D_m⁻¹, i.e. the rotation maximising tr(Rᵀ F).
// Newton iteration on skew(Rᵀ F) = 0 in the body frame (quadratic
// convergence from a warm start); far from the solution, or for inverted or
// flat elements where tr(S)I − S is not positive definite, the damped step of
// Müller et al. 2016, ω = Σ rᵢ × fᵢ / |Σ rᵢ · fᵢ|, which always makes
// progress and keeps R a proper rotation.
Mat3 FemBody::elementRotation(std::size_t e, const std::vector<Vec3>& x, Quat& q) const {
  const Tet& t = tets_[e];
  Mat3 Ds;
  Ds << x[t[1]] - x[t[0]], x[t[2]] - x[t[0]], x[t[3]] - x[t[0]];
  const Mat3 F = Ds * restInverse_[e];
  Mat3 R = q.toRotationMatrix();
  for (int it = 0; it < options_.polarIterations; ++it) {
    const Mat3 S = R.transpose() * F;
    const Vec3 g(S(2, 1) - S(1, 2), S(0, 2) - S(2, 0), S(1, 0) - S(0, 1));
    const double tr = S.trace();
    const Mat3 H = tr * Mat3::Identity() - 0.5 * (S + S.transpose());
    Vec3 delta = Vec3::Zero();
    bool newton = false;
    if (H(0, 0) > 0.0 && H(0, 0) * H(1, 1) - H(0, 1) * H(1, 0) > 0.0 &&
        H.determinant() > 1e-12 * tr * tr * tr) {
      delta = H.inverse() * g;
      newton = delta.norm() < 0.5;
    }
    if (!newton) delta = g / (std::abs(tr) + 1e-12);
    const double angle = delta.norm();
    if (!(angle > 1e-15)) break;
    // Small steps as the first-order quaternion (1, δ/2), normalised: a
    // rotation about δ by 2·atan(|δ|/2) = |δ| − |δ|³/12 + …, no sincos.
    if (angle < 0.1)
      q = (q * Quat(1.0, 0.5 * delta.x(), 0.5 * delta.y(), 0.5 * delta.z())).normalized();
    else
      q = (q * Quat(AngleAxis(angle, delta / angle))).normalized();
    R = q.toRotationMatrix();
    // A Newton step of δ leaves an error of order |δ|²: below 1e-8 here.
    if (angle < (newton ? 1e-4 : 1e-9)) break;
  }
  return R;
}

// Linear (small) strain of the unrotated deformation and the element's node
// forces. With u_j = Rᵀx_j − x0_j and Σ_j x0_j g_jᵀ = I, the displacement
// gradient is Σ_j u_j g_jᵀ = RᵀF − I, so ε = sym(RᵀF) − I,
// σ = 2με + λ tr(ε) I and f_i = −V R σ g_i (= −R Σ_j K_ij u_j).
// Returns the strain energy V(μ ε:ε + ½λ tr(ε)²).
double FemBody::elementForces(std::size_t e, const Mat3& R, const std::vector<Vec3>& x, Vec3 (&f)[4],
                              Vec3 (&g)[4]) const {
  const Tet& t = tets_[e];
  const Mat3& Bm = restInverse_[e];
  Mat3 Ds;
  Ds << x[t[1]] - x[t[0]], x[t[2]] - x[t[0]], x[t[3]] - x[t[0]];
  const Mat3 RtF = R.transpose() * (Ds * Bm);
  const Mat3 eps = 0.5 * (RtF + RtF.transpose()) - Mat3::Identity();
  const double tr = eps.trace();
  const Mat3 sigma = 2.0 * mu_ * eps + lambda_ * tr * Mat3::Identity();
  const double V = restVolume_[e];
  const Mat3 RsV = V * R * sigma;
  for (int i = 1; i < 4; ++i) g[i] = Bm.row(i - 1).transpose();
  g[0] = -(g[1] + g[2] + g[3]);
  f[0] = Vec3::Zero();
  for (int i = 1; i < 4; ++i) {
    f[i] = -RsV * g[i];
    f[0] -= f[i];
  }
  return V * (mu_ * eps.squaredNorm() + 0.5 * lambda_ * tr * tr);
}

Mat3 FemBody::elementStress(std::size_t e) const {
  DM_DEMAND(e < tets_.size(), "FemBody::elementStress: element out of range");
  const Tet& t = tets_[e];
  Mat3 Ds;
  Ds << x_[t[1]] - x_[t[0]], x_[t[2]] - x_[t[0]], x_[t[3]] - x_[t[0]];
  const Mat3 R = options_.corotational ? rot_[e].toRotationMatrix() : Mat3::Identity();
  const Mat3 RtF = R.transpose() * (Ds * restInverse_[e]);
  const Mat3 eps = 0.5 * (RtF + RtF.transpose()) - Mat3::Identity();
  const Mat3 sigma = 2.0 * mu_ * eps + lambda_ * eps.trace() * Mat3::Identity();
  return R * sigma * R.transpose();
}

// Rotations, elastic forces (force_) and rotated stiffness blocks (blocks_):
// with r_i = R g_i, R K_ij Rᵀ = V(μ(r_i·r_j)I + μ r_j r_iᵀ + λ r_i r_jᵀ).
void FemBody::assemble() {
  std::fill(force_.begin(), force_.end(), Vec3::Zero());
  forRange(blocks_.size(), 4096, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) blocks_[i].setZero();
  });
  const bool corot = options_.corotational;
  const double mu = mu_, lambda = lambda_;
  for (std::size_t c = 0; c + 1 < colourStart_.size(); ++c) {
    const std::size_t first = colourStart_[c];
    forRange(colourStart_[c + 1] - first, 128, [&](std::size_t b, std::size_t end) {
      for (std::size_t k = b; k < end; ++k) {
        const std::size_t e = colourOrder_[first + k];
        const Tet& t = tets_[e];
        const Mat3 R = corot ? elementRotation(e, x_, rot_[e]) : Mat3::Identity();
        Vec3 f[4], g[4];
        elementForces(e, R, x_, f, g);
        const double V = restVolume_[e];
        Vec3 r[4];
        for (int i = 0; i < 4; ++i) {
          force_[t[i]] += f[i];
          r[i] = R * g[i];
        }
        const auto& slot = slot_[e];
        for (int i = 0, pair = 0; i < 4; ++i)
          for (int j = i; j < 4; ++j, ++pair) {
            // K_ij = V·μ·r_j r_iᵀ + V·λ·r_i r_jᵀ + V·μ·(r_i·r_j)·I, added to
            // its stored block (transposed when the block is K_ji).
            const int s = slot[std::size_t(pair)];
            const bool transposed = s < 0;
            double* B = blocks_[std::size_t(transposed ? ~s : s)].data();
            const double vm = V * mu, vl = V * lambda, diag = vm * r[i].dot(r[j]);
            const double *ri = r[i].data(), *rj = r[j].data();
            for (int col = 0; col < 3; ++col)
              for (int row = 0; row < 3; ++row) {
                const int u = transposed ? col : row, w = transposed ? row : col;
                B[3 * col + row] += vm * rj[u] * ri[w] + vl * ri[u] * rj[w] + (u == w ? diag : 0.0);
              }
          }
      }
    });
  }
}

// out = massScale·M·in + stiffScale·K·in on free nodes; fixed nodes are the
// identity (rows and columns), which keeps the operator symmetric.
// With hanging nodes the operator is Pᵀ A P: `in` is expanded (hanging
// rows from their free masters), multiplied, and the hanging rows of the
// product are folded into their masters; hanging rows are then the
// identity, like fixed ones (their right-hand side is zero).
void FemBody::applySystem(const VecX& input, VecX& out, double massScale, double stiffScale) {
  const bool hangs = !hangNode_.empty();
  if (hangs) {
    full_ = input;
    for (std::size_t k = 0; k < hangNode_.size(); ++k) {
      Vec3 value = Vec3::Zero();
      for (std::uint32_t s = hangStart_[k]; s < hangStart_[k + 1]; ++s)
        if (!fixed_[hangMaster_[s]]) value += hangWeight_[s] * input.segment<3>(Eigen::Index(3 * hangMaster_[s]));
      full_.segment<3>(Eigen::Index(3 * hangNode_[k])) = value;
    }
  }
  const VecX& in = hangs ? full_ : input;
  const auto node = [](const VecX& v, std::size_t i) { return v.segment<3>(Eigen::Index(3 * i)); };
  const auto finish = [&](std::size_t r, const Vec3& kx) {
    out.segment<3>(Eigen::Index(3 * r)) = stiffScale * kx + massScale * mass_[r] * node(in, r);
  };
  if (options_.parallel) {
    // Row by row (rows in parallel), lower blocks read transposed.
    forRange(x_.size(), 256, [&](std::size_t b, std::size_t e) {
      for (std::size_t r = b; r < e; ++r) {
        if (fixed_[r])
          out.segment<3>(Eigen::Index(3 * r)) = node(in, r);
        else
          finish(r, stiffnessRow(r, in.data(), true));
      }
    });
  } else {
    // One pass over the stored blocks: block (r, c) adds B·in_c to row r
    // and Bᵀ·in_r to row c > r, which is complete when the pass reaches it.
    out.head(Eigen::Index(3 * x_.size())).setZero();
    const double* ind = in.data();
    double* od = out.data();
    for (std::size_t r = 0; r < x_.size(); ++r) {
      if (fixed_[r]) {
        out.segment<3>(Eigen::Index(3 * r)) = node(in, r);
        continue;
      }
      const double* inR = ind + 3 * r;
      double acc[3] = {od[3 * r], od[3 * r + 1], od[3 * r + 2]};
      addMul(blocks_[std::size_t(rowStart_[r])], inR, acc);
      for (int s = rowStart_[r] + 1; s < rowStart_[r + 1]; ++s) {
        const std::size_t col = std::size_t(colIndex_[std::size_t(s)]);
        if (fixed_[col]) continue;
        const Mat3& B = blocks_[std::size_t(s)];
        addMul(B, ind + 3 * col, acc);
        addMulT(B, inR, od + 3 * col);
      }
      finish(r, Vec3(acc[0], acc[1], acc[2]));
    }
  }
  // Dynamic obstacles' rows: their mass and world inertia.
  for (std::size_t j = 0; j < obstacles_.size(); ++j)
    if (const Eigen::Index r = obstacleRow_[j]; r >= 0) {
      out.segment<3>(r) = obstacles_[j].mass * in.segment<3>(r);
      out.segment<3>(r + 3) = obstacleInertia_[j] * in.segment<3>(r + 3);
    }
  // Obstacle contacts: h²·k·g·n with g = n·(Δv_node − Δu), Δu the dynamic
  // obstacle's velocity change at the contact (ΔV + ΔΩ × arm); the obstacle
  // takes −h²·k·g·(n, arm × n).
  // Friction adds h·c_t·(I − n nᵀ)(Δv_node − Δu) the same way.
  for (const NodeContact& c : contacts_) {
    const Eigen::Index o = Eigen::Index(3 * c.node);
    const Eigen::Index r = obstacleRow_[c.obstacle];
    Vec3 rel = in.segment<3>(o);
    if (r >= 0) rel -= in.segment<3>(r) + Vec3(in.segment<3>(r + 3)).cross(c.arm);
    const double g = c.normal.dot(rel);
    Vec3 f = (sysContactScale_ * c.stiffness * g) * c.normal;
    if (c.friction > 0.0) f += (sysDampScale_ * c.friction) * (rel - g * c.normal);
    out.segment<3>(o) += f;
    if (r >= 0) {
      out.segment<3>(r) -= f;
      out.segment<3>(r + 3) -= c.arm.cross(f);
    }
  }
  // The springs: h²·w wᵀ ⊗ K over their nodes' free rows and columns.
  forEachSpring([&](const FemPointSpring& s) {
    double point[3] = {0.0, 0.0, 0.0};
    for (std::size_t j = 0; j < 4; ++j)
      if (s.weights[j] != 0.0 && !fixed_[s.nodes[j]])
        for (int a = 0; a < 3; ++a) point[a] += s.weights[j] * in[Eigen::Index(3 * s.nodes[j] + a)];
    double kp[3] = {0.0, 0.0, 0.0};
    addMul(s.stiffness, point, kp);
    for (std::size_t i = 0; i < 4; ++i)
      if (s.weights[i] != 0.0 && !fixed_[s.nodes[i]])
        for (int a = 0; a < 3; ++a)
          out[Eigen::Index(3 * s.nodes[i] + a)] += sysContactScale_ * s.weights[i] * kp[a];
  });
  if (hangs) foldHanging(out, &input);
}

void FemBody::foldHanging(VecX& v, const VecX* identityFrom) const {
  for (std::size_t k = 0; k < hangNode_.size(); ++k) {
    const Eigen::Index h = Eigen::Index(3 * hangNode_[k]);
    const Vec3 value = v.segment<3>(h);
    for (std::uint32_t s = hangStart_[k]; s < hangStart_[k + 1]; ++s)
      if (!fixed_[hangMaster_[s]]) v.segment<3>(Eigen::Index(3 * hangMaster_[s])) += hangWeight_[s] * value;
    if (identityFrom)
      v.segment<3>(h) = identityFrom->segment<3>(h);
    else
      v.segment<3>(h).setZero();
  }
}

Vec3 FemBody::stiffnessRow(std::size_t r, const double* in, bool skipFixed) const {
  double acc[3] = {0.0, 0.0, 0.0};
  for (int s = rowStart_[r]; s < rowStart_[r + 1]; ++s) {
    const std::size_t col = std::size_t(colIndex_[std::size_t(s)]);
    if (!(skipFixed && fixed_[col])) addMul(blocks_[std::size_t(s)], in + 3 * col, acc);
  }
  for (int k = lowerStart_[r]; k < lowerStart_[r + 1]; ++k) {
    const LowerBlock& l = lower_[std::size_t(k)];
    if (!(skipFixed && fixed_[std::size_t(l.col)]))
      addMulT(blocks_[std::size_t(l.slot)], in + 3 * l.col, acc);
  }
  return Vec3(acc[0], acc[1], acc[2]);
}

// z = M⁻¹ r. Node rows: block Jacobi, z_i = D_i⁻¹ r_i, or block symmetric
// Gauss–Seidel over A's node blocks (D_i as assembled for block Jacobi,
// off-diagonal blocks stiffScale·K_ij between free nodes):
// (D + L) y = r forward, then (D + U) z = D y backward. M is SPD for any
// off-diagonal blocks once every D_i is, so the contact spring's and the
// hanging nodes' couplings can be left out. Dynamic obstacles' rows: their
// inverse 6×6 diagonal block.
void FemBody::applyPreconditioner(const VecX& r, VecX& z) const {
  const std::size_t n = x_.size();
  double* zd = z.data();
  const double* rd = r.data();
  if (options_.preconditioner == FemPreconditioner::BlockJacobi) {
    for (std::size_t i = 0; i < n; ++i) {
      double* y = zd + 3 * i;
      y[0] = y[1] = y[2] = 0.0;
      addMul(invBlockDiag_[i], rd + 3 * i, y);
    }
  } else {
    const double scale = sysStiffScale_;
    z.head(Eigen::Index(3 * n)) = r.head(Eigen::Index(3 * n));
    for (std::size_t i = 0; i < n; ++i) {
      double y[3] = {0.0, 0.0, 0.0};
      addMul(invBlockDiag_[i], zd + 3 * i, y);
      zd[3 * i] = y[0], zd[3 * i + 1] = y[1], zd[3 * i + 2] = y[2];
      if (sweepSkip_[i]) continue;
      const double ys[3] = {-scale * y[0], -scale * y[1], -scale * y[2]};
      for (int s = rowStart_[i] + 1; s < rowStart_[i + 1]; ++s) {
        const std::size_t c = std::size_t(colIndex_[std::size_t(s)]);
        if (!sweepSkip_[c]) addMulT(blocks_[std::size_t(s)], ys, zd + 3 * c);
      }
    }
    for (std::size_t i = n; i-- > 0;) {
      if (sweepSkip_[i]) continue;
      double acc[3] = {0.0, 0.0, 0.0};
      for (int s = rowStart_[i] + 1; s < rowStart_[i + 1]; ++s) {
        const std::size_t c = std::size_t(colIndex_[std::size_t(s)]);
        if (!sweepSkip_[c]) addMul(blocks_[std::size_t(s)], zd + 3 * c, acc);
      }
      const double sa[3] = {-scale * acc[0], -scale * acc[1], -scale * acc[2]};
      addMul(invBlockDiag_[i], sa, zd + 3 * i);
    }
  }
  const Eigen::Index base = Eigen::Index(3 * n);
  for (std::size_t d = 0; d < obstaclePre_.size(); ++d)
    z.segment<6>(base + Eigen::Index(6 * d)).noalias() = obstaclePre_[d] * r.segment<6>(base + Eigen::Index(6 * d));
}

void FemBody::applyStiffness(Eigen::Ref<const VecX> in, Eigen::Ref<VecX> out) const {
  forRange(x_.size(), 256, [&](std::size_t b, std::size_t e) {
    for (std::size_t r = b; r < e; ++r) out.segment<3>(Eigen::Index(3 * r)) = stiffnessRow(r, in.data(), false);
  });
}

Result<FemStepReport> FemBody::step(double h) {
  constexpr const char* where = "FemBody::step";
  if (!(h > 0.0) || !std::isfinite(h))
    return femimpl::invalid("time step h = " + femimpl::num(h) + " s is not positive", where, "pass h > 0, e.g. 1/100 s");
  assemble();

  const double alpha = damping_.alpha, beta = damping_.beta;
  const double massScale = 1.0 + h * alpha, stiffScale = h * beta + h * h;
  const std::size_t n = x_.size();

  // tmp = K v, fixed columns included: a fixed node's prescribed velocity
  // (kept through the step, so its Δv is zero) drives the free nodes.
  applyStiffness(Eigen::Map<const VecX>(v_.data()->data(), Eigen::Index(3 * n)), tmp_);
  // Contact, implicitly. Obstacles: the penalty k·depth·n less its velocity
  // term h·k·n(n·v) in the right-hand side, h²·k·n nᵀ on the diagonal. The
  // springs after the node loop.
  for (std::size_t j = 0; j < obstacles_.size(); ++j) {
    const FemObstacle& o = obstacles_[j];
    obstacleCenter_[j] = o.pose * o.centerOfMass;
    if (o.mass > 0) obstacleInertia_[j] = o.pose.linear() * o.inertia * o.pose.linear().transpose();
  }
  findObstacleContacts();
  sysContactScale_ = h * h;
  sysDampScale_ = h;
  forRange(n, 512, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      const Eigen::Index o = Eigen::Index(3 * i);
      if (fixed_[i]) {
        rhs_.segment<3>(o).setZero();
        dv_.segment<3>(o).setZero();
        invBlockDiag_[i].setIdentity();
        sweepSkip_[i] = 1;
        continue;
      }
      Vec3 f = force_[i] + fext_[i] + mass_[i] * (gravity_ - alpha * v_[i]) - (beta + h) * tmp_.segment<3>(o);
      // Block-Jacobi: the node's 3×3 diagonal block of A, SPD like A.
      Mat3 d = stiffScale * blocks_[std::size_t(rowStart_[i])];
      d.diagonal().array() += massScale * mass_[i];
      if (contactOf_[i] >= 0) {
        const NodeContact& c = contacts_[std::size_t(contactOf_[i])];
        const Mat3 nnt = c.normal * c.normal.transpose();
        f += contactForce(c, h) + contactFriction(c);
        d += (h * h * c.stiffness) * nnt + (h * c.friction) * (Mat3::Identity() - nnt);
      }
      rhs_.segment<3>(o) = h * f;
      invBlockDiag_[i] = d;
      sweepSkip_[i] = 0;
    }
  });
  // The springs: f_s = K·(a − Σwⱼxⱼ − hΣwⱼvⱼ) + load shared by weight wᵢ, and
  // h²·wᵢ²·K on the diagonal blocks (the rest is in applySystem).
  forEachSpring([&](const FemPointSpring& s) {
    Vec3 point = Vec3::Zero(), velocity = Vec3::Zero();
    for (std::size_t j = 0; j < 4; ++j)
      if (s.weights[j] != 0.0)
        point += s.weights[j] * x_[s.nodes[j]], velocity += s.weights[j] * v_[s.nodes[j]];
    const Vec3 pull = s.stiffness * (s.anchor - point - h * velocity) + s.load;
    for (std::size_t j = 0; j < 4; ++j) {
      const std::uint32_t i = s.nodes[j];
      if (s.weights[j] == 0.0 || fixed_[i]) continue;
      rhs_.segment<3>(Eigen::Index(3 * i)) += (h * s.weights[j]) * pull;
      invBlockDiag_[i] += (h * h * s.weights[j] * s.weights[j]) * s.stiffness;
    }
  });
  // Hanging nodes: their loads act on their masters (Pᵀb). The
  // preconditioner takes the diagonal part of Pᵀ A P that each master's own
  // block and its hanging nodes' blocks give (w²·A_hh; SPD, which is all
  // PCG needs of it).
  if (!hangNode_.empty()) {
    foldHanging(rhs_, nullptr);
    for (std::size_t k = 0; k < hangNode_.size(); ++k) {
      const std::uint32_t node = hangNode_[k];
      for (std::uint32_t s = hangStart_[k]; s < hangStart_[k + 1]; ++s)
        if (!fixed_[hangMaster_[s]])
          invBlockDiag_[hangMaster_[s]] += hangWeight_[s] * hangWeight_[s] * invBlockDiag_[node];
      invBlockDiag_[node].setIdentity();
      sweepSkip_[node] = 1;
      dv_.segment<3>(Eigen::Index(3 * node)).setZero();
    }
  }
  forRange(n, 512, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) invBlockDiag_[i] = invBlockDiag_[i].inverse();
  });
  // Dynamic obstacles: −h·Jᵀf of their contacts' start forces on the
  // right, and their mass, inertia and contact terms (h²k·JᵀnnᵀJ) as one
  // 6×6 block of the preconditioner. They start from zero velocity change.
  if (rigidRows_ > 0) {
    rhs_.tail(Eigen::Index(rigidRows_)).setZero();
    dv_.tail(Eigen::Index(rigidRows_)).setZero();
    for (std::size_t j = 0; j < obstacles_.size(); ++j)
      if (obstacleRow_[j] >= 0) {
        auto& p = obstaclePre_[std::size_t(obstacleRow_[j] - Eigen::Index(3 * n)) / 6];
        p.setZero();
        p.topLeftCorner<3, 3>().diagonal().setConstant(obstacles_[j].mass);
        p.bottomRightCorner<3, 3>() = obstacleInertia_[j];
      }
    for (const NodeContact& c : contacts_) {
      const Eigen::Index r = obstacleRow_[c.obstacle];
      if (r < 0) continue;
      const Vec3 f = contactForce(c, h) + contactFriction(c);
      rhs_.segment<3>(r) -= h * f;
      rhs_.segment<3>(r + 3) -= h * c.arm.cross(f);
      Eigen::Matrix<double, 6, 1> jn;
      jn << c.normal, c.arm.cross(c.normal);
      auto& pre = obstaclePre_[std::size_t(r - Eigen::Index(3 * n)) / 6];
      pre += (h * h * c.stiffness) * jn * jn.transpose();
      if (c.friction > 0.0) {
        // The contact point's velocity G·(ΔV, ΔΩ) = ΔV − arm × ΔΩ, across n.
        Eigen::Matrix<double, 3, 6> g;
        g.leftCols<3>().setIdentity();
        g.rightCols<3>() << 0.0, c.arm.z(), -c.arm.y(), -c.arm.z(), 0.0, c.arm.x(), c.arm.y(), -c.arm.x(),
            0.0;
        pre += (h * c.friction) * g.transpose() * (Mat3::Identity() - c.normal * c.normal.transpose()) * g;
      }
    }
    for (auto& p : obstaclePre_) p = p.inverse().eval();
  }
  if (!options_.warmStart) dv_.setZero();

  // Stopping test relative to the forces in balance, not only to ‖b‖: near
  // equilibrium b is the small difference of large elastic and external
  // forces, and a residual relative to it alone would ask for ever more
  // iterations while the motion is already resolved.
  double elastic2 = 0.0, load2 = 0.0;
  for (std::size_t i = 0; i < n; ++i)
    if (!fixed_[i])
      elastic2 += force_[i].squaredNorm(), load2 += (fext_[i] + mass_[i] * gravity_).squaredNorm();
  const double bNorm = rhs_.norm();
  const double forceScale = h * (std::sqrt(elastic2) + std::sqrt(load2));
  const double tolerance =
      bNorm > 0.0 ? options_.tolerance * std::max(1.0, forceScale / bNorm) : options_.tolerance;

  // Both operators capture only `this`, so std::function keeps them in its
  // small buffer: no allocation per step. The preconditioner is applied on
  // the calling thread (Gauss–Seidel sweeps are sequential; block Jacobi's
  // 3n·3 flops would cost more in synchronisation than they save).
  sysMassScale_ = massScale;
  sysStiffScale_ = stiffScale;
  const LinearOperator applyA = [this](const VecX& in, VecX& out) {
    applySystem(in, out, sysMassScale_, sysStiffScale_);
  };
  const LinearOperator applyM = [this](const VecX& r, VecX& z) { applyPreconditioner(r, z); };
  pcg_.setOptions({.tolerance = tolerance,
                   .maxIterations = options_.maxIterations,
                   .preconditioner = Preconditioner::None,
                   .useInitialGuess = true});
  auto solved = pcg_.solve(applyA, rhs_, dv_, applyM);
  report_.cgIterations = pcg_.lastReport().iterations;
  report_.relativeResidual = pcg_.lastReport().relativeResidual;
  report_.converged = solved.ok();
  if (!solved && solved.error().code != ErrorCode::Timeout) {
    dv_.setZero();
    return std::move(solved).error().within(where);
  }
  if (!dv_.allFinite()) {
    dv_.setZero();
    return femimpl::invalid("the velocity update is not finite", where,
                   "the state blew up: reduce the time step or raise the damping");
  }

  forRange(n, 1024, [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      if (hanging_[i]) continue;
      if (!fixed_[i]) v_[i] += dv_.segment<3>(Eigen::Index(3 * i));
      x_[i] += h * v_[i];  // a fixed node: its prescribed motion
    }
  });
  syncHanging();
  // Dynamic obstacles leave the step with what the contact did to them.
  for (std::size_t j = 0; j < obstacles_.size(); ++j)
    if (const Eigen::Index r = obstacleRow_[j]; r >= 0) {
      obstacleVelocity_[j].linear += dv_.segment<3>(r);
      obstacleVelocity_[j].angular += dv_.segment<3>(r + 3);
    }
  // What the obstacles took: the penalty springs at the end state (the
  // linearisation the step solved with), never pulling.
  std::fill(obstacleWrench_.begin(), obstacleWrench_.end(), Wrench{});
  for (const NodeContact& c : contacts_) {
    const double push = c.stiffness * c.depth - h * contactRate(c);
    if (push <= 0.0) continue;
    const Vec3 f = push * c.normal + contactFriction(c);  // on the node
    obstacleWrench_[c.obstacle] += Wrench{-f, -c.arm.cross(f)};
  }
  return report_;
}

// ---------------------------------------------------------------------------
// FemBody: energy and forces at the current state (const, not real-time)
// ---------------------------------------------------------------------------

double FemBody::elasticEnergy() const {
  double energy = 0.0;
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    Quat q = rot_[e];
    const Mat3 R = options_.corotational ? elementRotation(e, x_, q) : Mat3::Identity();
    Vec3 f[4], g[4];
    energy += elementForces(e, R, x_, f, g);
  }
  return energy;
}

void FemBody::computeElasticForces(std::vector<Vec3>& out) const {
  out.assign(x_.size(), Vec3::Zero());
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    Quat q = rot_[e];
    const Mat3 R = options_.corotational ? elementRotation(e, x_, q) : Mat3::Identity();
    Vec3 f[4], g[4];
    elementForces(e, R, x_, f, g);
    for (int i = 0; i < 4; ++i) out[tets_[e][i]] += f[i];
  }
}

void FemBody::computeConstraintForces(std::vector<Vec3>& out) const {
  computeElasticForces(out);
  // The forces on node i (fixed or hanging), its share of what the
  // constraints must balance.
  for (std::size_t i = 0; i < x_.size(); ++i) {
    if (!fixed_[i] && !hanging_[i]) continue;
    const Vec3 kv = stiffnessRow(i, v_.data()->data(), false);  // row i of K·v
    const Vec3 damping = -damping_.alpha * mass_[i] * v_[i] - damping_.beta * kv;
    out[i] += damping + fext_[i] + mass_[i] * gravity_;
  }
  // A hanging node's forces act on its masters; fixed masters hold them.
  for (std::size_t k = 0; k < hangNode_.size(); ++k)
    for (std::uint32_t s = hangStart_[k]; s < hangStart_[k + 1]; ++s)
      if (fixed_[hangMaster_[s]]) out[hangMaster_[s]] += hangWeight_[s] * out[hangNode_[k]];
  for (std::size_t i = 0; i < x_.size(); ++i) out[i] = fixed_[i] ? Vec3(-out[i]) : Vec3::Zero();
}

}  // namespace dm
