// Continuous cutting of tetrahedral meshes by the virtual node algorithm;
// see dm/physics/tet_cut.hpp for the method and its reference.
#include <dm/collide/triangle.hpp>
#include <dm/physics/tet_cut.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <string>
#include <utility>

namespace dm {

namespace {
namespace tetcut {

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

// Local edges of a tetrahedron and the local edge of each corner pair.
constexpr int kEdge[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
constexpr int kEdgeOf[4][4] = {{-1, 0, 1, 2}, {0, -1, 3, 4}, {1, 3, -1, 5}, {2, 4, 5, -1}};
// The face opposite each corner, counter-clockwise seen from outside a
// positively oriented tetrahedron.
constexpr int kFace[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};

Error invalidCut(std::string what, std::string where) {
  return fail(ErrorCode::InvalidArgument, std::move(what), std::move(where));
}

// Where segment p→q meets triangle abc, as a fraction of the segment in
// [0, 1], or −1 where it does not: the watertight test, so an edge through
// the diagonal two sweep triangles share is crossed.
double segmentTriangle(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c) {
  RayTriangleHit hit;
  return rayTriangle(p, q - p, a, b, c, 0.0, 1.0, hit) ? hit.t : -1.0;
}

struct Uf {
  std::vector<std::uint32_t> parent;
  explicit Uf(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  std::uint32_t find(std::uint32_t a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  }
  void unite(std::uint32_t a, std::uint32_t b) {
    a = find(a), b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);  // the lower index is the root: deterministic
  }
};

// Weights over a tetrahedron's four corners.
using Weights = std::array<double, 4>;

Vec3 pointOf(const Weights& w, const std::array<Vec3, 4>& p) {
  return w[0] * p[0] + w[1] * p[1] + w[2] * p[2] + w[3] * p[3];
}

}  // namespace tetcut
}  // namespace

std::array<CutTriangle, 2> bladeSweep(const Vec3& a0, const Vec3& b0, const Vec3& a1, const Vec3& b1) {
  return {CutTriangle{a0, b0, b1}, CutTriangle{a0, b1, a1}};
}

void CutSurface::evaluate(std::span<const Vec3> x, std::vector<Vec3>& out) const {
  out.resize(vertices.size());
  for (std::size_t i = 0; i < vertices.size(); ++i) {
    const CutSurfaceVertex& v = vertices[i];
    Vec3 p = Vec3::Zero();
    for (int k = 0; k < 4; ++k)
      if (v.weights[k] != 0.0) p += v.weights[k] * x[v.nodes[k]];
    out[i] = p;
  }
}

Result<TetCutter> TetCutter::create(const TetMesh& mesh, const TetCutOptions& options) {
  using namespace tetcut;
  constexpr const char* where = "TetCutter::create";
  if (auto st = mesh.validate(); !st) return st.error();
  if (!mesh.hanging.empty())
    return invalidCut("the mesh has " + std::to_string(mesh.hanging.size()) +
                          " hanging nodes (a hierarchical grid); cutting needs a conforming mesh",
                      where);
  if (!(options.snap > 0.0 && options.snap <= 0.25))
    return invalidCut("snap = " + std::to_string(options.snap) + " is outside (0, 0.25]",
                      std::string(where) + ": snap");
  TetCutter c;
  c.options_ = options;
  c.x0_ = mesh.nodes;
  c.tets_ = mesh.tets;
  const std::size_t T = mesh.tets.size();
  c.volume_.resize(T);
  for (std::size_t t = 0; t < T; ++t) c.volume_[t] = mesh.tetVolume(t);

  // Edges: sorted unique (lower, higher) pairs.
  std::vector<std::uint64_t> keys;
  keys.reserve(6 * T);
  auto edgeKey = [](std::uint32_t a, std::uint32_t b) {
    return (std::uint64_t(std::min(a, b)) << 32) | std::max(a, b);
  };
  for (const Tet& e : mesh.tets)
    for (const auto& le : kEdge) keys.push_back(edgeKey(e[le[0]], e[le[1]]));
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  c.edgeNodes_.resize(keys.size());
  for (std::size_t i = 0; i < keys.size(); ++i)
    c.edgeNodes_[i] = {std::uint32_t(keys[i] >> 32), std::uint32_t(keys[i] & 0xffffffffu)};
  c.tetEdge_.resize(T);
  std::vector<std::uint32_t> count(keys.size() + 1, 0);
  for (std::size_t t = 0; t < T; ++t)
    for (int k = 0; k < 6; ++k) {
      const auto id =
          std::uint32_t(std::lower_bound(keys.begin(), keys.end(),
                                         edgeKey(c.tets_[t][kEdge[k][0]], c.tets_[t][kEdge[k][1]])) -
                        keys.begin());
      c.tetEdge_[t][k] = id;
      ++count[id + 1];
    }
  std::partial_sum(count.begin(), count.end(), count.begin());
  c.edgeTetStart_ = count;
  c.edgeTets_.resize(6 * T);
  for (std::size_t t = 0; t < T; ++t)
    for (int k = 0; k < 6; ++k) c.edgeTets_[count[c.tetEdge_[t][k]]++] = std::uint32_t(t);

  // Faces: sorted corner triples.
  struct FaceRef {
    std::array<std::uint32_t, 3> key;
    std::uint32_t tet;
    int corner;
  };
  std::vector<FaceRef> faces;
  faces.reserve(4 * T);
  for (std::size_t t = 0; t < T; ++t)
    for (int k = 0; k < 4; ++k) {
      std::array<std::uint32_t, 3> f{c.tets_[t][kFace[k][0]], c.tets_[t][kFace[k][1]],
                                     c.tets_[t][kFace[k][2]]};
      std::sort(f.begin(), f.end());
      faces.push_back({f, std::uint32_t(t), k});
    }
  std::sort(faces.begin(), faces.end(), [](const FaceRef& a, const FaceRef& b) {
    return a.key != b.key ? a.key < b.key : a.tet < b.tet;
  });
  c.tetFace_.resize(T);
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i + 1;
    while (j < faces.size() && faces[j].key == faces[i].key) ++j;
    if (j - i > 2)
      return invalidCut("face (" + std::to_string(faces[i].key[0]) + ", " + std::to_string(faces[i].key[1]) +
                            ", " + std::to_string(faces[i].key[2]) + ") belongs to " + std::to_string(j - i) +
                            " tetrahedra (at most two in a valid mesh)",
                        where);
    const auto id = std::uint32_t(c.faceTets_.size());
    c.faceTets_.push_back({faces[i].tet, j - i == 2 ? faces[i + 1].tet : kNone});
    for (std::size_t k = i; k < j; ++k) c.tetFace_[faces[k].tet][faces[k].corner] = id;
    i = j;
  }

  c.crossing_.assign(c.edgeNodes_.size(), -1.0);
  c.label_.assign(T, {0, 0, 0, 0});
  c.labelCount_.assign(T, 1);
  c.copyOf_.resize(T);
  c.elements_.resize(T);
  for (std::size_t t = 0; t < T; ++t) {
    c.copyOf_[t] = {std::uint32_t(t), kNone, kNone, kNone};
    c.elements_[t] = {c.tets_[t], std::uint32_t(t), 1.0};
  }
  c.origin_.resize(c.x0_.size());
  std::iota(c.origin_.begin(), c.origin_.end(), 0u);
  return c;
}

std::vector<Vec3> TetCutter::restPositions() const {
  std::vector<Vec3> out(origin_.size());
  for (std::size_t i = 0; i < origin_.size(); ++i) out[i] = x0_[origin_[i]];
  return out;
}

TetMesh TetCutter::mesh() const {
  TetMesh m;
  m.nodes = restPositions();
  m.tets.reserve(elements_.size());
  m.fractions.reserve(elements_.size());
  for (const CutElement& e : elements_) {
    m.tets.push_back(e.nodes);
    m.fractions.push_back(e.fraction);
  }
  return m;
}

double TetCutter::elementVolume(std::size_t e) const {
  return elements_[e].fraction * volume_[elements_[e].source];
}

int TetCutter::labelCorners(std::size_t t, std::array<std::uint8_t, 4>& label) const {
  using namespace tetcut;
  std::array<int, 4> root{0, 1, 2, 3};
  auto find = [&](int a) {
    while (root[a] != a) a = root[a];
    return a;
  };
  for (int k = 0; k < 6; ++k)
    if (crossing_[tetEdge_[t][k]] < 0.0) {
      const int a = find(kEdge[k][0]), b = find(kEdge[k][1]);
      if (a != b) root[std::max(a, b)] = std::min(a, b);
    }
  int n = 0;
  std::array<int, 4> of{-1, -1, -1, -1};
  for (int j = 0; j < 4; ++j) {
    const int r = find(j);
    if (of[r] < 0) of[r] = n++;
    label[j] = std::uint8_t(of[r]);
  }
  return n;
}

TetCutter::Subdivision TetCutter::subdivision(std::size_t t) const {
  using namespace tetcut;
  Subdivision s;
  for (int k = 0; k < 6; ++k) {
    const int a = kEdge[k][0], b = kEdge[k][1];
    const double c = crossing_[tetEdge_[t][k]];
    s.crossed[k] = c >= 0.0;
    const double fromA = !s.crossed[k] ? 0.5 : (tets_[t][a] < tets_[t][b] ? c : 1.0 - c);
    s.edge[k] = {0, 0, 0, 0};
    s.edge[k][a] = 1.0 - fromA;
    s.edge[k][b] = fromA;
  }
  auto meanOfCrossings = [&](std::initializer_list<int> edges, Weights& w) {
    w = {0, 0, 0, 0};
    int n = 0;
    for (const int e : edges)
      if (s.crossed[e]) {
        for (int j = 0; j < 4; ++j) w[j] += s.edge[e][j];
        ++n;
      }
    for (int j = 0; j < 4; ++j) w[j] /= std::max(n, 1);
    return n;
  };
  for (int k = 0; k < 4; ++k) {
    const int* f = kFace[k];
    if (meanOfCrossings({kEdgeOf[f[0]][f[1]], kEdgeOf[f[1]][f[2]], kEdgeOf[f[2]][f[0]]}, s.face[k]) < 2) {
      s.face[k] = {0, 0, 0, 0};
      for (int i = 0; i < 3; ++i) s.face[k][f[i]] = 1.0 / 3.0;
    }
  }
  if (meanOfCrossings({0, 1, 2, 3, 4, 5}, s.cell) == 0) s.cell = {0.25, 0.25, 0.25, 0.25};
  return s;
}

void TetCutter::componentFractions(std::size_t t, const std::array<std::uint8_t, 4>& label, int k,
                                   std::array<double, 4>& fraction) const {
  using namespace tetcut;
  const Subdivision s = subdivision(t);
  const std::array<Vec3, 4> p{x0_[tets_[t][0]], x0_[tets_[t][1]], x0_[tets_[t][2]], x0_[tets_[t][3]]};
  const Vec3 c = pointOf(s.cell, p);
  // 24 small tetrahedra (corner v, edge point of (v, w), point of a face
  // holding both, cell point), each v's component's.
  std::array<double, 4> vol{0, 0, 0, 0};
  for (int v = 0; v < 4; ++v)
    for (int face = 0; face < 4; ++face) {
      if (face == v) continue;
      const Vec3 f = pointOf(s.face[face], p);
      for (int w = 0; w < 4; ++w) {
        if (w == v || w == face) continue;
        const Vec3 e = pointOf(s.edge[kEdgeOf[v][w]], p);
        vol[label[v]] += std::abs((e - p[v]).dot((f - p[v]).cross(c - p[v]))) / 6.0;
      }
    }
  const double total = vol[0] + vol[1] + vol[2] + vol[3];
  for (int l = 0; l < 4; ++l) fraction[l] = l < k ? vol[l] / total : 0.0;
}

Status TetCutter::checkPositions(std::span<const Vec3> x, const char* where) const {
  using namespace tetcut;
  if (x.size() != nodeCount())
    return invalidCut(std::to_string(x.size()) + " positions for " + std::to_string(nodeCount()) + " nodes",
                      where);
  for (std::size_t i = 0; i < x.size(); ++i)
    if (!x[i].allFinite()) return invalidCut("position " + std::to_string(i) + " is not finite", where);
  return ok();
}

void TetCutter::cross(std::size_t e, double s, std::vector<std::uint32_t>& dirty, CutUpdate& update) {
  crossing_[e] = std::clamp(s, options_.snap, 1.0 - options_.snap);
  ++crossedCount_, ++update.edgesCrossed;
  for (std::uint32_t i = edgeTetStart_[e]; i < edgeTetStart_[e + 1]; ++i) dirty.push_back(edgeTets_[i]);
}

bool TetCutter::touchesCrack(std::size_t e) const {
  const std::uint32_t t = elements_[e].source;
  for (const std::uint32_t edge : tetEdge_[t])
    if (crossing_[edge] >= 0.0) return true;
  return false;
}

Result<CutUpdate> TetCutter::cut(std::span<const CutTriangle> surface, std::span<const Vec3> x) {
  using namespace tetcut;
  constexpr const char* where = "TetCutter::cut";
  if (auto st = checkPositions(x, where); !st) return st.error();
  for (std::size_t i = 0; i < surface.size(); ++i)
    for (const Vec3& p : surface[i])
      if (!p.allFinite())
        return invalidCut("surface triangle " + std::to_string(i) + " is not finite", where);

  CutUpdate update;
  std::vector<std::uint32_t> dirty;
  for (const CutTriangle& tri : surface) {
    const Vec3 lo = tri[0].cwiseMin(tri[1]).cwiseMin(tri[2]);
    const Vec3 hi = tri[0].cwiseMax(tri[1]).cwiseMax(tri[2]);
    for (std::size_t e = 0; e < edgeNodes_.size(); ++e) {
      if (crossing_[e] >= 0.0) continue;
      const Vec3& p = x[edgeNodes_[e][0]];
      const Vec3& q = x[edgeNodes_[e][1]];
      if ((p.cwiseMax(q).array() < lo.array()).any() || (p.cwiseMin(q).array() > hi.array()).any()) continue;
      const double s = segmentTriangle(p, q, tri[0], tri[1], tri[2]);
      if (s >= 0.0) cross(e, s, dirty, update);
    }
  }
  splitDirty(dirty, update);
  return update;
}

Result<CutUpdate> TetCutter::tear(std::span<const TearSplit> splits, std::span<const Vec3> x) {
  using namespace tetcut;
  constexpr const char* where = "TetCutter::tear";
  if (auto st = checkPositions(x, where); !st) return st.error();
  for (std::size_t i = 0; i < splits.size(); ++i) {
    if (splits[i].element >= elements_.size())
      return invalidCut("split " + std::to_string(i) + " names element " + std::to_string(splits[i].element) +
                            " of " + std::to_string(elements_.size()),
                        where);
    if (!splits[i].normal.allFinite() || splits[i].normal.squaredNorm() == 0.0)
      return invalidCut("split " + std::to_string(i) + ": the normal is zero or not finite", where);
  }
  CutUpdate update;
  std::vector<std::uint32_t> dirty;
  for (const TearSplit& split : splits) {
    const CutElement& el = elements_[split.element];
    const std::uint32_t t = el.source;
    // Through the crossings the element has (a crack's plane), else its centroid.
    Vec3 through = Vec3::Zero();
    int n = 0;
    for (const std::uint32_t e : tetEdge_[t])
      if (crossing_[e] >= 0.0) {
        const Vec3& p = x[edgeNodes_[e][0]];
        through += p + crossing_[e] * (x[edgeNodes_[e][1]] - p), ++n;
      }
    if (n > 0)
      through /= n;
    else
      through = (x[el.nodes[0]] + x[el.nodes[1]] + x[el.nodes[2]] + x[el.nodes[3]]) / 4.0;
    const Vec3 normal = split.normal.normalized();
    for (const std::uint32_t e : tetEdge_[t]) {
      if (crossing_[e] >= 0.0) continue;
      const double dp = normal.dot(x[edgeNodes_[e][0]] - through),
                   dq = normal.dot(x[edgeNodes_[e][1]] - through);
      if ((dp < 0.0) != (dq < 0.0) && dp != dq) cross(e, dp / (dp - dq), dirty, update);
    }
  }
  splitDirty(dirty, update);
  return update;
}

void TetCutter::splitDirty(std::vector<std::uint32_t>& dirty, CutUpdate& update) {
  using namespace tetcut;
  std::sort(dirty.begin(), dirty.end());
  dirty.erase(std::unique(dirty.begin(), dirty.end()), dirty.end());
  for (const std::uint32_t t : dirty) {
    std::array<std::uint8_t, 4> label{};
    const int k = labelCorners(t, label);
    const int kOld = labelCount_[t];
    if (k == kOld) continue;  // components only split: the same count is the same partition
    ++update.tetsSplit;
    // Each new component comes from the old one of its first corner; the
    // first new component of an old one keeps that copy's element.
    std::array<std::uint32_t, 4> element{kNone, kNone, kNone, kNone};
    std::array<bool, 4> reused{false, false, false, false};
    std::array<Tet, 4> oldNodes{};
    for (int l = 0; l < kOld; ++l) oldNodes[l] = elements_[copyOf_[t][l]].nodes;
    for (int l = 0; l < k; ++l) {
      int first = 0;
      while (label[first] != l) ++first;
      const int from = label_[t][first];
      if (!reused[from]) {
        reused[from] = true;
        element[l] = copyOf_[t][from];
      } else {
        element[l] = std::uint32_t(elements_.size());
        elements_.push_back({oldNodes[from], t, 0.0});
      }
      elements_[element[l]].nodes = oldNodes[from];
    }
    std::array<double, 4> fraction{};
    componentFractions(t, label, k, fraction);
    for (int l = 0; l < k; ++l) {
      elements_[element[l]].fraction = fraction[l];
      update.changedElements.push_back(element[l]);
    }
    copyOf_[t] = element;
    label_[t] = label;
    labelCount_[t] = std::uint8_t(k);
    if (kOld == 1) split_.insert(std::upper_bound(split_.begin(), split_.end(), t), t);
  }
  if (update.tetsSplit > 0) regroupNodes(update);
  std::sort(update.changedElements.begin(), update.changedElements.end());
  update.changedElements.erase(std::unique(update.changedElements.begin(), update.changedElements.end()),
                               update.changedElements.end());
}

void TetCutter::regroupNodes(CutUpdate& update) {
  using namespace tetcut;
  const auto n0 = std::uint32_t(x0_.size());
  // Slots: four per copy of a split tetrahedron, in (tetrahedron, label)
  // order; then one anchor per original node that is a corner of one.
  std::vector<std::uint32_t> slotElement;
  std::vector<std::uint32_t> firstSlot(split_.size());
  for (std::size_t i = 0; i < split_.size(); ++i) {
    const std::uint32_t t = split_[i];
    firstSlot[i] = std::uint32_t(slotElement.size() * 4);
    for (int l = 0; l < labelCount_[t]; ++l) slotElement.push_back(copyOf_[t][l]);
  }
  const auto slotCount = std::uint32_t(slotElement.size() * 4);
  std::vector<std::uint32_t> anchorNode;
  for (const std::uint32_t t : split_)
    for (int j = 0; j < 4; ++j) anchorNode.push_back(tets_[t][j]);
  std::sort(anchorNode.begin(), anchorNode.end());
  anchorNode.erase(std::unique(anchorNode.begin(), anchorNode.end()), anchorNode.end());
  auto anchor = [&](std::uint32_t node) {
    return slotCount +
           std::uint32_t(std::lower_bound(anchorNode.begin(), anchorNode.end(), node) - anchorNode.begin());
  };
  auto splitIndex = [&](std::uint32_t t) {
    return std::uint32_t(std::lower_bound(split_.begin(), split_.end(), t) - split_.begin());
  };
  auto slot = [&](std::uint32_t si, int l, int corner) {
    return firstSlot[si] + std::uint32_t(4 * l + corner);
  };
  auto localCorner = [&](std::uint32_t t, std::uint32_t node) {
    int j = 0;
    while (tets_[t][j] != node) ++j;
    return j;
  };

  Uf uf(slotCount + anchorNode.size());
  for (std::size_t si = 0; si < split_.size(); ++si) {
    const std::uint32_t t = split_[si];
    for (int j = 0; j < 4; ++j) uf.unite(slot(std::uint32_t(si), label_[t][j], j), anchor(tets_[t][j]));
  }
  for (std::size_t si = 0; si < split_.size(); ++si) {
    const std::uint32_t t = split_[si];
    for (int k = 0; k < 4; ++k) {
      const auto& ft = faceTets_[tetFace_[t][k]];
      const std::uint32_t n = ft[0] == t ? ft[1] : ft[0];
      if (n == kNone) continue;
      std::array<std::uint32_t, 3> node{tets_[t][kFace[k][0]], tets_[t][kFace[k][1]], tets_[t][kFace[k][2]]};
      if (labelCount_[n] == 1) {
        // A whole neighbour: its corners are the original nodes.
        for (int l = 0; l < labelCount_[t]; ++l) {
          bool shares = false;
          for (int i = 0; i < 3; ++i) shares = shares || label_[t][kFace[k][i]] == l;
          if (!shares) continue;
          for (int i = 0; i < 3; ++i) uf.unite(slot(std::uint32_t(si), l, kFace[k][i]), anchor(node[i]));
        }
        continue;
      }
      if (n < t) continue;  // the pair is visited from its lower tetrahedron
      const std::uint32_t sn = splitIndex(n);
      std::array<int, 3> cn{};
      for (int i = 0; i < 3; ++i) cn[i] = localCorner(n, node[i]);
      for (int l = 0; l < labelCount_[t]; ++l)
        for (int m = 0; m < labelCount_[n]; ++m) {
          bool shares = false;
          for (int i = 0; i < 3; ++i)
            shares = shares || (label_[t][kFace[k][i]] == l && label_[n][cn[i]] == m);
          if (!shares) continue;
          for (int i = 0; i < 3; ++i) uf.unite(slot(std::uint32_t(si), l, kFace[k][i]), slot(sn, m, cn[i]));
        }
    }
  }

  // Classes, by their lowest slot (the root). A class with an anchor is its
  // original node; the others are virtual nodes, which keep a previous
  // virtual index where one of their slots had it, else take a new index
  // starting from the state of the node their slots had before (a virtual
  // one where there is: the material on the class's side).
  std::vector<std::uint32_t> nodeOfRoot(slotCount + anchorNode.size(), kNone);
  for (std::size_t a = 0; a < anchorNode.size(); ++a)
    nodeOfRoot[uf.find(slotCount + std::uint32_t(a))] = anchorNode[a];
  std::vector<std::uint32_t> previous(slotCount);
  for (std::uint32_t s = 0; s < slotCount; ++s) previous[s] = elements_[slotElement[s / 4]].nodes[s % 4];
  // Claim previous virtual indices, lowest class first.
  std::vector<std::pair<std::uint32_t, std::uint32_t>> claims;  // (previous virtual node, root)
  for (std::uint32_t s = 0; s < slotCount; ++s) {
    const std::uint32_t r = uf.find(s);
    if (nodeOfRoot[r] == kNone && previous[s] >= n0) claims.push_back({r, previous[s]});
  }
  std::sort(claims.begin(), claims.end());
  std::vector<std::uint8_t> taken(origin_.size() - n0, 0);
  for (const auto& [root, prev] : claims) {
    if (nodeOfRoot[root] != kNone || taken[prev - n0]) continue;
    nodeOfRoot[root] = prev;
    taken[prev - n0] = 1;
  }
  // New virtual nodes: the state source is the highest previous index among
  // the class's slots.
  std::vector<std::uint32_t> source(slotCount + anchorNode.size(), 0);
  for (std::uint32_t s = 0; s < slotCount; ++s) {
    const std::uint32_t r = uf.find(s);
    source[r] = std::max(source[r], previous[s]);
  }
  for (std::uint32_t s = 0; s < slotCount; ++s) {
    const std::uint32_t r = uf.find(s);
    if (nodeOfRoot[r] != kNone) continue;
    const auto id = std::uint32_t(origin_.size());
    origin_.push_back(origin_[source[r]]);
    nodeOfRoot[r] = id;
    update.newNodes.push_back({id, source[r]});
  }
  for (std::uint32_t s = 0; s < slotCount; ++s) {
    CutElement& e = elements_[slotElement[s / 4]];
    const std::uint32_t node = nodeOfRoot[uf.find(s)];
    if (e.nodes[s % 4] != node) {
      e.nodes[s % 4] = node;
      update.changedElements.push_back(slotElement[s / 4]);
    }
  }
}

std::size_t TetCutter::pieces(std::vector<std::uint32_t>& pieceOf) const {
  using namespace tetcut;
  Uf uf(origin_.size());
  for (const CutElement& e : elements_)
    for (int j = 1; j < 4; ++j) uf.unite(e.nodes[0], e.nodes[j]);
  std::vector<std::uint32_t> idOfRoot(origin_.size(), kNone);
  std::uint32_t n = 0;
  pieceOf.resize(elements_.size());
  for (std::size_t i = 0; i < elements_.size(); ++i) {
    const std::uint32_t r = uf.find(elements_[i].nodes[0]);
    if (idOfRoot[r] == kNone) idOfRoot[r] = n++;
    pieceOf[i] = idOfRoot[r];
  }
  return n;
}

CutSurface TetCutter::surface() const {
  using namespace tetcut;
  enum Kind : std::uint32_t { kNode, kEdgePoint, kFacePoint, kCellPoint };
  CutSurface out;
  std::map<std::array<std::uint32_t, 6>, std::uint32_t> index;
  auto vertex = [&](Kind kind, std::uint32_t id, const Tet& nodes, const Weights& w) {
    // The key names the point and the nodes it moves with.
    std::array<std::uint32_t, 6> key{kind, id, kNone, kNone, kNone, kNone};
    CutSurfaceVertex v;
    int n = 0;
    for (int j = 0; j < 4; ++j)
      if (w[j] != 0.0) v.nodes[n] = nodes[j], v.weights[n] = w[j], ++n;
    // Nodes in ascending order (insertion sort of ≤ 4), so two elements
    // naming one point agree.
    for (int j = 1; j < n; ++j)
      for (int i = j; i > 0 && v.nodes[i] < v.nodes[i - 1]; --i) {
        std::swap(v.nodes[i], v.nodes[i - 1]);
        std::swap(v.weights[i], v.weights[i - 1]);
      }
    for (int j = 0; j < n; ++j) key[2 + j] = v.nodes[j];
    const auto [it, fresh] = index.try_emplace(key, std::uint32_t(out.vertices.size()));
    if (fresh) out.vertices.push_back(v);
    return it->second;
  };
  auto corner = [](int j) {
    Weights w{0, 0, 0, 0};
    w[j] = 1.0;
    return w;
  };

  for (std::size_t t = 0; t < tets_.size(); ++t) {
    const Subdivision sub = subdivision(t);
    const auto& ew = sub.edge;
    const auto& fw = sub.face;
    const auto& crossed = sub.crossed;
    const auto& label = label_[t];
    auto copyNodes = [&](int l) -> const Tet& { return elements_[copyOf_[t][l]].nodes; };

    // Boundary faces: whole where nothing crosses them, else fanned from the
    // face point over their outline split at the crossings.
    for (int k = 0; k < 4; ++k) {
      if (faceTets_[tetFace_[t][k]][1] != kNone) continue;
      const int* f = kFace[k];
      const bool anyCrossed =
          crossed[kEdgeOf[f[0]][f[1]]] || crossed[kEdgeOf[f[1]][f[2]]] || crossed[kEdgeOf[f[2]][f[0]]];
      if (!anyCrossed && labelCount_[t] == 1) {
        const Tet& nodes = copyNodes(0);
        out.triangles.push_back({vertex(kNode, nodes[f[0]], nodes, corner(f[0])),
                                 vertex(kNode, nodes[f[1]], nodes, corner(f[1])),
                                 vertex(kNode, nodes[f[2]], nodes, corner(f[2]))});
        continue;
      }
      // The face's outline: corners and the crossings between them. Each
      // outline segment has a corner, whose component it belongs to; the
      // triangle (face point, segment) is that component's copy's.
      std::array<int, 6> walk{};  // ≥ 0: a corner; < 0: −1 − the edge of a crossing
      int n = 0;
      for (int i = 0; i < 3; ++i) {
        const int a = f[i], b = f[(i + 1) % 3], e = kEdgeOf[a][b];
        walk[n++] = a;
        if (crossed[e]) walk[n++] = -1 - e;
      }
      for (int i = 0; i < n; ++i) {
        const int pa = walk[i], pb = walk[(i + 1) % n];
        const int l = label[pa >= 0 ? pa : pb];
        const Tet& nodes = copyNodes(l);
        auto point = [&](int w) {
          return w >= 0 ? vertex(kNode, nodes[w], nodes, corner(w))
                        : vertex(kEdgePoint, tetEdge_[t][-1 - w], nodes, ew[-1 - w]);
        };
        out.triangles.push_back({vertex(kFacePoint, tetFace_[t][k], nodes, fw[k]), point(pa), point(pb)});
      }
    }

    // Cut faces inside a split tetrahedron: for each separating edge and
    // each of its two faces, the triangle (edge point, face point, cell
    // point) on both sides, unless both copies name the same nodes there
    // (a closed crack).
    if (labelCount_[t] < 2) continue;
    const Weights& cw = sub.cell;
    std::array<Vec3, 4> p{x0_[tets_[t][0]], x0_[tets_[t][1]], x0_[tets_[t][2]], x0_[tets_[t][3]]};
    for (int k = 0; k < 6; ++k) {
      const int a = kEdge[k][0], b = kEdge[k][1];
      if (label[a] == label[b]) continue;
      for (int face = 0; face < 4; ++face) {
        if (face == a || face == b) continue;
        const Vec3 ep = pointOf(ew[k], p), fpp = pointOf(fw[face], p), cp = pointOf(cw, p);
        const bool awayFromA = ((fpp - ep).cross(cp - ep)).dot(p[a] - ep) < 0.0;
        std::array<std::uint32_t, 3> side[2];
        for (int s = 0; s < 2; ++s) {
          const Tet& nodes = copyNodes(label[s == 0 ? a : b]);
          side[s] = {vertex(kEdgePoint, tetEdge_[t][k], nodes, ew[k]),
                     vertex(kFacePoint, tetFace_[t][face], nodes, fw[face]),
                     vertex(kCellPoint, std::uint32_t(t), nodes, cw)};
        }
        if (side[0] == side[1]) continue;
        // a's side faces away from a; b's the other way.
        if (awayFromA) {
          out.triangles.push_back({side[0][0], side[0][1], side[0][2]});
          out.triangles.push_back({side[1][0], side[1][2], side[1][1]});
        } else {
          out.triangles.push_back({side[0][0], side[0][2], side[0][1]});
          out.triangles.push_back({side[1][0], side[1][1], side[1][2]});
        }
      }
    }
  }
  return out;
}

}  // namespace dm
