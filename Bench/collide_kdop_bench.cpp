// Bounding-volume tightness and overlap-test cost per triangle pair: our
// AABB (dm::Aabb) and k-DOPs (dm::Kdop14/18/26) against FCL's AABB, OBB and
// KDOP<18> (same 9 axes as dm::Kdop18). Input: a torus mesh and a copy at
// random poses; every triangle pair whose centroids lie within one longest
// edge of each other is a candidate (the hard pairs a BVH descent reaches).
// All volumes are fitted to the same vertices in the first torus's frame.
// Printed per bounding volume: false-positive rate (the fraction of non-intersecting
// triangle pairs, by exact dm::trianglesIntersect, whose volumes overlap),
// missed contacts (must be 0), and thread-CPU ns per overlap test (best of 7
// rounds of ≥ 30 ms) with the ratio ours / FCL for the matching volume.
//
//   ninja -C build-cvx2 collide_kdop_bench && build-cvx2/Bench/collide_kdop_bench
#include <dm/collide/kdop.hpp>
#include <dm/collide/triangle.hpp>
#include <dm/math/primitives.hpp>

#include <fcl/fcl.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <ctime>
#include <random>
#include <vector>

namespace {

using dm::Isometry3;
using dm::Vec3;

struct Pair {
  std::uint32_t a, b;  // triangle of the first torus, triangle of the moved copy
};

double threadSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

volatile std::size_t gSink = 0;

// Nanoseconds per overlap(bvA[a], bvB[b]) over the pair list, and the set of
// pairs reported overlapping.
template <class BV, class Overlap>
double nsPerTest(const std::vector<BV>& bvA, const std::vector<BV>& bvB, const std::vector<Pair>& pairs,
                 Overlap overlap, std::vector<char>& reported) {
  reported.assign(pairs.size(), 0);
  for (std::size_t i = 0; i < pairs.size(); ++i) reported[i] = overlap(bvA[pairs[i].a], bvB[pairs[i].b]);
  double best = 1e30;
  for (int round = 0; round < 7; ++round) {
    std::size_t calls = 0, hits = 0;
    const double start = threadSeconds();
    double elapsed = 0;
    do {
      for (const Pair& p : pairs) hits += overlap(bvA[p.a], bvB[p.b]) ? 1u : 0u;
      calls += pairs.size();
      elapsed = threadSeconds() - start;
    } while (elapsed < 0.03);
    gSink = gSink + hits;
    best = std::min(best, elapsed / static_cast<double>(calls));
  }
  return 1e9 * best;
}

struct Row {
  const char* name;
  double ns;
  double falsePositive;
  int missed;
};

Row evaluate(const char* name, double ns, const std::vector<char>& reported, const std::vector<char>& truth) {
  int fp = 0, negatives = 0, missed = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    if (truth[i]) {
      missed += !reported[i];
    } else {
      ++negatives;
      fp += reported[i];
    }
  }
  return {name, ns, negatives ? static_cast<double>(fp) / negatives : 0.0, missed};
}

template <class K>
std::vector<K> kdops(const std::vector<std::array<Vec3, 3>>& tris) {
  std::vector<K> out;
  out.reserve(tris.size());
  for (const auto& t : tris) out.push_back(K::fromPoints(t));
  return out;
}

template <class BV>
std::vector<BV> fclVolumes(const std::vector<std::array<Vec3, 3>>& tris) {
  std::vector<BV> out(tris.size());
  for (std::size_t i = 0; i < tris.size(); ++i) {
    fcl::Vector3d ps[3] = {tris[i][0], tris[i][1], tris[i][2]};
    fcl::fit(ps, 3, out[i]);
  }
  return out;
}

}  // namespace

int main() {
  const dm::Mesh torus = dm::makeTorus(0.05, 0.02, 48, 24);
  double longest = 0;
  for (const auto& t : torus.triangles)
    for (int e = 0; e < 3; ++e)
      longest = std::max(longest, (torus.positions[t[e]] - torus.positions[t[(e + 1) % 3]]).norm());
  const std::size_t n = torus.triangles.size();
  auto triangle = [&](const dm::Triangle& t, const Isometry3& pose) {
    return std::array<Vec3, 3>{pose * torus.positions[t[0]], pose * torus.positions[t[1]],
                               pose * torus.positions[t[2]]};
  };
  std::vector<std::array<Vec3, 3>> trisA;
  for (const auto& t : torus.triangles) trisA.push_back(triangle(t, Isometry3::Identity()));

  // Moved copies: every pose contributes its candidate pairs; the copy's
  // triangles are stored per pose, indexed pose·n + triangle.
  std::mt19937_64 rng(1);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<std::array<Vec3, 3>> trisB;
  std::vector<Pair> pairs;
  const double reach2 = longest * longest;
  for (int pose = 0; pose < 6; ++pose) {
    Isometry3 p = Isometry3::Identity();
    p.linear() = dm::Quat(Eigen::Vector4d(g(rng), g(rng), g(rng), g(rng)).normalized()).toRotationMatrix();
    p.translation() = Vec3(g(rng), g(rng), g(rng)).normalized() * 0.04;
    const auto base = static_cast<std::uint32_t>(trisB.size());
    for (const auto& t : torus.triangles) trisB.push_back(triangle(t, p));
    for (std::uint32_t i = 0; i < n; ++i) {
      const Vec3 ca = (trisA[i][0] + trisA[i][1] + trisA[i][2]) / 3;
      for (std::uint32_t j = 0; j < n; ++j) {
        const auto& tb = trisB[base + j];
        if ((ca - (tb[0] + tb[1] + tb[2]) / 3).squaredNorm() < reach2) pairs.push_back({i, base + j});
      }
    }
  }
  std::vector<char> truth(pairs.size());
  int contacts = 0;
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    const auto& a = trisA[pairs[i].a];
    const auto& b = trisB[pairs[i].b];
    truth[i] = dm::trianglesIntersect(a[0], a[1], a[2], b[0], b[1], b[2]);
    contacts += truth[i];
  }
  std::printf("torus %zu triangles, 6 poses, %zu candidate pairs, %d intersecting\n\n", n, pairs.size(),
              contacts);

  std::vector<char> reported;
  std::vector<Row> rows;
  auto aabbs = [](const std::vector<std::array<Vec3, 3>>& tris) {
    std::vector<dm::Aabb> out;
    for (const auto& t : tris)
      out.push_back(dm::Aabb(t[0].cwiseMin(t[1]).cwiseMin(t[2]), t[0].cwiseMax(t[1]).cwiseMax(t[2])));
    return out;
  };
  {
    const auto a = aabbs(trisA), b = aabbs(trisB);
    const double ns = nsPerTest(
        a, b, pairs, [](const dm::Aabb& x, const dm::Aabb& y) { return x.intersects(y); }, reported);
    rows.push_back(evaluate("dm::Aabb", ns, reported, truth));
  }
  {
    const auto a = fclVolumes<fcl::AABBd>(trisA), b = fclVolumes<fcl::AABBd>(trisB);
    const double ns = nsPerTest(
        a, b, pairs, [](const fcl::AABBd& x, const fcl::AABBd& y) { return x.overlap(y); }, reported);
    rows.push_back(evaluate("fcl::AABB", ns, reported, truth));
  }
  {
    const auto a = fclVolumes<fcl::OBBd>(trisA), b = fclVolumes<fcl::OBBd>(trisB);
    const double ns = nsPerTest(
        a, b, pairs, [](const fcl::OBBd& x, const fcl::OBBd& y) { return x.overlap(y); }, reported);
    rows.push_back(evaluate("fcl::OBB", ns, reported, truth));
  }
  {
    const auto a = kdops<dm::Kdop14>(trisA), b = kdops<dm::Kdop14>(trisB);
    const double ns = nsPerTest(
        a, b, pairs, [](const dm::Kdop14& x, const dm::Kdop14& y) { return x.overlaps(y); }, reported);
    rows.push_back(evaluate("dm::Kdop14", ns, reported, truth));
  }
  {
    const auto a = kdops<dm::Kdop18>(trisA), b = kdops<dm::Kdop18>(trisB);
    const double ns = nsPerTest(
        a, b, pairs, [](const dm::Kdop18& x, const dm::Kdop18& y) { return x.overlaps(y); }, reported);
    rows.push_back(evaluate("dm::Kdop18", ns, reported, truth));
  }
  {
    using Fcl18 = fcl::KDOP<double, 18>;
    const auto a = fclVolumes<Fcl18>(trisA), b = fclVolumes<Fcl18>(trisB);
    const double ns = nsPerTest(
        a, b, pairs, [](const Fcl18& x, const Fcl18& y) { return x.overlap(y); }, reported);
    rows.push_back(evaluate("fcl::KDOP<18>", ns, reported, truth));
  }
  {
    const auto a = kdops<dm::Kdop26>(trisA), b = kdops<dm::Kdop26>(trisB);
    const double ns = nsPerTest(
        a, b, pairs, [](const dm::Kdop26& x, const dm::Kdop26& y) { return x.overlaps(y); }, reported);
    rows.push_back(evaluate("dm::Kdop26", ns, reported, truth));
  }
  std::printf("%-14s %10s %16s %8s\n", "volume", "ns/test", "false-positive", "missed");
  for (const Row& r : rows)
    std::printf("%-14s %10.2f %15.1f%% %8d\n", r.name, r.ns, 100 * r.falsePositive, r.missed);
  std::printf("\nratio ours/FCL ns: Aabb/AABB %.2f, Kdop18/KDOP<18> %.2f\n", rows[0].ns / rows[1].ns,
              rows[4].ns / rows[5].ns);
  int missed = 0;
  for (const Row& r : rows) missed += r.missed;
  return missed == 0 ? 0 : 1;
}
