// Binned-SAH BVH over mesh triangles; see dm/collide/bvh.hpp.
#include <dm/collide/bvh.hpp>
#include <dm/core/tasks.hpp>
#include <dm/math/float_bounds.hpp>
#include <dm/math/mesh_topology.hpp>

#include <Eigen/Eigenvalues>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include "lanes.hpp"

namespace dm {

namespace {

void setBox(BvhNode& n, const Aabb& b) noexcept {
  for (int i = 0; i < 3; ++i) {
    n.lo[i] = floatDown(b.min()[i]);
    n.hi[i] = floatUp(b.max()[i]);
  }
}

// Depth below which SAH is used; deeper nodes split at the object median so
// that the depth stays below MeshBvh::kMaxDepth (2^30 triangles need 30 more).
constexpr int kSahDepth = 64;
static_assert(kSahDepth + 31 < MeshBvh::kMaxDepth);

// The builder's boxes are the triangles' exact bounds rounded outward to
// float, so the union over a node is exactly setBox() of its exact box.
using lanes::F4;

// Half the surface area of the box [lo, hi] (lanes x, y, z).
float halfArea(F4 lo, F4 hi) noexcept {
  float d[4];
  (hi - lo).store(d);
  return d[0] * d[1] + d[1] * d[2] + d[2] * d[0];
}

// A node's bounds: its triangles' box and their centroids' box.
struct NodeBounds {
  F4 lo, hi, clo, chi;
};

}  // namespace

// Temporary binary tree built in parallel, then flattened depth-first into
// the adjacent-children layout.
struct BvhBuilder {
  struct TempNode {
    F4 lo, hi;
    std::uint32_t left = 0, right = 0;  // temp indices; both 0 for a leaf
    std::uint32_t begin = 0, count = 0;
  };
  const std::vector<F4>& lows;  // per triangle: box, rounded outward
  const std::vector<F4>& highs;
  const std::vector<F4>& centroids;
  std::vector<std::uint32_t>& index;
  std::vector<TempNode>& temp;
  std::atomic<std::uint32_t> next{1};
  int binLimit = 16;  // SAH bins per axis of a large node
  int maxLeaf = 4;
  std::size_t parallelThreshold = 4096;

  std::uint32_t allocate() { return next.fetch_add(1, std::memory_order_relaxed); }

  NodeBounds boundsOf(std::uint32_t begin, std::uint32_t end) const noexcept {
    constexpr float kInf = std::numeric_limits<float>::infinity();
    NodeBounds b{F4::all(kInf), F4::all(-kInf), F4::all(kInf), F4::all(-kInf)};
    for (std::uint32_t i = begin; i < end; ++i) {
      const std::uint32_t t = index[i];
      b.lo = min(b.lo, lows[t]), b.hi = max(b.hi, highs[t]);
      b.clo = min(b.clo, centroids[t]), b.chi = max(b.chi, centroids[t]);
    }
    return b;
  }

  // Builds the subtree of `node` over index[begin, end) with bounds `nb`.
  void build(std::uint32_t node, std::uint32_t begin, std::uint32_t end, int depth, const NodeBounds& nb) {
    TempNode& n = temp[node];
    n.begin = begin;
    n.count = end - begin;
    n.lo = nb.lo, n.hi = nb.hi;
    const std::uint32_t count = end - begin;
    if (count == 1) return;

    std::uint32_t mid = begin;
    bool split = false;
    NodeBounds left{}, right{};
    if (depth < kSahDepth) {
      // Binned SAH over the three axes, one pass over the triangles. Bins
      // also gather their centroids' box, so the children's bounds come from
      // the bins and need no pass of their own.
      constexpr int kMaxBins = 64;
      constexpr float kInf = std::numeric_limits<float>::infinity();
      struct Bin {
        NodeBounds b;
        std::uint32_t count;
      };
      // A small node gets as many bins as triangles: setting up and sweeping
      // the bins is most of a small node's cost, and more bins than
      // triangles add few distinct candidates.
      const int bins = std::min(binLimit, std::max(4, static_cast<int>(count)));
      float cext[4];
      (nb.chi - nb.clo).store(cext);
      float scale[4] = {0, 0, 0, 0};
      for (int axis = 0; axis < 3; ++axis) scale[axis] = cext[axis] > 0 ? float(bins) / cext[axis] : 0.0f;
      const F4 binScale = F4::of(scale[0], scale[1], scale[2]);
      // Bin of centroid c along every axis (the partition below recomputes
      // it the same way, so both agree to the bit).
      auto binsOf = [&](std::uint32_t t, std::int32_t* out) {
        ((centroids[t] - nb.clo) * binScale).truncate(out);
        for (int axis = 0; axis < 3; ++axis) out[axis] = std::min(bins - 1, out[axis]);
      };
      // Only the first `bins` of each axis are initialised and read.
      std::array<std::array<Bin, kMaxBins>, 3> bin;  // NOLINT
      const NodeBounds empty{F4::all(kInf), F4::all(-kInf), F4::all(kInf), F4::all(-kInf)};
      for (int axis = 0; axis < 3; ++axis)
        for (int b = 0; b < bins; ++b) bin[axis][b] = Bin{empty, 0};
      for (std::uint32_t i = begin; i < end; ++i) {
        const std::uint32_t t = index[i];
        std::int32_t at[4];
        binsOf(t, at);
        const F4 tlo = lows[t], thi = highs[t], c = centroids[t];
        for (int axis = 0; axis < 3; ++axis) {
          Bin& into = bin[axis][at[axis]];
          into.count++;
          into.b.lo = min(into.b.lo, tlo), into.b.hi = max(into.b.hi, thi);
          into.b.clo = min(into.b.clo, c), into.b.chi = max(into.b.chi, c);
        }
      }
      double bestCost = std::numeric_limits<double>::infinity();
      int bestAxis = -1, bestBin = 0;
      for (int axis = 0; axis < 3; ++axis) {
        if (!(cext[axis] > 0)) continue;
        const std::array<Bin, kMaxBins>& binA = bin[axis];
        // Right-to-left sweep of areas, then left-to-right evaluation (empty
        // prefixes and suffixes are skipped, so their infinite boxes never
        // reach the area).
        std::array<double, kMaxBins> rightCost;
        F4 lo = empty.lo, hi = empty.hi;
        std::uint32_t accCount = 0;
        for (int b = bins - 1; b > 0; --b) {
          lo = min(lo, binA[b].b.lo), hi = max(hi, binA[b].b.hi);
          accCount += binA[b].count;
          rightCost[b] = accCount ? double(halfArea(lo, hi)) * accCount : 0.0;
        }
        lo = empty.lo, hi = empty.hi;
        accCount = 0;
        for (int b = 0; b < bins - 1; ++b) {
          lo = min(lo, binA[b].b.lo), hi = max(hi, binA[b].b.hi);
          accCount += binA[b].count;
          if (accCount == 0 || accCount == count) continue;
          const double cost = double(halfArea(lo, hi)) * accCount + rightCost[b + 1];
          if (cost < bestCost) {
            bestCost = cost;
            bestAxis = axis;
            bestBin = b;
          }
        }
      }
      // Cost model: traversal step 1, triangle test 1, both relative to the
      // parent's area.
      const double parentArea = halfArea(nb.lo, nb.hi);
      const double splitCost = 1.0 + (parentArea > 0 ? bestCost / parentArea : 0.0);
      if (bestAxis >= 0 && count <= static_cast<std::uint32_t>(maxLeaf) && splitCost >= count) return;
      if (bestAxis >= 0) {
        auto* it = std::partition(index.data() + begin, index.data() + end, [&](std::uint32_t t) {
          std::int32_t at[4];
          binsOf(t, at);
          return at[bestAxis] <= bestBin;
        });
        mid = static_cast<std::uint32_t>(it - index.data());
        split = mid > begin && mid < end;
        if (split) {
          left = right = empty;
          auto merge = [](NodeBounds& into, const NodeBounds& b) {
            into.lo = min(into.lo, b.lo), into.hi = max(into.hi, b.hi);
            into.clo = min(into.clo, b.clo), into.chi = max(into.chi, b.chi);
          };
          for (int b = 0; b < bins; ++b) merge(b <= bestBin ? left : right, bin[bestAxis][b].b);
        }
      }
    }
    if (!split) {
      if (count <= static_cast<std::uint32_t>(maxLeaf)) return;
      // All centroids equal, or too deep: object median on the widest axis.
      float cext[4];
      (nb.chi - nb.clo).store(cext);
      const int axis = cext[0] >= cext[1] ? (cext[0] >= cext[2] ? 0 : 2) : (cext[1] >= cext[2] ? 1 : 2);
      mid = begin + count / 2;
      std::nth_element(index.data() + begin, index.data() + mid, index.data() + end,
                       [&](std::uint32_t a, std::uint32_t b) { return centroids[a][axis] < centroids[b][axis]; });
      left = boundsOf(begin, mid);
      right = boundsOf(mid, end);
    }
    const std::uint32_t l = allocate(), r = allocate();
    n.left = l;
    n.right = r;
    if (count > parallelThreshold) {
      tbb::parallel_invoke([&] { build(l, begin, mid, depth + 1, left); },
                           [&] { build(r, mid, end, depth + 1, right); });
    } else {
      build(l, begin, mid, depth + 1, left);
      build(r, mid, end, depth + 1, right);
    }
  }
};

Result<MeshBvh> MeshBvh::build(const Mesh& mesh, const BvhBuildOptions& options) {
  const std::string where =
      mesh.name.empty() ? std::string("MeshBvh::build") : "MeshBvh::build: mesh '" + mesh.name + "'";
  if (mesh.triangles.empty())
    return fail(ErrorCode::InvalidArgument, "the mesh has no triangles", where,
                "build a BVH from a non-empty mesh");
  if (mesh.triangles.size() > (std::size_t(1) << 30))
    return fail(ErrorCode::InvalidArgument,
                "the mesh has " + std::to_string(mesh.triangles.size()) + " triangles", where,
                "split meshes above 2^30 triangles into parts");
  const std::size_t nv = mesh.positions.size();
  for (std::size_t v = 0; v < nv; ++v)
    if (!mesh.positions[v].allFinite())
      return fail(ErrorCode::InvalidArgument, "position " + std::to_string(v) + " is not finite", where,
                  "remove NaN/Inf vertices before building");
  const std::size_t n = mesh.triangles.size();
  for (std::size_t t = 0; t < n; ++t)
    for (std::uint32_t v : mesh.triangles[t])
      if (v >= nv)
        return fail(ErrorCode::InvalidArgument,
                    "triangle " + std::to_string(t) + " uses vertex " + std::to_string(v) + " of " +
                        std::to_string(nv),
                    where, "check Mesh::validate()");

  // Triangle boxes rounded outward to float, and their centroids; the exact
  // bounds of the whole mesh on the side.
  std::vector<F4> lows(n), highs(n), centroids(n);
  Aabb all;
  for (std::size_t t = 0; t < n; ++t) {
    const Triangle& tri = mesh.triangles[t];
    const Vec3 &p0 = mesh.positions[tri[0]], &p1 = mesh.positions[tri[1]], &p2 = mesh.positions[tri[2]];
    const Vec3 lo = p0.cwiseMin(p1).cwiseMin(p2), hi = p0.cwiseMax(p1).cwiseMax(p2);
    all.extend(lo), all.extend(hi);
    lows[t] = F4::of(floatDown(lo.x()), floatDown(lo.y()), floatDown(lo.z()));
    highs[t] = F4::of(floatUp(hi.x()), floatUp(hi.y()), floatUp(hi.z()));
    const Vec3 c = 0.5 * (lo + hi);
    centroids[t] = F4::of(float(c.x()), float(c.y()), float(c.z()));
  }
  std::vector<std::uint32_t> index(n);
  for (std::size_t t = 0; t < n; ++t) index[t] = static_cast<std::uint32_t>(t);
  std::vector<BvhBuilder::TempNode> temp(2 * n);
  BvhBuilder builder{lows, highs, centroids, index, temp};
  builder.binLimit = std::clamp(options.bins, 4, 64);
  builder.maxLeaf = std::clamp(options.maxLeafSize, 1, 8);
  builder.parallelThreshold = std::max<std::size_t>(options.parallelThreshold, 64);
  builder.build(0, 0, static_cast<std::uint32_t>(n), 0, builder.boundsOf(0, static_cast<std::uint32_t>(n)));
  const std::size_t tempCount = builder.next.load();

  MeshBvh bvh;
  bvh.vertexCount_ = nv;
  // Flatten: slot 0 root, slot 1 padding, children pairs from slot 2 on.
  bvh.nodeCount_ = tempCount + 1;
  bvh.blocks_.resize((bvh.nodeCount_ + 1) / 2);
  BvhNode* nodes = bvh.nodeData();
  nodes[1] = BvhNode{{0, 0, 0}, 0, {0, 0, 0}, 0};
  struct Item {
    std::uint32_t tempIndex, slot;
    int depth;
  };
  std::vector<Item> stack;
  stack.push_back({0, 0, 0});
  std::uint32_t nextSlot = 2;
  while (!stack.empty()) {
    const Item it = stack.back();
    stack.pop_back();
    const BvhBuilder::TempNode& tn = temp[it.tempIndex];
    BvhNode& out = nodes[it.slot];
    float lo[4], hi[4];
    tn.lo.store(lo), tn.hi.store(hi);
    std::copy(lo, lo + 3, out.lo), std::copy(hi, hi + 3, out.hi);
    bvh.depth_ = std::max(bvh.depth_, it.depth);
    if (tn.left == 0) {
      out.first = tn.begin;
      out.count = tn.count;
    } else {
      out.first = nextSlot;
      out.count = 0;
      nextSlot += 2;
      stack.push_back({tn.right, out.first + 1, it.depth + 1});
      stack.push_back({tn.left, out.first, it.depth + 1});
    }
  }
  DM_ASSERT(nextSlot == bvh.nodeCount_, "flattened node count");
  DM_DEMAND(bvh.depth_ <= kMaxDepth, "BVH depth bound violated");

  bvh.order_ = std::move(index);
  bvh.tris_.resize(n);
  bvh.corners_.resize(3 * n);
  for (std::size_t k = 0; k < n; ++k) {
    const Triangle& tri = mesh.triangles[bvh.order_[k]];
    bvh.tris_[k] = tri;
    for (int c = 0; c < 3; ++c) bvh.corners_[3 * k + c] = mesh.positions[tri[c]];
  }
  bvh.bounds_ = all;
  bvh.faceNormals_.resize(n);
  bvh.computeFaceNormals();

  // Pseudonormals for closed, oriented manifolds: neighbours across edges.
  const MeshTopology topo = analyzeTopology(mesh);
  bvh.closed_ =
      topo.isClosed && topo.isManifold && topo.isOrientedConsistently && topo.degenerateTriangles == 0;
  if (bvh.closed_) {
    // Half-edges bucketed by their start vertex (counting sort, O(n)); the
    // twin of u->v is the one v->u in v's bucket, unique in a closed,
    // oriented manifold. (A sort of all 3n half-edges took ~8 % of the build.)
    std::vector<std::uint32_t> first(nv + 1, 0), out(3 * n);
    for (std::uint32_t k = 0; k < n; ++k)
      for (int e = 0; e < 3; ++e) ++first[bvh.tris_[k][e] + 1];
    for (std::size_t v = 0; v < nv; ++v) first[v + 1] += first[v];
    {
      std::vector<std::uint32_t> fill(first.begin(), first.end() - 1);
      for (std::uint32_t k = 0; k < n; ++k)
        for (std::uint32_t e = 0; e < 3; ++e) out[fill[bvh.tris_[k][e]]++] = 3 * k + e;
    }
    bvh.neighbours_.assign(3 * n, 0);
    for (std::uint32_t k = 0; k < n; ++k)
      for (int e = 0; e < 3; ++e) {
        const std::uint32_t u = bvh.tris_[k][e], v = bvh.tris_[k][(e + 1) % 3];
        [[maybe_unused]] bool found = false;
        for (std::uint32_t s = first[v]; s < first[v + 1]; ++s) {
          const std::uint32_t h = out[s];
          if (bvh.tris_[h / 3][(h % 3 + 1) % 3] == u) {
            bvh.neighbours_[3 * k + e] = h / 3;
            found = true;
            break;
          }
        }
        DM_ASSERT(found, "edge pairing of a closed mesh");
      }
    bvh.edgeNormals_.resize(3 * n);
    bvh.vertexNormals_.resize(nv);
    bvh.computeNormals();
  }
  bvh.computeObbs();
  return bvh;
}

namespace {
// Oriented box extents around leaf-order corners [3·first, 3·end) along
// o.axes, rounded outward by far more than the rounding of the projections
// and of the centre's reconstruction (a few ulps of the coordinates).
void fitObb(BvhObb& o, const std::vector<Vec3>& corners, std::uint32_t first, std::uint32_t end) noexcept {
  constexpr double kBig = std::numeric_limits<double>::infinity();
  const Mat3 at = o.axes.transpose();
  Vec3 lo = Vec3::Constant(kBig), hi = Vec3::Constant(-kBig);
  for (std::size_t k = 3 * std::size_t(first); k < 3 * std::size_t(end); ++k) {
    const Vec3 q = at * corners[k];
    lo = lo.cwiseMin(q), hi = hi.cwiseMax(q);
  }
  const double slack = 1e-13 * std::max(lo.cwiseAbs().maxCoeff(), hi.cwiseAbs().maxCoeff());
  o.half = 0.5 * (hi - lo) + Vec3::Constant(slack);
  o.center = o.axes * (0.5 * (lo + hi));
}
}  // namespace

void MeshBvh::computeObbs() {
  const std::size_t count = nodeCount_;
  obbs_.assign(count, BvhObb{Mat3::Identity(), Vec3::Zero(), Vec3::Zero()});
  nodeSpan_.assign(2 * count, 0);
  // Corner moments (about the bounds' centre, against cancellation), summed
  // bottom-up, give every node's covariance in O(n).
  struct Moments {
    Vec3 sum;
    Mat3 outer;
    double count;
  };
  std::vector<Moments> moments(count);
  const Vec3 origin = bounds_.center();
  const BvhNode* nodes = nodeData();
  for (std::size_t i = count; i-- > 0;) {
    if (i == 1) continue;
    const BvhNode& nd = nodes[i];
    Moments& m = moments[i];
    if (nd.isLeaf()) {
      m.sum.setZero();
      m.outer.setZero();
      m.count = 3.0 * nd.count;
      for (std::uint32_t k = nd.first; k < nd.first + nd.count; ++k)
        for (int c = 0; c < 3; ++c) {
          const Vec3 p = corners_[3 * std::size_t(k) + c] - origin;
          m.sum += p;
          m.outer += p * p.transpose();
        }
      nodeSpan_[2 * i] = nd.first;
      nodeSpan_[2 * i + 1] = nd.first + nd.count;
    } else {
      const Moments& l = moments[nd.first];
      const Moments& r = moments[nd.first + 1];
      m.sum = l.sum + r.sum;
      m.outer = l.outer + r.outer;
      m.count = l.count + r.count;
      // Subtrees are contiguous in leaf order; the hull of the two spans is
      // a superset otherwise, which only loosens the box.
      nodeSpan_[2 * i] = std::min(nodeSpan_[2 * nd.first], nodeSpan_[2 * (nd.first + 1)]);
      nodeSpan_[2 * i + 1] = std::max(nodeSpan_[2 * nd.first + 1], nodeSpan_[2 * (nd.first + 1) + 1]);
    }
  }
  // Axes (principal directions of the corners) and exact extents, node by
  // node in parallel: O(n log n) work over the levels. A small tree runs on
  // the calling thread (task start-up would cost more than it saves).
  auto fit = [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      if (i == 1) continue;
      const Moments& m = moments[i];
      const Vec3 mean = m.sum / m.count;
      const Mat3 cov = m.outer / m.count - mean * mean.transpose();
      Eigen::SelfAdjointEigenSolver<Mat3> solver;
      solver.computeDirect(cov);
      Vec3 a0 = solver.eigenvectors().col(2), a1 = solver.eigenvectors().col(1);
      // Exactly orthonormal (to rounding) whatever the solver returned.
      Mat3 axes = Mat3::Identity();
      if (a0.allFinite() && a1.allFinite() && a0.norm() > 0.5) {
        a0.normalize();
        a1 -= a1.dot(a0) * a0;
        if (a1.norm() > 1e-6) {
          a1.normalize();
          axes.col(0) = a0;
          axes.col(1) = a1;
          axes.col(2) = a0.cross(a1).normalized();
        }
      }
      obbs_[i].axes = axes;
      fitObb(obbs_[i], corners_, nodeSpan_[2 * i], nodeSpan_[2 * i + 1]);
    }
  };
  if (count < 4096)
    fit(0, count);
  else
    parallelFor(0, count, 256, fit);
}

void MeshBvh::computeObbExtents() noexcept {
  for (std::size_t i = 0; i < nodeCount_; ++i)
    if (i != 1) fitObb(obbs_[i], corners_, nodeSpan_[2 * i], nodeSpan_[2 * i + 1]);
}

void MeshBvh::computeFaceNormals() noexcept {
  const std::size_t n = tris_.size();
  for (std::size_t k = 0; k < n; ++k) {
    const Vec3* c = &corners_[3 * k];
    const Vec3 nrm = (c[1] - c[0]).cross(c[2] - c[0]);
    const double len = nrm.norm();
    faceNormals_[k] = len > 0 ? Vec3(nrm / len) : Vec3::Zero();
  }
}

// Edge and vertex pseudonormals of a closed mesh, from the face normals.
void MeshBvh::computeNormals() noexcept {
  const std::size_t n = tris_.size();
  for (Vec3& v : vertexNormals_) v.setZero();
  for (std::size_t k = 0; k < n; ++k) {
    const Vec3* c = &corners_[3 * k];
    // Interior angles weight the vertex pseudonormals: two by atan2 (|u × w|
    // is twice the area at every corner), the third as π minus them.
    const double twiceArea = (c[1] - c[0]).cross(c[2] - c[0]).norm();
    double angle[3];
    for (int e = 0; e < 2; ++e)
      angle[e] = std::atan2(twiceArea, (c[(e + 1) % 3] - c[e]).dot(c[(e + 2) % 3] - c[e]));
    angle[2] = std::max(0.0, std::numbers::pi - angle[0] - angle[1]);
    for (int e = 0; e < 3; ++e) {
      const Vec3 s = faceNormals_[k] + faceNormals_[neighbours_[3 * k + e]];
      const double len = s.norm();
      edgeNormals_[3 * k + e] = len > 0 ? Vec3(s / len) : faceNormals_[k];
      vertexNormals_[tris_[k][e]] += angle[e] * faceNormals_[k];
    }
  }
  for (Vec3& v : vertexNormals_) {
    const double len = v.norm();
    if (len > 0) v /= len;
  }
}

void MeshBvh::computeBoxes() noexcept {
  BvhNode* nodes = nodeData();
  for (std::size_t i = nodeCount_; i-- > 0;) {
    if (i == 1) continue;
    BvhNode& nd = nodes[i];
    if (nd.isLeaf()) {
      Aabb b;
      for (std::uint32_t k = nd.first; k < nd.first + nd.count; ++k)
        for (int c = 0; c < 3; ++c) b.extend(corners_[3 * std::size_t(k) + c]);
      setBox(nd, b);
      if (i == 0) bounds_ = b;
    } else {
      const BvhNode& l = nodes[nd.first];
      const BvhNode& r = nodes[nd.first + 1];
      for (int a = 0; a < 3; ++a) {
        nd.lo[a] = std::min(l.lo[a], r.lo[a]);
        nd.hi[a] = std::max(l.hi[a], r.hi[a]);
      }
    }
  }
}

Status MeshBvh::refit(std::span<const Vec3> positions) {
  if (positions.size() != vertexCount_)
    return fail(ErrorCode::InvalidArgument,
                "refit got " + std::to_string(positions.size()) + " positions for a mesh of " +
                    std::to_string(vertexCount_) + " vertices",
                "MeshBvh::refit", "pass the deformed positions of the mesh the BVH was built from");
  for (std::size_t v = 0; v < positions.size(); ++v)
    if (!positions[v].allFinite())
      return fail(ErrorCode::InvalidArgument, "position " + std::to_string(v) + " is not finite",
                  "MeshBvh::refit", "pass finite positions");
  const std::size_t n = tris_.size();
  Aabb all;
  for (std::size_t k = 0; k < n; ++k)
    for (int c = 0; c < 3; ++c) {
      corners_[3 * k + c] = positions[tris_[k][c]];
      all.extend(corners_[3 * k + c]);
    }
  computeBoxes();
  bounds_ = all;
  computeObbExtents();
  computeFaceNormals();
  if (closed_) computeNormals();
  return ok();
}

}  // namespace dm
