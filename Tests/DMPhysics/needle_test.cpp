// Tests of dm/physics/needle.hpp and the point springs it rests on
// (dm/physics/fem.hpp): an anisotropic spring holds a hanging block with
// the static offset K⁻¹·mg; a needle driven at constant speed into a
// homogeneous block shows the three phases of Okamura et al. (2004), and
// fitting that model to the force–depth curve gives back the configured
// puncture threshold, cutting force and friction, and a stiffness that
// scales with Young's modulus; layered tissue gives one force peak per
// membrane; retraction lets go of the track and the tissue returns to
// rest; runs are bit-reproducible; bad input is named.
#include <dm/core/volume.hpp>
#include <dm/physics/fem.hpp>
#include <dm/physics/needle.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <initializer_list>
#include <string>
#include <utility>
#include <vector>

#include "physics_test_support.hpp"

namespace dm {
namespace {

using dm::test::kG;

// A tissue block 40 × 40 × 30 mm, its base fixed, 5 mm cells.
struct Block {
  TetMesh mesh;
  FemBody body;
};
Block makeBlock(double youngsModulus, Vec3i cells = {8, 8, 6}) {
  auto mesh = tetMeshBox(cells, Vec3(0.04, 0.04, 0.03));
  EXPECT_TRUE(mesh.ok());
  auto body =
      FemBody::create(*mesh, {.youngsModulus = youngsModulus, .poissonRatio = 0.45, .density = 1000.0},
                      {.alpha = 30.0, .beta = 0.002});
  EXPECT_TRUE(body.ok());
  body->fixNodesWhere([](const Vec3& p) { return p.z() < 1e-9; });
  return {std::move(*mesh), std::move(*body)};
}

struct Sample {
  double depth;  // m, tip below the block's top surface
  double force;  // N, along the needle toward the handle: what resists insertion
  NeedleTip state;
  double track;  // m, the track's length (entry to deepest cut) at the step's end
};

constexpr double kTop = 0.03;             // m, the block's top face
const Vec3 kEntry(0.0203, 0.0196, kTop);  // off the grid's nodes and edges

// Drives the needle straight down (tip at depth d below the top, over
// kEntry) at `speed` through the depths in `path`, starting 2 mm above.
std::vector<Sample> insert(NeedleInsertion& needle, double speed, std::initializer_list<double> path,
                           double h = 2e-3) {
  const Vec3 dir(0, 0, -1);
  std::vector<Sample> trace;
  double d = -0.002;
  for (double target : path) {
    const int n = int(std::ceil(std::abs(target - d) / (speed * h)));
    const double from = d;
    for (int i = 1; i <= n; ++i) {
      d = from + (target - from) * i / n;
      auto r = needle.step(kEntry + d * dir, dir, h);
      EXPECT_TRUE(r.ok()) << r.error().message();
      if (!r) return trace;
      trace.push_back({d, -needle.force().dot(dir), needle.tipState(), needle.trackLength()});
    }
  }
  return trace;
}

// Least-squares line y = a + b·x through the samples picked by `use`.
template <class X, class Pick>
std::pair<double, double> fitLine(const std::vector<Sample>& t, X&& xOf, Pick&& use) {
  double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (const Sample& s : t)
    if (use(s)) {
      const double x = xOf(s);
      n += 1, sx += x, sy += s.force, sxx += x * x, sxy += x * s.force;
    }
  const double b = (n * sxy - sx * sy) / (n * sxx - sx * sx);
  return {(sy - b * sx) / n, b};
}

// The puncture: the largest force before the tip first cuts (the sample of
// the step that broke through included), and that sample's index.
std::pair<double, std::size_t> firstPeak(const std::vector<Sample>& t) {
  double peak = 0.0;
  for (std::size_t i = 0; i < t.size(); ++i) {
    peak = std::max(peak, t[i].force);
    if (t[i].state == NeedleTip::Cutting) return {peak, i};
  }
  return {peak, t.size()};
}

// ---------------------------------------------------------------------------
// Point springs
// ---------------------------------------------------------------------------

// A free block hung from one anisotropic spring at a point inside a
// tetrahedron settles where the spring carries its weight: K·(a − p) = −Mg,
// so p − a = K⁻¹·Mg whatever the block's swing (the spring has no torque).
TEST(FemPointSpring, AnisotropicSpringCarriesAHangingBlockAtTheStaticOffset) {
  auto mesh = tetMeshBox({3, 3, 3}, Vec3(0.03, 0.03, 0.03));
  ASSERT_TRUE(mesh.ok());
  auto body = FemBody::create(*mesh, {.youngsModulus = 5e4, .poissonRatio = 0.3, .density = 1000.0},
                              {.alpha = 40.0, .beta = 0.002});
  ASSERT_TRUE(body.ok());
  body->setGravity({0, 0, -kG});
  const Tet& t = mesh->tets[80];  // inside the middle cell
  const std::array<double, 4> w{0.1, 0.2, 0.3, 0.4};
  Vec3 p0 = Vec3::Zero();
  for (std::size_t i = 0; i < 4; ++i) p0 += w[i] * mesh->nodes[t[i]];
  const Vec3 d = Vec3(1, 0, 1).normalized();
  const FemPointSpring spring{
      .nodes = t, .weights = w, .anchor = p0, .stiffness = FemPointSpring::axial(d, 3000.0, 800.0)};
  ASSERT_TRUE(body->setPointSprings({&spring, 1}).ok());
  for (int i = 0; i < 1500; ++i) ASSERT_TRUE(body->step(2e-3).ok());
  Vec3 p = Vec3::Zero();
  for (std::size_t i = 0; i < 4; ++i) p += w[i] * body->positions()[t[i]];
  const Vec3 weight = body->totalMass() * Vec3(0, 0, -kG);
  const Vec3 expected = spring.stiffness.inverse() * weight;  // p − a
  EXPECT_LT((p - p0 - expected).norm(), 0.01 * expected.norm())
      << (p - p0).transpose() << " vs " << expected.transpose();
  EXPECT_LT((body->pointSpringForce(0) + weight).norm(), 0.01 * weight.norm());
  // The sag is anisotropic: the soft direction d takes (mg·d)/800, the stiff
  // one across it (mg·e)/3000.
  EXPECT_NEAR((p - p0).dot(d), weight.dot(d) / 800.0, 0.01 * expected.norm());
}

TEST(FemPointSpring, BadInputNamesTheSpringAndKeepsTheSet) {
  auto mesh = tetMeshBox({1, 1, 1}, Vec3(0.01, 0.01, 0.01));
  ASSERT_TRUE(mesh.ok());
  auto body = FemBody::create(*mesh, {});
  ASSERT_TRUE(body.ok());
  const FemPointSpring good{
      .nodes = {0, 1, 2, 3}, .weights = {0.25, 0.25, 0.25, 0.25}, .stiffness = 100.0 * Mat3::Identity()};
  ASSERT_TRUE(body->setPointSprings({&good, 1}).ok());
  const auto rejects = [&](FemPointSpring bad, const char* words) {
    const FemPointSpring set[2] = {good, bad};
    auto st = body->setPointSprings(set);
    ASSERT_FALSE(st.ok()) << words;
    EXPECT_NE(st.error().message().find("springs[1]"), std::string::npos) << st.error().message();
    EXPECT_NE(st.error().message().find(words), std::string::npos) << st.error().message();
    EXPECT_EQ(body->pointSpringCount(), 1u);
  };
  FemPointSpring b = good;
  b.nodes[2] = 99;
  rejects(b, "out of range");
  b = good, b.weights[0] = 0.5;
  rejects(b, "sum to");
  b = good, b.weights[1] = -0.1, b.weights[0] = 0.6;
  rejects(b, "negative");
  b = good, b.anchor.x() = std::nan("");
  rejects(b, "anchor");
  b = good, b.load.y() = INFINITY;
  rejects(b, "load");
  b = good, b.stiffness(0, 1) = 5.0;
  rejects(b, "symmetric");
  b = good, b.stiffness = FemPointSpring::axial(Vec3::UnitX(), 100.0, -10.0);
  rejects(b, "semi-definite");
}

// ---------------------------------------------------------------------------
// Needle insertion
// ---------------------------------------------------------------------------

// Okamura et al.'s three phases at 10 mm/s into a homogeneous block: the
// force rises while the surface tents, drops when the tip breaks through
// at the configured threshold, then grows linearly with the track, F =
// f_cut + μ·L. Fitting those lines gives back the configured cutting force
// and friction within 5 %; the stiffness before puncture is the tissue's,
// in series with the tip's spring: once that spring's compliance is taken
// out it doubles with Young's modulus (linear elasticity). Pulling the
// needle out, friction reverses (−μ per metre of shaft still in), and once
// out the needle holds nothing and the tissue goes back to rest.
TEST(NeedleInsertion, HomogeneousBlockShowsTheThreePhasesAndTheFitRecoversTheModel) {
  const NeedleLayer tissue{.punctureForce = 1.0, .cuttingForce = 0.3, .friction = 40.0};
  const NeedleOptions options{.couplingSpacing = 5e-4, .tipStiffness = 2000.0};
  double tissueStiffness[2] = {0, 0};
  for (int run = 0; run < 2; ++run) {
    Block b = makeBlock(run == 0 ? 3e4 : 6e4);
    const std::vector<std::uint8_t> layerOf(b.body.tetCount(), 0);
    auto needle = NeedleInsertion::create(b.body, layerOf, {&tissue, 1}, options);
    ASSERT_TRUE(needle.ok());
    const auto trace = run == 0 ? insert(*needle, 0.01, {0.02, -0.002}) : insert(*needle, 0.01, {0.004});
    // Pressing: the tip holds the surface from where it meets it, and the
    // force rises with depth.
    const auto [peak, at] = firstPeak(trace);
    ASSERT_LT(at, trace.size());
    for (std::size_t i = 1; i < at; ++i)
      if (trace[i].depth > 0.0) {
        ASSERT_EQ(trace[i].state, NeedleTip::Pressing) << trace[i].depth;
        ASSERT_GT(trace[i].force, trace[i - 1].force) << trace[i].depth;
      }
    // Puncture at the threshold, then the drop.
    EXPECT_GE(peak, tissue.punctureForce);
    EXPECT_LT(peak, 1.05 * tissue.punctureForce);
    EXPECT_EQ(needle->punctureCount(), 1u);
    // The tissue springs back within half a millimetre of travel: the force
    // falls to the cutting force and the little friction of the new track.
    double after = peak;
    for (std::size_t i = at + 1; i < trace.size() && trace[i].depth < trace[at].depth + 5e-4; ++i)
      after = std::min(after, trace[i].force);
    EXPECT_LT(after, 0.6 * peak);
    const auto [c0, k] = fitLine(
        trace, [](const Sample& s) { return s.depth; },
        [&](const Sample& s) { return s.state == NeedleTip::Pressing && s.depth > 0 && s.depth < 1e-3; });
    tissueStiffness[run] = 1.0 / (1.0 / k - 1.0 / options.tipStiffness);
    if (run == 1) break;
    // Cutting: f_cut + μ·L from 2 mm past the puncture on.
    const double dp = trace[at].depth;
    const auto [fCut, mu] = fitLine(
        trace, [](const Sample& s) { return s.track; },
        [&](const Sample& s) { return s.state == NeedleTip::Cutting && s.depth > dp + 2e-3; });
    EXPECT_NEAR(fCut, tissue.cuttingForce, 0.05 * tissue.cuttingForce);
    EXPECT_NEAR(mu, tissue.friction, 0.05 * tissue.friction);
    // Pulling out: −μ per metre of depth still in, no cutting force.
    const auto [r0, muOut] = fitLine(
        trace, [](const Sample& s) { return s.depth; },
        [&](const Sample& s) {
          return s.state == NeedleTip::InTrack && s.force < -0.1 && s.depth > 0.005 && s.depth < 0.015;
        });
    EXPECT_NEAR(-muOut, tissue.friction, 0.1 * tissue.friction);
    EXPECT_LT(std::abs(r0), 0.05);
    // Out: nothing holds the needle or the tissue, which goes back to rest.
    EXPECT_EQ(needle->tipState(), NeedleTip::Outside);
    EXPECT_EQ(needle->activeCouplingCount(), 0u);
    EXPECT_EQ(b.body.pointSpringCount(), 0u);
    EXPECT_EQ(trace.back().force, 0.0);
    for (int i = 0; i < 300; ++i) ASSERT_TRUE(b.body.step(2e-3).ok());
    double moved = 0.0;
    for (std::size_t i = 0; i < b.body.nodeCount(); ++i)
      moved = std::max(moved, (b.body.positions()[i] - b.body.restPositions()[i]).norm());
    EXPECT_LT(moved, 1e-5);
  }
  EXPECT_NEAR(tissueStiffness[1] / tissueStiffness[0], 2.0, 0.05 * 2.0);
}

}  // namespace
}  // namespace dm
