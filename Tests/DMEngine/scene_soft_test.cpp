// Soft tissue in a scene run: "soft" objects as FEM bodies the physics
// engine deforms. Checked against mechanics: a cantilever posed and scaled
// in the world sags in the world's −z exactly as the same FEM model built by
// hand (gravity turned into the object's frame, held face, scale baked in)
// and its held face carries its weight; the bundled tissue press
// (examples/scenes/tissue_press.json) ends at rest with the hand feeling
// what the tissue feels (Newton's third law across the haptic–physics
// threads) and the held bottom carrying push plus weight. Lockstep reruns
// are bit-identical; a model that cannot be built fails before anything
// runs.
#include <dm/core/filesystem.hpp>
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/nifti.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/physics/fem.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "../common/build_paths.hpp"
#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_soft_test {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr double kG = 9.80665;

using scene_run::fileText;
using scene_run::runScene;
using scene_run::vec;

const json& softBody(const json& summary, const std::string& name) {
  return scene_run::named(summary.at("physics").at("soft"), name);
}

// The bundled tissue press, without its render engine (the mechanics is
// what is checked here; example_tissue_press_lockstep renders it).
dm::SceneDesc tissuePress() { return scene_run::bundledScene("tissue_press.json"); }

// A 100 × 10 × 10 mm beam (a 50 × 5 × 5 mm box at scale 2) held at its −x
// end, turned 90° about x: its local y is the world's z, so gravity acts
// along its local −y.
constexpr double kBeamE = 1e7, kBeamNu = 0.3, kBeamRho = 1000, kBeamAlpha = 20, kBeamVoxel = 0.0025;
dm::SceneDesc cantilever() {
  const std::string text = R"({
    "format": "dmplatform-scene", "version": 2, "name": "cantilever",
    "resources": {"beam": {"type": "shape", "shape": "box", "half_extents": [0.025, 0.0025, 0.0025]}},
    "objects": [
      {"name": "beam", "mesh": "beam", "scale": 2,
       "pose": {"position": [0.1, 0.2, 0.3], "euler_deg": [90, 0, 0]},
       "soft": {"youngs_modulus": 1e7, "poisson_ratio": 0.3, "density": 1000, "damping": {"alpha": 20},
                "voxel_size": 0.0025, "fixed": ["-x"]}}
    ],
    "engines": {"physics": {"rate_hz": 100}},
    "outputs": {"summary": true}
  })";
  return scene_run::parsedScene(text, "cantilever.json");
}

TEST(SceneSoft, CantileverSagsInTheWorldLikeTheSameModelBuiltByHand) {
  const dm::SceneDesc scene = cantilever();
  const json s = runScene(scene, 1.0, dm::test::TempDir("soft_beam").path());
  const json& b = softBody(s, "beam");
  // The model: 40 × 4 × 4 cubes of 2.5 mm, six tetrahedra each; the held
  // face's 5 × 5 nodes.
  EXPECT_EQ(b.at("tets").get<int>(), 40 * 4 * 4 * 6);
  EXPECT_EQ(b.at("fixed_nodes").get<int>(), 25);
  const double mass = kBeamRho * 0.1 * 0.01 * 0.01;
  EXPECT_NEAR(b.at("mass_kg").get<double>(), mass, 1e-12);
  EXPECT_EQ(b.at("steps").get<int>(), 100);
  EXPECT_EQ(b.at("unconverged_steps").get<int>(), 0);

  // The same model by hand, in the object frame (scale baked in), gravity
  // along local −y (turned by the same rotation, so the inputs are the same
  // to the bit: the solver's tolerance would otherwise set the agreement),
  // 100 steps of 10 ms.
  auto mesh = dm::tetMeshBox({40, 4, 4}, {0.1, 0.01, 0.01}, {-0.05, -0.005, -0.005});
  ASSERT_TRUE(mesh) << mesh.error();
  auto body = dm::FemBody::create(
      *mesh, {.youngsModulus = kBeamE, .poissonRatio = kBeamNu, .density = kBeamRho}, {.alpha = kBeamAlpha});
  ASSERT_TRUE(body) << body.error();
  body->fixNodesWhere([](const dm::Vec3& p) { return std::abs(p.x() + 0.05) < 0.25 * kBeamVoxel; });
  const dm::Mat3 R = scene.objects[0].pose.isometry().linear();
  body->setGravity(R.transpose() * dm::Vec3(0, 0, -kG));
  EXPECT_NEAR(body->gravity().y(), -kG, 1e-12);
  const dm::Vec3 com0 = body->centerOfMass();
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(body->step(0.01));
  const dm::Vec3 local = body->centerOfMass() - com0;
  double maxDisplacement = 0;
  for (std::size_t i = 0; i < body->nodeCount(); ++i)
    maxDisplacement = std::max(maxDisplacement, (body->positions()[i] - body->restPositions()[i]).norm());

  // The scene's sag, in the world: the local −y is the world −z.
  const dm::Vec3 sag = vec(b.at("center_of_mass_displacement_m"));
  ASSERT_LT(local.y(), 0.0);
  EXPECT_NEAR(sag.z(), local.y(), 1e-12 * std::abs(local.y())) << sag.transpose();
  EXPECT_NEAR(sag.x(), local.x(), 1e-15);
  EXPECT_NEAR(sag.y(), -local.z(), 1e-15);
  EXPECT_NEAR(b.at("max_displacement_m").get<double>(), maxDisplacement, 1e-12 * maxDisplacement);
  // Euler–Bernoulli for the tip, q L⁴ / (8 E I) = 1.47 mm: the centre of
  // mass of a cantilever under uniform load sags 0.4 × the tip's deflection
  // (∫₀ᴸ w dx / L with w = q x²(6L² − 4Lx + x²)/(24 E I)); four linear
  // tetrahedra across are stiffer than the beam (Tests/DMPhysics/fem_test
  // measures the convergence), so the sag lies below it, and above half.
  const double I = 0.01 * 0.01 * 0.01 * 0.01 / 12.0, q = mass / 0.1 * kG;
  const double comBeam = 0.4 * q * std::pow(0.1, 4) / (8.0 * kBeamE * I);
  EXPECT_LT(-sag.z(), comBeam);
  EXPECT_GT(-sag.z(), 0.5 * comBeam);
  // At rest the held face carries the weight: held + weight = 0.
  const dm::Vec3 held = vec(b.at("held_force_N")), weight = vec(b.at("weight_N"));
  EXPECT_NEAR(weight.z(), -mass * kG, 1e-9);
  EXPECT_LE((held + weight).norm(), 1e-3 * mass * kG) << held.transpose();
}

TEST(SceneSoft, TissuePressHandFeelsWhatTheTissueFeels) {
  const json s = runScene(tissuePress(), 4.0, dm::test::TempDir("soft_press").path());
  const json& pad = softBody(s, "pad");
  EXPECT_GE(pad.at("tets").get<int>(), 5000);
  EXPECT_EQ(pad.at("unconverged_steps").get<int>(), 0);
  EXPECT_GT(pad.at("gripped_steps").get<int>(), 300);  // pressed from about 0.44 s on, 100 steps a second
  // At rest the hand feels the tissue's force on the tool (Newton's third
  // law across the haptic and physics threads), to 1 %.
  const dm::Vec3 hand = vec(s.at("haptics").at("final_force_N"));
  const dm::Vec3 onTissue = vec(pad.at("tool_force_N"));
  ASSERT_GT(hand.z(), 0.5) << "the stylus no longer presses";
  EXPECT_LE((hand + onTissue).norm(), 0.01 * hand.norm())
      << hand.transpose() << " vs " << onTissue.transpose();
  // The held bottom carries the push and the weight: held + tool + weight = 0.
  const dm::Vec3 held = vec(pad.at("held_force_N")), weight = vec(pad.at("weight_N"));
  EXPECT_NEAR(weight.z(), -0.06 * 0.06 * 0.03 * 1000 * kG, 1e-9);
  EXPECT_LE((held + onTissue + weight).norm(), 0.01 * (onTissue.norm() + weight.norm()))
      << held.transpose() << " vs " << (onTissue + weight).transpose();
  // The stylus ends 8 mm below the pad's top: the god-object's spring
  // (500 N/m) stretches by F/k, the rest is the tissue's dimple.
  const double stretch = hand.norm() / 500.0;
  EXPECT_GT(pad.at("max_displacement_m").get<double>(), 0.008 - stretch - 1e-3);
  EXPECT_LT(pad.at("max_displacement_m").get<double>(), 0.012);
}

TEST(SceneSoft, LockstepRunsAreBitIdentical) {
  const dm::SceneDesc scene = tissuePress();
  const dm::test::TempDir dir("soft_rerun");
  const json sa = runScene(scene, 1.5, dir / "a");
  const json sb = runScene(scene, 1.5, dir / "b");
  EXPECT_EQ(fileText(dir / "a" / "forces.csv"), fileText(dir / "b" / "forces.csv"));
  EXPECT_EQ(sa.at("physics"), sb.at("physics"));
  EXPECT_GT(softBody(sa, "pad").at("gripped_steps").get<int>(), 0);  // pressed by then
}

TEST(SceneSoft, AModelThatCannotBeBuiltFailsBeforeAnythingRuns) {
  // More tetrahedra than max_tets: the run fails naming the object's soft
  // block, and no output folder is left behind.
  dm::SceneDesc scene = tissuePress();
  for (dm::SceneObject& o : scene.objects)
    if (o.soft) o.soft->maxTets = 1000;
  const dm::test::TempDir dir("soft_never");
  const fs::path out = dir / "out";
  auto rt = dm::SceneRuntime::create(scene);
  ASSERT_TRUE(rt) << rt.error();
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 1.0, .outDir = out});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().where.find("objects/pad/soft"), std::string::npos) << r.error();
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace scene_soft_test

namespace scene_soft_test {

// The bundled needle insertion (examples/scenes/needle_insertion.json)
// without its render engine.
dm::SceneDesc needleInsertion() { return scene_run::bundledScene("needle_insertion.json"); }

// One haptic tick of a force trace: time, the force on the hand along z
// and the tip's depth below the block's top (30 mm; the tip is 40 mm below
// the device point).
struct NeedleTick {
  double t, fz, depth;
};
std::vector<NeedleTick> needleTrace(const fs::path& csv) {
  std::vector<NeedleTick> out;
  std::istringstream in(fileText(csv));
  std::string line;
  std::getline(in, line);  // t,fx,fy,fz,tx,ty,tz,px,py,pz,…
  while (std::getline(in, line)) {
    double v[10];
    if (std::sscanf(line.c_str(), "%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf", &v[0], &v[1], &v[2], &v[3],
                    &v[4], &v[5], &v[6], &v[7], &v[8], &v[9]) != 10)
      break;
    out.push_back({v[0], v[3], 0.03 - (v[9] - 0.04)});
  }
  return out;
}

TEST(SceneNeedle, LayeredInsertionPopsAtEachMembraneAndReleasesOnRetraction) {
  const dm::test::TempDir dir("soft_needle");
  const json s = runScene(needleInsertion(), 6.4, dir.path());
  const json& block = softBody(s, "block");
  const json& n = block.at("needle");
  // Down to 22 mm: the skin's and the muscle's fascia broke (fat has no
  // membrane); back out: the tip is outside and nothing holds the shaft.
  EXPECT_EQ(n.at("punctures").get<int>(), 2) << n.dump();
  EXPECT_EQ(n.at("tip").get<std::string>(), "outside");
  EXPECT_EQ(n.at("active_couplings").get<int>(), 0);
  EXPECT_GT(n.at("track_points").get<int>(), 5);  // the track it cut stays
  EXPECT_EQ(s.at("haptics").at("renderer"), "needle");
  // The pops, in the trace the hand felt: a fall of more than 0.2 N in one
  // tick while going in. The first is the skin's, at its 1.2 N threshold
  // (felt in the tick the tip's force reaches it, so just under) after the
  // skin tented in; the second the fascia's, 15 mm down, tented in too.
  const std::vector<NeedleTick> trace = needleTrace(dir.path() / "forces.csv");
  ASSERT_GT(trace.size(), 6000u);
  std::vector<std::size_t> pops;
  for (std::size_t i = 1; i < trace.size() && trace[i].t < 3.2; ++i)
    if (trace[i - 1].fz - trace[i].fz > 0.2 &&
        (pops.empty() || trace[i].depth > trace[pops.back()].depth + 0.005))
      pops.push_back(i);
  ASSERT_EQ(pops.size(), 2u);
  const NeedleTick& skin = trace[pops[0] - 1];
  EXPECT_NEAR(skin.fz, 1.2, 0.02) << "at t = " << skin.t;
  EXPECT_GT(skin.depth, 0.001);
  EXPECT_LT(skin.depth, 0.015);
  const NeedleTick& fascia = trace[pops[1] - 1];
  EXPECT_GT(fascia.depth, 0.015);
  EXPECT_LT(fascia.depth, 0.022);
  // Going in the tissue resists (force up on the hand), coming out the
  // shaft's friction holds it back (force down).
  for (const NeedleTick& k : trace) {
    if (k.t > 1.2 && k.t < 3.15) {
      EXPECT_GT(k.fz, 0.0) << "at t = " << k.t;
    }
    if (k.t > 3.5 && k.t < 5.0) {
      EXPECT_LT(k.fz, 0.0) << "at t = " << k.t;
    }
  }
}

TEST(SceneNeedle, LockstepRunsAreBitIdentical) {
  const dm::SceneDesc scene = needleInsertion();
  const dm::test::TempDir dir("soft_needle_rerun");
  const json sa = runScene(scene, 2.0, dir / "a");
  const json sb = runScene(scene, 2.0, dir / "b");
  EXPECT_EQ(fileText(dir / "a" / "forces.csv"), fileText(dir / "b" / "forces.csv"));
  EXPECT_EQ(sa.at("physics"), sb.at("physics"));
  EXPECT_EQ(softBody(sa, "block").at("needle").at("punctures").get<int>(), 1);  // through the skin by then
}

}  // namespace scene_soft_test

namespace scene_soft_test {

// A 40 × 40 × 10 mm pad of tissue (its faces `fixed` held) above a static
// object under gravity (no haptics).
dm::SceneDesc padOn(const std::string& support, const std::string& supportPose, const std::string& fixed) {
  const std::string text = R"({
    "format": "dmplatform-scene", "version": 2, "name": "pad_on",
    "resources": {
      "table": {"type": "shape", "shape": "plane", "half_extents": [0.1, 0.1]},
      "ball": {"type": "shape", "shape": "sphere", "radius": 0.02, "subdivisions": 4},
      "pad": {"type": "shape", "shape": "box", "half_extents": [0.02, 0.02, 0.005]}
    },
    "objects": [
      {"name": "support", "mesh": ")" +
                           support + R"(", "pose": )" + supportPose + R"(},
      {"name": "pad", "mesh": "pad", "pose": {"position": [0, 0, 0.0055]},
       "soft": {"youngs_modulus": 2e4, "density": 1000, "damping": {"alpha": 20, "beta": 0.005},
                "voxel_size": 0.0025, "fixed": )" +
                           fixed + R"(}}
    ],
    "engines": {"physics": {"rate_hz": 100}},
    "outputs": {"summary": true}
  })";
  return scene_run::parsedScene(text, "pad_on.json");
}

TEST(SceneSoft, TissueRestsOnATableThatCarriesItsWeight) {
  // Dropped 0.5 mm onto a table, nothing held: at rest the table carries
  // the pad's weight, to 1 %.
  const json s = runScene(padOn("table", R"({"position": [0, 0, 0]})", "[]"), 1.5,
                          dm::test::TempDir("soft_on_table").path());
  const json& pad = softBody(s, "pad");
  ASSERT_TRUE(pad.contains("obstacles")) << pad.dump(2);
  const json& ob = pad.at("obstacles").at(0);
  EXPECT_EQ(ob.at("name"), "support");
  const dm::Vec3 weight = vec(pad.at("weight_N"));
  EXPECT_NEAR(weight.z(), -0.04 * 0.04 * 0.01 * 1000 * kG, 1e-9);
  const dm::Vec3 onTable = vec(ob.at("force_N"));
  EXPECT_LE((onTable - weight).norm(), 0.01 * weight.norm()) << onTable.transpose();
  EXPECT_EQ(pad.at("fixed_nodes").get<int>(), 0);
  EXPECT_GT(pad.at("obstacle_contacts").get<int>(), 0);
  // It fell the 0.5 mm gap and sank a little into the penalty springs
  // (about its weight / (nodes × stiffness): µm).
  const double drop = -vec(pad.at("center_of_mass_displacement_m")).z();
  EXPECT_GT(drop, 0.0004);
  EXPECT_LT(drop, 0.0006);
}

TEST(SceneSoft, ABallHoldsUpATissueHeldAtItsEnds) {
  // A curved support: the pad held at its −x and +x faces sags under its
  // weight onto a ball whose top is 1 mm into its underside. At rest the
  // tissue is in equilibrium: what the ball takes from it is what the ends
  // hold plus the weight, to 1 %; the ball carries part of the weight, and
  // the pad sags less than with the ball out of reach.
  const json s = runScene(padOn("ball", R"({"position": [0, 0, -0.0195]})", R"(["-x", "+x"])"), 1.5,
                          dm::test::TempDir("soft_on_ball").path());
  const json& pad = softBody(s, "pad");
  ASSERT_TRUE(pad.contains("obstacles")) << pad.dump(2);
  const dm::Vec3 onBall = vec(pad.at("obstacles").at(0).at("force_N"));
  const dm::Vec3 held = vec(pad.at("held_force_N")), weight = vec(pad.at("weight_N"));
  EXPECT_LE((onBall - (held + weight)).norm(), 0.01 * onBall.norm())
      << onBall.transpose() << " vs " << (held + weight).transpose();
  EXPECT_LT(onBall.z(), -0.05 * weight.norm()) << onBall.transpose();
  EXPECT_GT(onBall.z(), weight.z());
  EXPECT_GT(pad.at("obstacle_contacts").get<int>(), 0);
  const json free = runScene(padOn("ball", R"({"position": [0, 0, -0.5]})", R"(["-x", "+x"])"), 1.5,
                             dm::test::TempDir("soft_off_ball").path());
  const json& alone = softBody(free, "pad");
  EXPECT_EQ(alone.at("obstacle_contacts").get<int>(), 0);
  const double sagOn = -vec(pad.at("center_of_mass_displacement_m")).z();
  const double sagOff = -vec(alone.at("center_of_mass_displacement_m")).z();
  EXPECT_GT(sagOff, 0.0);
  EXPECT_LT(sagOn, sagOff) << "the ball does not hold the pad up";
  // Without the ball the ends carry all the weight.
  EXPECT_LE((vec(alone.at("held_force_N")) + weight).norm(), 0.01 * weight.norm());
}

}  // namespace scene_soft_test

namespace scene_soft_test {

// The bundled needle scene with its layers from a label volume written
// beside it: 1 mm voxels over the block, labelled by depth below its top
// as the slabs are (skin 5 mm, fat 10 mm, muscle), or with `gap` a depth
// range left as background (label 0).
dm::Result<dm::SceneDesc> needleByLabels(const fs::path& dir, double gapFrom = 1.0, double gapTo = 1.0) {
  auto v = dm::Volume::create({40, 40, 30}, dm::VoxelType::U8,
                              Eigen::Translation3d(-0.0195, -0.0195, 0.0005) * Eigen::Scaling(0.001));
  if (!v) return v.error();
  for (int k = 0; k < 30; ++k)
    for (int j = 0; j < 40; ++j)
      for (int i = 0; i < 40; ++i) {
        const double depth = 0.03 - (0.0005 + 0.001 * k);
        const int label = depth >= gapFrom && depth < gapTo ? 0 : depth < 0.005 ? 1 : depth < 0.015 ? 2 : 3;
        v->setValue(i, j, k, label);
      }
  if (auto s = dm::writeNifti(*v, dir / "layers.nii"); !s) return s.error();
  auto text =
      dm::readFile(fs::path(dm::test::besideExecutable(DM_EXAMPLE_SCENES_DIR)) / "needle_insertion.json");
  if (!text) return text.error();
  json j = json::parse(std::string(reinterpret_cast<const char*>(text->data()), text->size()), nullptr, true,
                       true);
  j["resources"]["layers"] = {{"type", "volume"}, {"source", "layers.nii"}};
  json& soft = j["objects"][0]["soft"];
  soft["labels"] = "layers";
  for (std::size_t i = 0; i < 3; ++i) {
    soft["layers"][i].erase("thickness");
    soft["layers"][i]["label"] = i + 1;
  }
  std::vector<dm::Error> problems;
  auto s = dm::parseScene(j.dump(), "needle_labels.json", dir, &problems);
  if (!s)
    return dm::fail(dm::ErrorCode::InvalidArgument, dm::formatSceneErrors(problems), "needle_labels.json");
  s->engines.render.reset();
  s->outputs.frames = false;
  s->outputs.plot = false;
  return s;
}

TEST(SceneNeedle, LayersFromALabelVolumeAreTheSlabsItLabels) {
  // A label map that labels the slabs' depths gives every tetrahedron the
  // same layer: the same run, to the byte.
  const dm::test::TempDir dir("soft_needle_labels");
  auto byLabels = needleByLabels(dir.path());
  ASSERT_TRUE(byLabels) << byLabels.error();
  const json a = runScene(*byLabels, 3.0, dir / "labels");
  const json b = runScene(needleInsertion(), 3.0, dir / "slabs");
  EXPECT_EQ(fileText(dir / "labels" / "forces.csv"), fileText(dir / "slabs" / "forces.csv"));
  EXPECT_EQ(softBody(a, "block").at("needle").at("punctures").get<int>(), 2);
  EXPECT_EQ(a.at("physics"), b.at("physics"));
}

TEST(SceneNeedle, ATissueOnALabelNoLayerNamesFailsBeforeAnythingRuns) {
  // Background (label 0) inside the block between 20 and 25 mm down: no
  // layer names it, and the run fails at the object's labels, leaving no
  // output folder.
  const dm::test::TempDir dir("soft_needle_gap");
  auto scene = needleByLabels(dir.path(), 0.020, 0.025);
  ASSERT_TRUE(scene) << scene.error();
  auto rt = dm::SceneRuntime::create(*scene);
  ASSERT_TRUE(rt) << rt.error();
  const fs::path out = dir / "out";
  auto r = (*rt)->run({.mode = dm::RunMode::Lockstep, .duration = 1.0, .outDir = out});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().where.find("objects/block/soft/labels"), std::string::npos) << r.error();
  EXPECT_NE(r.error().what.find("no layer names"), std::string::npos) << r.error();
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace scene_soft_test

namespace scene_soft_test {

TEST(SceneSoft, AFixedBoxAroundAFaceHoldsWhatTheFaceDoes) {
  // The cantilever held by a box around its −x end face (object frame,
  // before the scale of 2) instead of by the face: the same nodes, the
  // same run.
  dm::SceneDesc byBox = cantilever();
  dm::SceneSoft& soft = *byBox.objects[0].soft;
  soft.fixedFaces = 0;
  soft.fixedBoxes.push_back({dm::Vec3(-0.026, -0.01, -0.01), dm::Vec3(-0.0249, 0.01, 0.01)});
  const dm::test::TempDir dir("soft_fixed_box");
  const json a = runScene(byBox, 1.0, dir / "box");
  const json b = runScene(cantilever(), 1.0, dir / "face");
  EXPECT_EQ(softBody(a, "beam").at("fixed_nodes").get<int>(), 25);
  EXPECT_EQ(a.at("physics").at("soft"), b.at("physics").at("soft"));
}

TEST(SceneSoft, AHierarchicalPadRestsOnTheTableWithFewerTetrahedra) {
  // The pad on the table at 1.25 mm voxels (32 × 32 × 8: 49,152
  // tetrahedra on a uniform grid) with cells of up to 4 voxels away from a
  // fine region at its top centre: about a tenth of them (5,136), hanging
  // nodes where fine meets coarse, and the table still carries the weight,
  // to 1 %.
  dm::SceneDesc scene = padOn("table", R"({"position": [0, 0, 0]})", "[]");
  dm::SceneSoft& soft = *scene.objects[1].soft;
  soft.voxelSize = 0.00125;  // 32 × 32 × 8 voxels
  soft.levels = 2;
  soft.fineRegion = dm::SceneBox{dm::Vec3(-0.004, -0.004, 0.004), dm::Vec3(0.004, 0.004, 0.005)};
  const json s = runScene(scene, 1.5, dm::test::TempDir("soft_hier").path());
  const json& pad = softBody(s, "pad");
  EXPECT_LT(pad.at("tets").get<int>(), 32 * 32 * 8 * 6 / 5) << "no coarser cells";
  const dm::Vec3 weight = vec(pad.at("weight_N"));
  const dm::Vec3 onTable = vec(pad.at("obstacles").at(0).at("force_N"));
  EXPECT_LE((onTable - weight).norm(), 0.01 * weight.norm()) << onTable.transpose();
  EXPECT_NEAR(pad.at("mass_kg").get<double>(), 0.04 * 0.04 * 0.01 * 1000, 1e-9);  // the cells cover the box
  EXPECT_EQ(pad.at("unconverged_steps").get<int>(), 0);
}

}  // namespace scene_soft_test

namespace scene_soft_test {

TEST(SceneSoft, TissueFromASegmentationRestsOnTheTableLikeTheSameBox) {
  // A segmentation (2 mm voxels, a 20 × 20 × 10 mm block of ones in zeros)
  // made tissue by its threshold, on its own grid: the block's voxels, six
  // tetrahedra each, as many as the same box shape split at 2 mm; dropped
  // 0.5 mm onto a table, it rests with the table carrying its weight (1 %),
  // as the box does.
  const dm::test::TempDir dir("soft_from_volume");
  auto v = dm::Volume::create({14, 14, 9}, dm::VoxelType::U8,
                              Eigen::Translation3d(-0.013, -0.013, -0.003) * Eigen::Scaling(0.002));
  ASSERT_TRUE(v) << v.error();
  for (int k = 2; k < 7; ++k)  // voxel centres z = 1 … 9 mm: cells [0, 10] mm
    for (int j = 2; j < 12; ++j)
      for (int i = 2; i < 12; ++i) v->setValue(i, j, k, 1);
  ASSERT_TRUE(dm::writeNifti(*v, dir / "block.nii"));
  const auto scene = [&](const std::string& soft, const std::string& mesh) {
    const std::string text = R"({
      "format": "dmplatform-scene", "version": 2, "name": "from_volume",
      "resources": {
        "table": {"type": "shape", "shape": "plane", "half_extents": [0.1, 0.1]},
        "seg": {"type": "volume", "source": "block.nii"},
        "skin": {"type": "isosurface", "volume": "seg", "level": 0.5},
        "box": {"type": "shape", "shape": "box", "half_extents": [0.01, 0.01, 0.005]}
      },
      "objects": [
        {"name": "table", "mesh": "table"},
        {"name": "pad", "mesh": ")" +
                             mesh + R"(", "pose": {"position": [0, 0, )" +
                             (mesh == "box" ? "0.0055" : "0.0005") + R"(]},
         "soft": {"youngs_modulus": 2e4, "density": 1000, "damping": {"alpha": 20, "beta": 0.005}, )" +
                             soft +
                             R"(}}
      ],
      "engines": {"physics": {"rate_hz": 100}},
      "outputs": {"summary": true}
    })";
    std::vector<dm::Error> problems;
    auto s = dm::parseScene(text, "from_volume.json", dir.path(), &problems);
    EXPECT_TRUE(s) << dm::formatSceneErrors(problems);
    return s ? *s : dm::SceneDesc{};
  };
  const json fromVolume =
      runScene(scene(R"("volume": "seg", "threshold": 0.5)", "skin"), 2.0, dir / "volume");
  const json fromBox = runScene(scene(R"("voxel_size": 0.002)", "box"), 2.0, dir / "box");
  const json& a = softBody(fromVolume, "pad");
  const json& b = softBody(fromBox, "pad");
  EXPECT_EQ(a.at("tets").get<int>(), 10 * 10 * 5 * 6);
  EXPECT_EQ(a.at("tets"), b.at("tets"));
  EXPECT_NEAR(a.at("mass_kg").get<double>(), 0.02 * 0.02 * 0.01 * 1000, 1e-12);
  for (const json* pad : {&a, &b}) {
    const dm::Vec3 weight = vec(pad->at("weight_N"));
    const dm::Vec3 onTable = vec(pad->at("obstacles").at(0).at("force_N"));
    EXPECT_LE((onTable - weight).norm(), 0.01 * weight.norm()) << onTable.transpose();
  }
  // The same fall and the same sinking into the table.
  EXPECT_NEAR(vec(a.at("center_of_mass_displacement_m")).z(), vec(b.at("center_of_mass_displacement_m")).z(),
              2e-6);
}

}  // namespace scene_soft_test
