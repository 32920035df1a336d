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
#include <cstring>
#include <initializer_list>
#include <numbers>
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
// kEntry) at `speed` through the depths in `path`, starting at depth
// `from` (2 mm above).
std::vector<Sample> insert(NeedleInsertion& needle, double speed, std::initializer_list<double> path,
                           double h = 4e-3, double from = -0.002) {
  const Vec3 dir(0, 0, -1);
  std::vector<Sample> trace;
  double d = from;
  for (double target : path) {
    const int n = int(std::ceil(std::abs(target - d) / (speed * h)));
    const double start = d;
    for (int i = 1; i <= n; ++i) {
      d = start + (target - start) * i / n;
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
// and friction within 1 % (the issue asks 5 %; 0.04 % measured); the
// stiffness before puncture is the tissue's, in series with the tip's
// spring: once that spring's compliance is taken out it doubles with
// Young's modulus (linear elasticity). Pulling the needle out (at 20 mm/s),
// friction reverses (−μ per metre of shaft still in, the surface dragged
// up with it), and once out the needle holds nothing and the tissue goes
// back to rest.
TEST(NeedleInsertion, HomogeneousBlockShowsTheThreePhasesAndTheFitRecoversTheModel) {
  const NeedleLayer tissue{.punctureForce = 1.0, .cuttingForce = 0.3, .friction = 40.0};
  const NeedleOptions options{.couplingSpacing = 5e-4, .tipStiffness = 2000.0};
  double tissueStiffness[2] = {0, 0};
  for (int run = 0; run < 2; ++run) {
    Block b = makeBlock(run == 0 ? 3e4 : 6e4);
    const std::vector<std::uint8_t> layerOf(b.body.tetCount(), 0);
    auto needle = NeedleInsertion::create(b.body, layerOf, {&tissue, 1}, options);
    ASSERT_TRUE(needle.ok());
    auto trace = run == 0 ? insert(*needle, 0.01, {0.02}, 4e-3) : insert(*needle, 0.01, {0.004}, 4e-3);
    if (run == 0) {  // out at twice the speed
      const auto out = insert(*needle, 0.02, {-0.002}, 4e-3, 0.02);
      trace.insert(trace.end(), out.begin(), out.end());
    }
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
    EXPECT_NEAR(fCut, tissue.cuttingForce, 0.01 * tissue.cuttingForce);
    EXPECT_NEAR(mu, tissue.friction, 0.01 * tissue.friction);
    // Pulling out: −μ per metre of depth still in, no cutting force.
    const auto [r0, muOut] = fitLine(
        trace, [](const Sample& s) { return s.depth; },
        [&](const Sample& s) {
          return s.state == NeedleTip::InTrack && s.force < -0.1 && s.depth > 0.004 && s.depth < 0.010;
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

// Skin over fat over muscle, from a label volume of 5 mm voxels (the
// block's cells): the force peaks where the tip breaks the skin (its
// threshold) and again at the muscle's fascia, with friction and cutting in
// between: at each membrane the tip holds until the layer's threshold, and
// the force drops once through — the loss of resistance a trainee feels.
TEST(NeedleInsertion, LayersGiveOnePeakPerMembrane) {
  Block b = makeBlock(3e4);
  Affine3 indexToWorld = Affine3::Identity();
  indexToWorld.linear() = 0.005 * Mat3::Identity();
  indexToWorld.translation() = Vec3::Constant(0.0025);  // voxel centres at the cells' centres
  auto labels = Volume::create({8, 8, 6}, VoxelType::U8, indexToWorld);
  ASSERT_TRUE(labels.ok());
  for (int k = 0; k < 6; ++k)
    for (int j = 0; j < 8; ++j)
      for (int i = 0; i < 8; ++i)
        labels->setValue(i, j, k, k == 5 ? 1 : k >= 3 ? 2 : 3);  // skin, fat, muscle
  const std::uint8_t layerOfLabel[] = {0, 0, 1, 2};              // background (unused), skin, fat, muscle
  auto layerOf = tetLayersFromLabels(b.mesh, *labels, layerOfLabel);
  ASSERT_TRUE(layerOf.ok()) << layerOf.error().message();
  const NeedleLayer layers[] = {{.punctureForce = 1.2, .cuttingForce = 0.4, .friction = 50.0},   // skin
                                {.punctureForce = 0.0, .cuttingForce = 0.1, .friction = 10.0},   // fat
                                {.punctureForce = 0.8, .cuttingForce = 0.3, .friction = 40.0}};  // muscle
  auto needle = NeedleInsertion::create(b.body, *layerOf, layers, {.couplingSpacing = 5e-4});
  ASSERT_TRUE(needle.ok());
  const Vec3 dir(0, 0, -1);
  double peak[2] = {0, 0}, tipAtPuncture[2] = {0, 0}, dropAfter[2] = {1e9, 1e9};
  int inLayer[3] = {0, 0, 0};
  std::size_t punctures = 0;
  double d = -0.002;
  for (; d < 0.021; d += 4e-5) {
    ASSERT_TRUE(needle->step(kEntry + d * dir, dir, 4e-3).ok());
    const double f = -needle->force().dot(dir);
    if (needle->tipLayer() >= 0 && needle->tipState() == NeedleTip::Cutting) ++inLayer[needle->tipLayer()];
    if (needle->punctureCount() > punctures) {  // this step broke a membrane
      tipAtPuncture[punctures] = needle->tipForce();
      peak[punctures] = f;
      punctures = needle->punctureCount();
    } else if (punctures > 0 && needle->tipState() != NeedleTip::Pressing) {
      dropAfter[punctures - 1] = std::min(dropAfter[punctures - 1], f);
    }
  }
  ASSERT_EQ(punctures, 2u);  // skin and fascia; fat has no membrane
  EXPECT_GT(inLayer[0], 0);
  EXPECT_GT(inLayer[1], 0);
  EXPECT_GT(inLayer[2], 0);
  EXPECT_NEAR(tipAtPuncture[0], layers[0].punctureForce, 0.05 * layers[0].punctureForce);
  EXPECT_NEAR(tipAtPuncture[1], layers[2].punctureForce, 0.05 * layers[2].punctureForce);
  // The skin's puncture is the whole force (nothing else holds the needle
  // yet); at the fascia the shaft's friction in skin and fat adds to it.
  EXPECT_NEAR(peak[0], layers[0].punctureForce, 0.05 * layers[0].punctureForce);
  EXPECT_GT(peak[1], tipAtPuncture[1]);
  for (int m = 0; m < 2; ++m) EXPECT_LT(dropAfter[m], peak[m] - 0.3) << "membrane " << m;
}

// Pulled back half way and pushed in again along its own track, the needle
// cuts nothing and breaks nothing: the force is the shaft's friction alone,
// at most μ times the depth (the first pass, with its cutting force, had
// half as much again).
TEST(NeedleInsertion, ReinsertionAlongTheTrackOnlySlides) {
  Block b = makeBlock(3e4);
  const std::vector<std::uint8_t> layerOf(b.body.tetCount(), 0);
  const NeedleLayer tissue{.punctureForce = 1.0, .cuttingForce = 0.3, .friction = 40.0};
  auto needle = NeedleInsertion::create(b.body, layerOf, {&tissue, 1}, {.couplingSpacing = 5e-4});
  ASSERT_TRUE(needle.ok());
  const auto first = insert(*needle, 0.01, {0.012});
  const double firstAt10 =
      std::find_if(first.begin(), first.end(), [](const Sample& s) { return s.depth >= 0.010; })->force;
  const double track = needle->trackLength();
  const auto again = insert(*needle, 0.01, {0.006, 0.0105}, 4e-3, 0.012);
  for (const Sample& s : again) {
    ASSERT_NE(s.state, NeedleTip::Pressing) << s.depth;
    ASSERT_NE(s.state, NeedleTip::Cutting) << s.depth;
  }
  EXPECT_EQ(needle->punctureCount(), 1u);
  EXPECT_NEAR(needle->trackLength(), track, 5e-4);
  // At 10.5 mm on the way back in: friction over the shaft in the tissue
  // (the surface dragged down a little shortens it), no cutting force.
  const double depth = again.back().depth;
  EXPECT_LT(again.back().force, tissue.friction * depth);
  EXPECT_GT(again.back().force, 0.8 * tissue.friction * depth);
  EXPECT_GT(firstAt10, tissue.cuttingForce + 0.8 * tissue.friction * 0.010);
}

// Two runs from the same state give the same bits: force, tip state and
// every node.
TEST(NeedleInsertion, LockstepRunsAreBitIdentical) {
  std::vector<double> forces[2];
  std::vector<Vec3> nodes[2];
  for (int run = 0; run < 2; ++run) {
    Block b = makeBlock(3e4);
    const std::vector<std::uint8_t> layerOf(b.body.tetCount(), 0);
    const NeedleLayer tissue{.punctureForce = 0.5, .cuttingForce = 0.2, .friction = 30.0};
    auto needle = NeedleInsertion::create(b.body, layerOf, {&tissue, 1});
    ASSERT_TRUE(needle.ok());
    for (const Sample& s : insert(*needle, 0.02, {0.008, 0.003})) forces[run].push_back(s.force);
    nodes[run] = b.body.positions();
  }
  ASSERT_EQ(forces[0].size(), forces[1].size());
  EXPECT_EQ(std::memcmp(forces[0].data(), forces[1].data(), forces[0].size() * sizeof(double)), 0);
  EXPECT_EQ(std::memcmp(nodes[0].data(), nodes[1].data(), nodes[0].size() * sizeof(Vec3)), 0);
}

// The local model a haptic loop runs between physics steps gives, at the
// step's own pose, the step's wrench (but at the puncture's step), whatever the tip is doing: pressing,
// cutting, sliding back, and with the needle tilted and moved sideways (the
// shaft's points then push across it and make a torque).
TEST(NeedleLocalModel, ReproducesTheStepsWrenchAtItsPose) {
  Block b = makeBlock(3e4);
  const std::vector<std::uint8_t> layerOf(b.body.tetCount(), 0);
  const NeedleLayer tissue{.punctureForce = 0.8, .cuttingForce = 0.3, .friction = 40.0};
  auto needle = NeedleInsertion::create(b.body, layerOf, {&tissue, 1});
  ASSERT_TRUE(needle.ok());
  NeedleLocalModel model;
  int seen[4] = {0, 0, 0, 0};
  const double h = 4e-3;
  for (int i = 0; i < 500; ++i) {
    const double t = i * h;
    // In 12 mm at 10 mm/s, with a sideways drift and a tilt, then back 3 mm.
    const double depth = t < 1.4 ? -0.002 + 0.01 * t : 0.012 - 0.01 * (t - 1.4);
    const Vec3 dir = Vec3(0.05 * std::min(t, 1.0), 0.0, -1.0).normalized();
    const Vec3 tip = kEntry + Vec3(0.001 * std::min(t, 1.0), 0.0, 0.0) + depth * Vec3(0, 0, -1);
    const std::size_t punctures = needle->punctureCount();
    ASSERT_TRUE(needle->step(tip, dir, h).ok());
    // The step that breaks the membrane reports the force that broke it;
    // the model already holds what comes after.
    if (needle->punctureCount() != punctures) continue;
    needle->localModel(model);
    const Wrench w = model.evaluate(tip, dir);
    ++seen[int(needle->tipState())];
    ASSERT_LT((w.force - needle->force()).norm(), 1e-9 + 1e-9 * needle->force().norm()) << "t = " << t;
    ASSERT_LT((w.torque - needle->wrench().torque).norm(), 1e-11) << "t = " << t;
  }
  EXPECT_GT(seen[int(NeedleTip::Pressing)], 0);
  EXPECT_GT(seen[int(NeedleTip::Cutting)], 0);
  EXPECT_GT(seen[int(NeedleTip::InTrack)], 0);
  EXPECT_GT(needle->wrench().torque.norm(), 1e-5);
}

// Frozen at a step while pressing (half the threshold), the model pushed
// further in breaks the membrane where the physics, stepped on, breaks it
// (the membrane yields with the tissue's stiffness), and the force falls at
// once to the cutting force.
TEST(NeedleLocalModel, BreaksTheMembraneAtItsThresholdBetweenSteps) {
  Block b = makeBlock(3e4);
  const std::vector<std::uint8_t> layerOf(b.body.tetCount(), 0);
  const NeedleLayer tissue{.punctureForce = 1.0, .cuttingForce = 0.3, .friction = 40.0};
  const NeedleOptions options{.tipStiffness = 2000.0};
  auto needle = NeedleInsertion::create(b.body, layerOf, {&tissue, 1}, options);
  ASSERT_TRUE(needle.ok());
  const Vec3 dir(0, 0, -1);
  double d = -0.002;
  while (needle->tipState() != NeedleTip::Pressing || needle->tipForce() < 0.5) {
    d += 4e-5;
    ASSERT_TRUE(needle->step(kEntry + d * dir, dir, 4e-3).ok());
    ASSERT_LT(d, 0.02);
  }
  NeedleLocalModel model;
  needle->localModel(model);
  const double d0 = d;
  // The model, frozen here, pushed on in micrometres until it breaks.
  double last = -needle->force().dot(dir), x = d0, modelBreak = 0.0;
  for (; x < d0 + 0.01; x += 1e-6) {
    const double f = -model.evaluate(kEntry + x * dir, dir).force.dot(dir);
    if (model.state != NeedleTip::Pressing) {
      modelBreak = x;
      EXPECT_NEAR(f, tissue.cuttingForce, 1e-9);  // the pop: the spring lets go at once
      EXPECT_GT(last, tissue.punctureForce - 0.01);
      break;
    }
    last = f;
  }
  ASSERT_EQ(model.state, NeedleTip::Cutting);
  // The physics, stepped on: it breaks the membrane where the model said,
  // within a tenth of the way (the model's tissue stiffness is the secant
  // so far; the tissue stiffens a little as it tents).
  while (needle->punctureCount() == 0) {
    d += 4e-5;
    ASSERT_TRUE(needle->step(kEntry + d * dir, dir, 4e-3).ok());
    ASSERT_LT(d, d0 + 0.02);
  }
  EXPECT_NEAR(modelBreak - d0, d - d0, 0.1 * (d - d0));
  // Frozen, the tissue would not yield and the tip's spring alone would
  // break it within (1 − f)/2000 m: far too soon.
  EXPECT_GT(modelBreak - d0, 3.0 * (tissue.punctureForce - 0.5) / options.tipStiffness);
}

// Where the hand reverses, the shaft's points stick: between two physics
// steps (10 ms, 100 Hz) the model must predict the force the next step will
// find, which the tissue's give sets as much as the points' springs. The
// model's prediction at the next step's pose, against that step's force,
// going back out at 10 mm/s: frozen points overshoot the drop by about
// N·k_along·0.1 mm (the sawtooth a hand feels). Yielding along the track
// (shaftYield), the first two steps on the tissue's stiffness under the tip
// as it last pressed halve that error; once the points have stuck for two
// steps (the track's own stiffness measured) it stays under 0.05 N and a
// fifth of the frozen error.
TEST(NeedleLocalModel, PointsYieldWithTheTissueWhereTheHandReverses) {
  Block b = makeBlock(3e4);
  const std::vector<std::uint8_t> layerOf(b.body.tetCount(), 0);
  const NeedleLayer tissue{.punctureForce = 0.8, .cuttingForce = 0.3, .friction = 40.0};
  auto needle = NeedleInsertion::create(b.body, layerOf, {&tissue, 1});
  ASSERT_TRUE(needle.ok());
  const Vec3 dir(0, 0, -1);
  const double h = 0.01, speed = 0.01;
  double d = -0.002;
  while (d < 0.016) {
    d += speed * h;
    ASSERT_TRUE(needle->step(kEntry + d * dir, dir, h).ok());
  }
  ASSERT_GT(needle->activeCouplingCount(), 5u);
  NeedleLocalModel model, frozen;
  double firstYield = 0.0, firstFrozen = 0.0, worstYield = 0.0, worstFrozen = 0.0;
  for (int i = 0; i < 20; ++i) {  // 0.2 s back out
    needle->localModel(model);
    frozen.assign(model);
    frozen.shaftYield = 0.0;
    d -= speed * h;
    const double predicted = -model.evaluate(kEntry + d * dir, dir).force.dot(dir);
    const double predictedFrozen = -frozen.evaluate(kEntry + d * dir, dir).force.dot(dir);
    ASSERT_TRUE(needle->step(kEntry + d * dir, dir, h).ok());
    const double actual = -needle->force().dot(dir);
    double& yielding = i < 2 ? firstYield : worstYield;
    double& still = i < 2 ? firstFrozen : worstFrozen;
    yielding = std::max(yielding, std::abs(predicted - actual));
    still = std::max(still, std::abs(predictedFrozen - actual));
  }
  EXPECT_GT(model.shaftYield, 0.0);
  EXPECT_LT(model.shaftYield, 1.0);
  EXPECT_GT(firstFrozen, 0.1) << "frozen points should overshoot the drop (the sawtooth)";
  EXPECT_LT(firstYield, 0.5 * firstFrozen)
      << "yielding " << firstYield << " N, frozen " << firstFrozen << " N";
  EXPECT_GT(worstFrozen, 0.1);
  EXPECT_LT(worstYield, 0.2 * worstFrozen)
      << "yielding " << worstYield << " N, frozen " << worstFrozen << " N";
  EXPECT_LT(worstYield, 0.05);
}

// The arc of a curved needle: every point(u) is R from the centre, the
// coordinate of point(u) (and of any point off it along the radius or
// across the plane) is u, and tangentAt is point's derivative.
TEST(NeedleShaft, ArcPointsCoordinatesAndTangents) {
  Isometry3 pose = Isometry3::Identity();
  pose.linear() = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  pose.translation() = Vec3(0.01, -0.02, 0.03);
  const double R = 0.012, L = 0.03;
  const NeedleShaft arc = NeedleShaft::fromPose(pose, R, L);
  const Vec3 centre = arc.tip + R * arc.normal;
  for (double u = -L; u <= 0.0; u += L / 16) {
    const Vec3 p = arc.point(u);
    EXPECT_NEAR((p - centre).norm(), R, 1e-15);
    EXPECT_NEAR(arc.coordinate(p), u, 1e-14);
    const Vec3 binormal = arc.tangent.cross(arc.normal);
    EXPECT_NEAR(arc.coordinate(p + 0.003 * (p - centre).normalized() + 0.002 * binormal), u, 1e-14);
    const Vec3 slope = (arc.point(u + 1e-7) - arc.point(u - 1e-7)) / 2e-7;
    EXPECT_LT((slope - arc.tangentAt(u)).norm(), 1e-8);
  }
  EXPECT_GT(arc.coordinate(arc.tip + 1e-3 * arc.tangent), 0.0);  // ahead of the tip
  const NeedleShaft line = NeedleShaft::straight(Vec3::Zero(), Vec3::UnitZ(), L);
  EXPECT_DOUBLE_EQ(line.coordinate(Vec3(0.3, 0.1, -0.02)), -0.02);
  EXPECT_NEAR(line.normal.dot(line.tangent), 0.0, 1e-15);
}

// A suture needle (R = 10 mm, half a circle) driven the way a surgeon
// drives it, turned about its own centre 5 mm above the tissue: the tip
// goes in, the shaft follows its own arc, so the track lies on the shaft
// (the tissue is not pushed sideways), and what resists the turn is the
// friction along the arc and the cutting force: a torque about the centre
// of R·(f_cut + μ·L_in). The local model reproduces the curved needle's
// wrench at each step's pose.
TEST(NeedleInsertion, CurvedNeedleTurnedAboutItsCentreFollowsItsArc) {
  Block b = makeBlock(3e4);
  const std::vector<std::uint8_t> layerOf(b.body.tetCount(), 0);
  const NeedleLayer tissue{.punctureForce = 0.8, .cuttingForce = 0.3, .friction = 40.0};
  const double R = 0.01;
  auto needle = NeedleInsertion::create(
      b.body, layerOf, {&tissue, 1}, {.length = std::numbers::pi * R, .radius = R, .couplingSpacing = 5e-4});
  ASSERT_TRUE(needle.ok());
  const Vec3 centre(0.0203, 0.0196, kTop + 0.005);
  NeedleLocalModel model;
  double worstOffset = 0.0, offPlane = 0.0, torqueSeen = 0.0, torqueExpected = 0.0;
  for (double theta = 0.3; theta < 2.4; theta += 2e-3) {  // 20 µm of tip travel a 4 ms step
    // Tip at centre + R(−cos θ, 0, −sin θ), moving along (sin θ, 0, −cos θ).
    Isometry3 pose = Isometry3::Identity();
    const Vec3 tangent(std::sin(theta), 0.0, -std::cos(theta)), normal(std::cos(theta), 0.0, std::sin(theta));
    pose.linear().col(0) = normal;
    pose.linear().col(1) = tangent.cross(normal);
    pose.linear().col(2) = tangent;
    pose.translation() = centre - R * normal;
    const std::size_t punctures = needle->punctureCount();
    ASSERT_TRUE(needle->step(pose, 4e-3).ok());
    if (needle->punctureCount() != punctures) continue;
    needle->localModel(model);
    const Wrench w = model.evaluate(pose);
    ASSERT_LT((w.force - needle->force()).norm(), 1e-9 + 1e-9 * needle->force().norm()) << "theta " << theta;
    ASSERT_LT((w.torque - needle->wrench().torque).norm(), 1e-11) << "theta " << theta;
    if (theta > 1.2 && theta < 2.3) {
      // Every shaft point sits on the arc: the tissue follows the needle.
      const NeedleShaft& shaft = needle->shaft();
      for (std::size_t k = 0; k < model.pointCount; ++k) {
        const Vec3& p = model.points[k].position;
        worstOffset = std::max(worstOffset, (p - shaft.point(shaft.coordinate(p))).norm());
      }
      // The turn's resistance: the torque about the centre's axis (the tip
      // moving along +tangent turns about −y, so the tissue's torque on
      // the needle is about +y), R times the cutting force and the
      // friction over the track, entry to tip.
      const Vec3 aboutCentre = needle->wrench().torque + (shaft.tip - centre).cross(needle->force());
      torqueSeen = aboutCentre.y();
      torqueExpected = R * (tissue.cuttingForce + tissue.friction * needle->trackLength());
      offPlane = std::max(
          offPlane, (std::abs(aboutCentre.x()) + std::abs(aboutCentre.z())) / std::abs(aboutCentre.y()));
    }
  }
  // Within half a millimetre (a tenth of the cells): the entry point was
  // held by the tip's isotropic spring while the tip pressed in obliquely,
  // and lags off the arc by up to that spring's stretch at the threshold
  // (0.8 N / 2000 N/m = 0.4 mm).
  EXPECT_LT(worstOffset, 5e-4);
  // The torque turns about the centre's axis; what is off it (7 %) comes
  // from the tetrahedra, whose Kuhn split is not mirror-symmetric about the
  // needle's plane.
  EXPECT_LT(offPlane, 0.1);
  EXPECT_EQ(needle->punctureCount(), 1u);
  EXPECT_EQ(needle->tipState(), NeedleTip::Cutting);
  EXPECT_NEAR(torqueSeen, torqueExpected, 0.02 * torqueExpected);
}

TEST(NeedleInsertion, BadInputIsNamed) {
  Block b = makeBlock(3e4, {2, 2, 2});
  std::vector<std::uint8_t> layerOf(b.body.tetCount(), 0);
  const NeedleLayer one{};
  const auto message = [](const auto& r) { return r.ok() ? std::string("(accepted)") : r.error().message(); };
  auto shortList = NeedleInsertion::create(b.body, std::span(layerOf).first(3), {&one, 1});
  EXPECT_NE(message(shortList).find("tetLayers has 3 entries"), std::string::npos) << message(shortList);
  layerOf[5] = 1;
  auto outOfRange = NeedleInsertion::create(b.body, layerOf, {&one, 1});
  EXPECT_NE(message(outOfRange).find("tetLayers[5]"), std::string::npos) << message(outOfRange);
  layerOf[5] = 0;
  const NeedleLayer negative{.friction = -1.0};
  auto badLayer = NeedleInsertion::create(b.body, layerOf, {&negative, 1});
  EXPECT_NE(message(badLayer).find("layers[0].friction"), std::string::npos) << message(badLayer);
  auto badOption = NeedleInsertion::create(b.body, layerOf, {&one, 1}, {.couplingSpacing = 0.0});
  EXPECT_NE(message(badOption).find("options.couplingSpacing"), std::string::npos) << message(badOption);
  auto badRadius = NeedleInsertion::create(b.body, layerOf, {&one, 1}, {.radius = -1.0});
  EXPECT_NE(message(badRadius).find("options.radius"), std::string::npos) << message(badRadius);
  auto tooLong = NeedleInsertion::create(b.body, layerOf, {&one, 1}, {.length = 0.1, .radius = 0.01});
  EXPECT_NE(message(tooLong).find("options.length"), std::string::npos) << message(tooLong);
  auto curved = NeedleInsertion::create(b.body, layerOf, {&one, 1}, {.length = 0.03, .radius = 0.01});
  ASSERT_TRUE(curved.ok());
  EXPECT_NE(message(curved->step(Vec3::Zero(), Vec3::UnitZ(), 1e-3)).find("plane of its arc"),
            std::string::npos);
  Isometry3 sheared = Isometry3::Identity();
  sheared.linear()(0, 2) = 0.3;
  EXPECT_NE(message(curved->step(sheared, 1e-3)).find("not a finite rigid"), std::string::npos);
  auto needle = NeedleInsertion::create(b.body, layerOf, {&one, 1});
  ASSERT_TRUE(needle.ok());
  EXPECT_NE(message(needle->step(Vec3(0, 0, NAN), Vec3::UnitZ(), 1e-3)).find("tip"), std::string::npos);
  EXPECT_NE(message(needle->step(Vec3::Zero(), Vec3::Zero(), 1e-3)).find("direction"), std::string::npos);
  EXPECT_NE(message(needle->step(Vec3::Zero(), Vec3::UnitZ(), 0.0)).find("h "), std::string::npos);
  // A label volume with a label the map does not cover.
  auto labels = Volume::create({2, 2, 2}, VoxelType::U8, Affine3(Eigen::Scaling(0.025)));
  ASSERT_TRUE(labels.ok());
  labels->setValue(0, 0, 0, 7);
  const std::uint8_t map[] = {0, 0};
  auto unmapped = tetLayersFromLabels(b.mesh, *labels, map);
  EXPECT_NE(message(unmapped).find("label 7"), std::string::npos) << message(unmapped);
}

}  // namespace
}  // namespace dm
