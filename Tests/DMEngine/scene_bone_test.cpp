// The bone-placement renderer in a scene (examples/scenes/osteotomy.json at
// 1 mm voxels, as examples/osteotomy on the Colin27 head): a fragment cut
// from the generated calvarium by an oblique saw plane, brought back from
// 10 mm and 15° away by a scripted hand. Sent exactly home, it ends within
// a third of a voxel of the plan, the 1 mm saw kerf open (no voxel pair
// presses) and no force left on the hand; pressed 2 mm past home into the
// fixed fragment, the
// contact closes the 1 mm kerf and holds it there (no deeper than a voxel)
// while the hand feels the virtual coupling — k_c times the offset of the
// hand's image of the centre of mass, and k_r times the rotation offset — as
// BonePlacementRenderer's rest state says. Lockstep reruns are bit-identical.
#include <dm/core/filesystem.hpp>
#include <dm/engine/scene_runtime.hpp>
#include <dm/io/scene_file.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>
#include <string>
#include <vector>

#include "../common/temp_dir.hpp"
#include "scene_run_support.hpp"

namespace scene_bone_test {

namespace fs = std::filesystem;
using dm::Vec3;

// The saw plane's normal, from the fixed side to the moving one (the scene's).
const Vec3 kNormal = Vec3(0.925417, 0.163176, -0.342020).normalized();
constexpr double kLead = 0.2, kApproach = 2.0, kHold = 1.5;

// The hand's path as the sim-haptic driver's CSV: from 8 mm out along the
// cut normal, 6 mm sideways and turned 15° about a point of the fragment, a
// minimum-jerk approach to `push` metres past the planned pose along −n.
std::string handCsv(double push) {
  const Vec3 pivot(0.0075, 0.0, -0.0035);
  const Vec3 side = kNormal.cross(Vec3::UnitZ()).normalized();
  const dm::Quat q0(dm::AngleAxis(15.0 * std::numbers::pi / 180, Vec3(0.3, 1, 0.2).normalized()));
  const Vec3 start = pivot - q0 * pivot + 8e-3 * kNormal + 6e-3 * side;
  const Vec3 goal = -push * kNormal;
  std::string csv = "t,x,y,z,qw,qx,qy,qz\n";
  for (int k = 0; k <= 370; ++k) {
    const double t = 0.01 * k, u = std::clamp((t - kLead) / kApproach, 0.0, 1.0);
    const double s = u * u * u * (10 - 15 * u + 6 * u * u);
    const Vec3 p = (1 - s) * start + s * goal;
    const dm::Quat q = q0.slerp(s, dm::Quat::Identity());
    csv += dm::formatString("%.3f,%.12g,%.12g,%.12g,%.15g,%.15g,%.15g,%.15g\n", t, p.x(), p.y(), p.z(), q.w(),
                            q.x(), q.y(), q.z());
  }
  return csv;
}

struct Placement {
  nlohmann::json summary;
  std::vector<scene_run::TraceRow> trace;
  std::string forces;  // forces.csv's bytes
};

// The bundled osteotomy scene at 1 mm voxels, the hand pressing `push` m past home.
Placement place(double push, const std::string& name) {
  const dm::test::TempDir tmp("scene_bone_" + name);
  const fs::path dir = tmp.path();
  const fs::path csv = dir / "hand.csv";
  const std::string text = handCsv(push);
  EXPECT_TRUE(dm::writeFileAtomic(csv, text.data(), text.size()));
  dm::SceneDesc scene = scene_run::bundledScene("osteotomy.json");
  for (dm::SceneResource& r : scene.resources)
    if (r.phantom) r.phantom->spacing = 0.001;
  EXPECT_EQ(scene.devices.size(), 1u);
  if (scene.devices.empty()) return {};
  scene.devices[0].files["file"] = csv;
  scene.outputs.forces = true;
  Placement run;
  run.summary = scene_run::runScene(scene, kLead + kApproach + kHold, dir / "out");
  run.forces = scene_run::fileText(dir / "out" / "forces.csv");
  run.trace = scene_run::forceTrace(dir / "out" / "forces.csv");
  return run;
}

TEST(SceneBone, SentHomeTheFragmentLiesAtThePlanAcrossTheOpenKerfWithNoForceLeft) {
  const Placement r = place(0.0, "home");
  ASSERT_TRUE(r.summary.contains("bone_placement")) << r.summary.dump(2);
  const nlohmann::json& b = r.summary["bone_placement"];
  EXPECT_GT(b["fixed_voxels"].get<int>(), 1500);
  EXPECT_GT(b["fragment_voxels"].get<int>(), 1500);
  // Bone of 1900 kg/m³ in 1 mm voxels.
  EXPECT_NEAR(b["fragment_mass_kg"].get<double>(), b["fragment_voxels"].get<double>() * 1e-9 * 1900, 1e-12);
  EXPECT_GT(b["initial_error_m"].get<double>(), 5e-3);
  EXPECT_LT(b["final_error_m"].get<double>(), 0.3e-3);
  EXPECT_EQ(b["final_contacts"].get<int>(), 0) << "voxel pairs press across the open kerf";
  EXPECT_EQ(b["stack_overflows"].get<int>(), 0);
  ASSERT_FALSE(r.trace.empty());
  EXPECT_LT(r.trace.back().force.norm(), 0.02);
}

TEST(SceneBone, PressedPastHomeTheCutHoldsAndTheHandFeelsTheCoupling) {
  const Placement r = place(2e-3, "pressed");
  ASSERT_TRUE(r.summary.contains("bone_placement")) << r.summary.dump(2);
  const nlohmann::json& b = r.summary["bone_placement"];
  // The kerf is 1 mm: the fragment closes it and stops.
  EXPECT_LT(b["final_error_m"].get<double>(), 1.5e-3);
  EXPECT_GT(b["final_error_m"].get<double>(), 0.3e-3);
  EXPECT_LT(b["max_contact_depth_m"].get<double>(), 1e-3) << "leaf spheres overlapped by more than a voxel";
  EXPECT_GE(b["final_contacts"].get<int>(), 1) << "no voxel pair holds the fragment at the cut";
  ASSERT_GT(r.trace.size(), 3000u);
  const scene_run::TraceRow& last = r.trace.back();
  EXPECT_GT(last.force.dot(kNormal), 0.2) << "the hand is pulled back out along the cut normal";
  // At rest the hand feels the coupling alone: −k_c (hand's image of the
  // centre of mass − the centre) and −k_r log(R_hand R_fragmentᵀ); the hand
  // is at −2 mm n, unturned.
  const Vec3 c = scene_run::vec(b["center_of_mass_m"]);
  const Vec3 p = scene_run::vec(b["final_position_m"]);
  const auto& q = b["final_rotation"];
  const dm::Quat rf(q[0].get<double>(), q[1].get<double>(), q[2].get<double>(), q[3].get<double>());
  const Vec3 hand = -2e-3 * kNormal;
  const Vec3 coupling = -300.0 * ((hand + c) - (rf * c + p));
  EXPECT_LT((last.force - coupling).norm(), 0.01 * coupling.norm())
      << last.force.transpose() << " vs " << coupling.transpose();
  const dm::AngleAxis turn(rf.conjugate());  // R_hand R_fragmentᵀ, R_hand = I
  const Vec3 torque = -0.3 * turn.angle() * turn.axis();
  EXPECT_LT((last.torque - torque).norm(), 0.02 * torque.norm() + 1e-6)
      << last.torque.transpose() << " vs " << torque.transpose();
}

TEST(SceneBone, LockstepRerunsAreBitIdentical) {
  const Placement a = place(2e-3, "rerun_a");
  const Placement b = place(2e-3, "rerun_b");
  ASSERT_FALSE(a.forces.empty());
  EXPECT_EQ(a.forces, b.forces);
  EXPECT_EQ(a.summary["bone_placement"], b.summary["bone_placement"]);
}

}  // namespace scene_bone_test
