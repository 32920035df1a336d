// dm/collide/kdop.hpp — discrete oriented polytopes (k-DOPs): bounding
// volumes bounded by k/2 pairs of parallel planes with fixed normals, the
// tighter-than-an-AABB, cheaper-than-an-OBB box of Klosowski et al. 1998
// ("Efficient collision detection using bounding volume hierarchies of
// k-DOPs").
//
// A Kdop<K> stores, for each of its K/2 fixed axes a_i, the interval
// [min_i, max_i] of a_i·x over the bounded set. The axes are integer vectors,
// deliberately not normalised (projections are then sums and differences of
// coordinates, exact up to one rounding), in this order:
//   K = 14: x, y, z; (1,1,1), (1,1,−1), (1,−1,1), (1,−1,−1)   (cube corners)
//   K = 18: x, y, z; (1,1,0), (1,0,1), (0,1,1), (1,−1,0), (1,0,−1), (0,1,−1)
//           (cube edges; the same axes and order as FCL's KDOP<18>)
//   K = 26: x, y, z; the 4 corner axes of K = 14; the 6 edge axes of K = 18
// The first three slabs are the AABB. A k-DOP is axis-bound to the frame it
// was built in: to move one, rebuild it from the moved points (rotating the
// slabs does not give a k-DOP). Overlap is the separating-axis test on the
// k/2 fixed axes only, so it is conservative: disjoint k-DOPs prove disjoint
// sets, overlapping ones do not prove contact.
//
// Everything is header-only, allocation-free and thread-safe, O(K) per
// operation (fromPoints O(K·n)).
//
// @code
//   dm::Kdop18 a = dm::Kdop18::fromPoints(triangleA);   // std::span<const dm::Vec3>
//   dm::Kdop18 b = dm::Kdop18::fromPoints(triangleB);
//   if (a.overlaps(b)) narrowPhase();
// @endcode
#pragma once

#include <dm/core/types.hpp>

#include <algorithm>
#include <array>
#include <limits>
#include <span>

namespace dm {

/// k-DOP with K ∈ {14, 18, 26} (see the file comment for the axes).
template <int K>
class Kdop {
  static_assert(K == 14 || K == 18 || K == 26, "Kdop<K>: K must be 14, 18 or 26");

 public:
  /// Number of slabs (axis pairs of planes).
  static constexpr int kSlabs = K / 2;

  /// Axis i (0 ≤ i < kSlabs), integer components, not normalised.
  static Vec3 axis(int i) noexcept {
    const auto& a = axisTable()[static_cast<std::size_t>(i)];
    return Vec3(a[0], a[1], a[2]);
  }

  /// Projection a_i·p of point p on every axis (m × |a_i|).
  static std::array<double, kSlabs> project(const Vec3& p) noexcept {
    std::array<double, kSlabs> out{};
    const auto& t = axisTable();
    for (int i = 0; i < kSlabs; ++i) {
      const auto& a = t[static_cast<std::size_t>(i)];
      out[static_cast<std::size_t>(i)] = a[0] * p.x() + a[1] * p.y() + a[2] * p.z();
    }
    return out;
  }

  /// The empty k-DOP (min = +∞, max = −∞): merging it changes nothing,
  /// nothing overlaps it, it contains nothing.
  Kdop() noexcept {
    min_.fill(std::numeric_limits<double>::infinity());
    max_.fill(-std::numeric_limits<double>::infinity());
  }

  /// Tightest k-DOP of `points` (m): per axis the exact minimum and maximum
  /// of the projections. Empty for no points. O(K·n).
  /// @code
  ///   const std::array<dm::Vec3, 3> tri = {a, b, c};
  ///   dm::Kdop26 bv = dm::Kdop26::fromPoints(tri);
  /// @endcode
  static Kdop fromPoints(std::span<const Vec3> points) noexcept {
    Kdop k;
    for (const Vec3& p : points) k.extend(p);
    return k;
  }

  /// Grows the slabs to include point p. O(K).
  void extend(const Vec3& p) noexcept {
    const auto q = project(p);
    for (std::size_t i = 0; i < kSlabs; ++i) {
      min_[i] = std::min(min_[i], q[i]);
      max_[i] = std::max(max_[i], q[i]);
    }
  }

  /// Smallest k-DOP holding this one and `other` (slab-wise hull): equal to
  /// fromPoints() of the union of both point sets. O(K).
  void merge(const Kdop& other) noexcept {
    for (std::size_t i = 0; i < kSlabs; ++i) {
      min_[i] = std::min(min_[i], other.min_[i]);
      max_[i] = std::max(max_[i], other.max_[i]);
    }
  }
  /// merge() as a value.
  friend Kdop merged(Kdop a, const Kdop& b) noexcept {
    a.merge(b);
    return a;
  }

  /// True when every slab interval of the two k-DOPs intersects (closed
  /// intervals: touching counts). False proves the bounded sets disjoint.
  /// O(K), early exit on the first separating slab.
  bool overlaps(const Kdop& other) const noexcept {
    for (std::size_t i = 0; i < kSlabs; ++i)
      if (min_[i] > other.max_[i] || other.min_[i] > max_[i]) return false;
    return true;
  }

  /// True when point p lies in every slab (closed). O(K).
  bool contains(const Vec3& p) const noexcept {
    const auto q = project(p);
    for (std::size_t i = 0; i < kSlabs; ++i)
      if (q[i] < min_[i] || q[i] > max_[i]) return false;
    return true;
  }

  /// True when `other` lies inside this k-DOP (slab-wise inclusion, which is
  /// exact for two k-DOPs of the same K). An empty `other` is contained. O(K).
  bool contains(const Kdop& other) const noexcept {
    if (other.isEmpty()) return true;
    for (std::size_t i = 0; i < kSlabs; ++i)
      if (other.min_[i] < min_[i] || other.max_[i] > max_[i]) return false;
    return true;
  }

  /// True when no point was added.
  bool isEmpty() const noexcept { return min_[0] > max_[0]; }

  /// Slab i's interval of a_i·x (m × |a_i|).
  double min(int i) const noexcept { return min_[static_cast<std::size_t>(i)]; }
  double max(int i) const noexcept { return max_[static_cast<std::size_t>(i)]; }

  /// The axis-aligned box of the first three slabs (m). Empty box when empty.
  Aabb aabb() const noexcept {
    if (isEmpty()) return Aabb();
    return Aabb(Vec3(min_[0], min_[1], min_[2]), Vec3(max_[0], max_[1], max_[2]));
  }

 private:
  using AxisTable = std::array<std::array<double, 3>, kSlabs>;
  static const AxisTable& axisTable() noexcept {
    static constexpr std::array<std::array<double, 3>, 13> kAll = {{
        {1, 0, 0},
        {0, 1, 0},
        {0, 0, 1},  // faces
        {1, 1, 1},
        {1, 1, -1},
        {1, -1, 1},
        {1, -1, -1},  // corners
        {1, 1, 0},
        {1, 0, 1},
        {0, 1, 1},
        {1, -1, 0},
        {1, 0, -1},
        {0, 1, -1}  // edges
    }};
    static constexpr AxisTable kTable = [] {
      AxisTable t{};
      std::size_t n = 0;
      for (std::size_t i = 0; i < 13; ++i) {
        const bool corner = i >= 3 && i < 7, edge = i >= 7;
        if ((corner && K == 18) || (edge && K == 14)) continue;
        t[n++] = kAll[i];
      }
      return t;
    }();
    return kTable;
  }

  std::array<double, kSlabs> min_;
  std::array<double, kSlabs> max_;
};

using Kdop14 = Kdop<14>;  ///< 7 slabs: AABB + cube corners
using Kdop18 = Kdop<18>;  ///< 9 slabs: AABB + cube edges (FCL's KDOP<18> axes)
using Kdop26 = Kdop<26>;  ///< 13 slabs: AABB + corners + edges

}  // namespace dm
