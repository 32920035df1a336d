// FemBody::applyCut: a TetCutter's update (new nodes, split elements)
// applied to a body in place — masses, the block pattern and the element
// colouring updated, not rebuilt; see dm/physics/fem.hpp and
// dm/physics/tet_cut.hpp.
#include <dm/physics/fem.hpp>
#include <dm/physics/tet_cut.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <bit>
#include <string>

#include "fem_shared.hpp"

namespace dm {

Status FemBody::applyCut(const TetCutter& cutter, const CutUpdate& update) {
  constexpr const char* where = "FemBody::applyCut";
  const std::size_t n = x_.size(), T = tets_.size();
  const std::size_t n1 = cutter.nodeCount(), T1 = cutter.elements().size();
  if (!hangNode_.empty())
    return femimpl::invalid("the body has " + std::to_string(hangNode_.size()) + " hanging nodes", where,
                            "cut a body built from a conforming mesh");
  if (n1 < n || T1 < T || cutter.originalNodeCount() > n)
    return femimpl::invalid("the cutter has " + std::to_string(n1) + " nodes and " + std::to_string(T1) +
                                " elements, the body " + std::to_string(n) + " and " + std::to_string(T),
                            where, "give the cutter made from this body's mesh, after each of its cuts");
  std::size_t appended = 0;
  for (const CutNodeChange& c : update.newNodes) {
    if (c.node < n || c.node >= n1 || c.source >= n)
      return femimpl::invalid("new node " + std::to_string(c.node) + " from node " +
                                  std::to_string(c.source) + " does not fit a body of " + std::to_string(n) +
                                  " nodes",
                              where);
    ++appended;
  }
  std::size_t newElements = 0;
  for (const std::uint32_t e : update.changedElements) {
    if (e >= T1)
      return femimpl::invalid(
          "changed element " + std::to_string(e) + " is out of range (" + std::to_string(T1) + ")", where);
    newElements += e >= T;
  }
  if (appended != n1 - n || newElements != T1 - T)
    return femimpl::invalid("the update appends " + std::to_string(appended) + " nodes and " +
                                std::to_string(newElements) + " elements, the cutter has " +
                                std::to_string(n1 - n) + " and " + std::to_string(T1 - T) +
                                " more than the body",
                            where, "apply every update of the cutter, in order");

  // New nodes start from their sources' state.
  const double rho = material_.density;
  x0_.resize(n1), x_.resize(n1), v_.resize(n1);
  fext_.resize(n1, Vec3::Zero()), force_.resize(n1, Vec3::Zero());
  fixed_.resize(n1, 0), mass_.resize(n1, 0.0), hanging_.resize(n1, 0), contactOf_.resize(n1, -1);
  invBlockDiag_.resize(n1, Mat3::Identity()), sweepSkip_.resize(n1, 0);
  for (const CutNodeChange& c : update.newNodes) {
    x0_[c.node] = x0_[cutter.nodeOrigin()[c.node]];
    x_[c.node] = x_[c.source];
    v_[c.node] = v_[c.source];
    fixed_[c.node] = fixed_[c.source];
  }

  // Elements: their nodes, material and the masses they give.
  tets_.resize(T1), rot_.resize(T1), restInverse_.resize(T1), restVolume_.resize(T1), slot_.resize(T1);
  colour_.resize(T1, -1);
  for (const std::uint32_t e : update.changedElements)
    if (e < T)
      for (const std::uint32_t v : tets_[e]) mass_[v] -= rho * restVolume_[e] / 4.0;
  for (const std::uint32_t e : update.changedElements) {
    const CutElement& ce = cutter.elements()[e];
    if (e >= T) {
      restInverse_[e] = restInverse_[ce.source];  // the original's first copy keeps its index
      rot_[e] = rot_[ce.source];
    }
    tets_[e] = ce.nodes;
    restVolume_[e] = ce.fraction / (6.0 * restInverse_[e].determinant());
    for (const std::uint32_t v : tets_[e]) mass_[v] += rho * restVolume_[e] / 4.0;
  }
  totalMass_ = 0.0;
  for (const double m : mass_) totalMass_ += m;

  // The pattern: the changed elements' node pairs that are not in it yet,
  // merged row by row; the other elements' slots follow their blocks.
  std::vector<std::uint64_t> add;
  for (const std::uint32_t e : update.changedElements)
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) {
        const std::uint32_t a = tets_[e][i], b = tets_[e][j];
        if (a > b) continue;
        if (a < n && findBlock(a, b) >= 0) continue;
        add.push_back((std::uint64_t(a) << 32) | b);
      }
  std::sort(add.begin(), add.end());
  add.erase(std::unique(add.begin(), add.end()), add.end());
  if (!add.empty()) {
    std::vector<int> rowStart(n1 + 1, 0), col, oldToNew(colIndex_.size());
    col.reserve(colIndex_.size() + add.size());
    std::size_t k = 0;
    for (std::size_t row = 0; row < n1; ++row) {
      int s = row < n ? rowStart_[row] : 0;
      const int sEnd = row < n ? rowStart_[row + 1] : 0;
      while (s < sEnd || (k < add.size() && (add[k] >> 32) == row)) {
        const bool fromAdd = k < add.size() && (add[k] >> 32) == row &&
                             (s == sEnd || int(add[k] & 0xffffffffu) < colIndex_[std::size_t(s)]);
        if (fromAdd) {
          col.push_back(int(add[k++] & 0xffffffffu));
        } else {
          oldToNew[std::size_t(s)] = int(col.size());
          col.push_back(colIndex_[std::size_t(s++)]);
        }
      }
      rowStart[row + 1] = int(col.size());
    }
    rowStart_ = std::move(rowStart);
    colIndex_ = std::move(col);
    buildLowerBlocks();
    blocks_.assign(colIndex_.size(), Mat3::Zero());
    for (std::size_t e = 0; e < T; ++e)
      for (int& s : slot_[e]) s = s >= 0 ? oldToNew[std::size_t(s)] : ~oldToNew[std::size_t(~s)];
  }
  for (const std::uint32_t e : update.changedElements) setElementSlots(e);

  // Colours: each changed element takes the lowest colour none of its nodes
  // has; with more than 64 colours, all elements are coloured anew.
  int colours = int(colourStart_.size()) - 1;
  if (nodeColours_.empty() && colours <= 64) {
    nodeColours_.assign(n1, 0);  // (the changed elements' old colours too: a spare bit is harmless)
    for (std::size_t e = 0; e < T; ++e)
      for (const std::uint32_t v : tets_[e]) nodeColours_[v] |= std::uint64_t(1) << colour_[e];
  }
  bool recolour = nodeColours_.empty();
  if (!recolour) {
    nodeColours_.resize(n1, 0);
    for (const std::uint32_t e : update.changedElements) {
      std::uint64_t used = 0;
      for (const std::uint32_t v : tets_[e]) used |= nodeColours_[v];
      if (used == ~std::uint64_t(0)) {
        recolour = true;
        break;
      }
      const int c = std::countr_one(used);
      colour_[e] = c;
      colours = std::max(colours, c + 1);
      for (const std::uint32_t v : tets_[e]) nodeColours_[v] |= std::uint64_t(1) << c;
    }
  }
  if (recolour)
    colourAll();
  else
    groupColours(colours);

  // Solver vectors: the node rows grow, dynamic obstacles' rows move after
  // them; warm starts of new nodes from their sources.
  const auto rows = Eigen::Index(3 * n1 + rigidRows_);
  VecX dv = VecX::Zero(rows);
  dv.head(Eigen::Index(3 * n)) = dv_.head(Eigen::Index(3 * n));
  for (const CutNodeChange& c : update.newNodes)
    dv.segment<3>(Eigen::Index(3 * c.node)) = dv_.segment<3>(Eigen::Index(3 * c.source));
  dv_ = std::move(dv);
  rhs_.setZero(rows);
  tmp_.setZero(Eigen::Index(3 * n1));
  pcg_.reserve(rows);
  for (std::size_t j = 0, r = 3 * n1; j < obstacles_.size(); ++j)
    if (obstacleRow_[j] >= 0) obstacleRow_[j] = std::int32_t(r), r += 6;
  for (std::size_t i = n; i < n1; ++i) surfaceNodes_.push_back(std::uint32_t(i));
  contacts_.reserve(surfaceNodes_.size());
  return ok();
}

std::vector<TearSplit> tensileTears(const FemBody& body, const TetCutter& cutter, double strength) {
  struct Candidate {
    std::uint32_t element;
    double stress;
    Vec3 direction;
  };
  std::vector<Candidate> over;
  const std::size_t T = std::min(body.tetCount(), cutter.elements().size());
  for (std::size_t e = 0; e < T; ++e) {
    if (cutter.isSplit(e)) continue;
    const Eigen::SelfAdjointEigenSolver<Mat3> eig(body.elementStress(e));
    const double top = eig.eigenvalues()(2);
    if (top >= strength) over.push_back({std::uint32_t(e), top, eig.eigenvectors().col(2)});
  }
  std::vector<TearSplit> tears;
  for (const Candidate& c : over)
    if (cutter.touchesCrack(c.element)) tears.push_back({c.element, c.direction});
  if (tears.empty() && !over.empty()) {
    const Candidate* top = &over.front();
    for (const Candidate& c : over)
      if (c.stress > top->stress) top = &c;
    tears.push_back({top->element, top->direction});
  }
  return tears;
}

}  // namespace dm
