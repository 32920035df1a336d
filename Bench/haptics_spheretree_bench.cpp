// haptics_spheretree_bench — tick rate of the 6-DOF sphere-tree renderer
// (dm::SphereTree6DofRenderer) at tool levels 3, 4 and 5 in a contact-rich
// scene, and the collision step of the same ticks done with FCL 0.7
// (BVHModel<OBBRSSd> collide with contacts + distance between the meshes).
//
//   haptics_spheretree_bench [ticks] [envIcosphereLevel] [surfaceTolerance] [soft]
//
// Defaults: 20000 ticks, icosphere level 5 (20480 triangles), surface
// patches at the renderer's default tolerance 0.1 (0 = spheres only, the
// published method), the soft tooth rows on (soft 0: off). Scene: a
// "tooth" (icosphere of radius 10 mm, fitted sphere tree of 6 levels) and a
// dental-probe-like tool (a ball tip of radius 1.5 mm on a 12 mm square
// shaft, fitted tree of 6 levels); the handle is pressed 1 mm into the tooth
// and slides over it on a Lissajous path while the probe tilts by up to
// ±0.3 rad, so most ticks carry many contacts. Each tick is timed in
// thread CPU time (a loaded machine's waits do not count) into a
// dm::LatencyHistogram (mean, p99, achieved rate =
// 1/mean). The FCL row replays the graphic poses our run produced: per tick
// one fcl::collide with contacts (up to 256) and one fcl::distance between
// the tool and tooth meshes, i.e. only the collision step; ratio = dm full
// tick / FCL collision step (below 1: dm's whole tick is faster than FCL's
// collision query alone). One thread. Then the same scene with a soft
// tooth (the seed reports 1.5 kHz with deformation; goal ≥ 2 kHz at tool
// level 4): our tick including the deformation step against FCL refitting
// its tree to the deformed mesh before colliding.
#include <dm/collide/sphere_tree.hpp>
#include <dm/core/rt_loop.hpp>
#include <dm/haptics/sphere_tree_6dof.hpp>
#include <dm/haptics/sphere_tree_deformation.hpp>
#include <dm/math/primitives.hpp>

#include <fcl/fcl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <memory>
#include <vector>

namespace {

using dm::Isometry3;
using dm::Vec3;

// FCL's OBBRSS tree over the same triangles (one addTriangle per face).
std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> fclModel(const dm::Mesh& mesh) {
  auto bvh = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  bvh->beginModel(static_cast<int>(mesh.triangles.size()), static_cast<int>(mesh.positions.size()));
  for (const auto& f : mesh.triangles)
    bvh->addTriangle(mesh.positions[f[0]], mesh.positions[f[1]], mesh.positions[f[2]]);
  bvh->endModel();
  return bvh;
}

// The same, with shared vertices (addSubModel), so that a deformed copy of
// the mesh's positions can replace them and refit the tree.
std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> fclIndexedModel(const dm::Mesh& mesh) {
  auto bvh = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  std::vector<fcl::Triangle> tris;
  tris.reserve(mesh.triangles.size());
  for (const auto& f : mesh.triangles) tris.emplace_back(f[0], f[1], f[2]);
  bvh->beginModel(static_cast<int>(mesh.triangles.size()), static_cast<int>(mesh.positions.size()));
  bvh->addSubModel(mesh.positions, tris);
  bvh->endModel();
  return bvh;
}

// Ball tip at the origin, square shaft along +z.
dm::Mesh probeMesh() {
  dm::Mesh tip = dm::makeIcosphere(0.0015, 3);
  dm::Mesh shaft = dm::makeBox(Vec3(0.0006, 0.0006, 0.006));
  shaft.transform(dm::Affine3(Eigen::Translation3d(0, 0, 0.0072)));
  tip.append(shaft);
  tip.normals.clear();  // per-vertex attributes are optional; the tree needs positions only
  tip.uvs.clear();
  tip.colors.clear();
  return tip;
}

// Handle pose of tick i: tip 1 mm inside the tooth surface, shaft outward.
Isometry3 handlePose(int i) {
  const double t = i * 1e-3;
  const double th = 0.6 + 0.35 * std::sin(0.9 * t), ph = 1.3 * t;
  const Vec3 radial(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th));
  Isometry3 p = Isometry3::Identity();
  const dm::Quat align = dm::Quat::FromTwoVectors(Vec3::UnitZ(), radial);
  p.linear() = (dm::AngleAxis(0.3 * std::sin(2.1 * t), radial.unitOrthogonal()) * align).toRotationMatrix();
  p.translation() = (0.010 + 0.0015 - 0.001) * radial;
  return p;
}

// Thread CPU time (ns): unlike wall time it does not count the time this
// thread waits while other processes run on a shared machine.
std::int64_t cpuNs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return std::int64_t{ts.tv_sec} * 1000000000 + ts.tv_nsec;
}

// Puts the renderer's tool above the surface and warms it up along the
// first 200 ticks of the path.
void startOnPath(dm::SphereTree6DofRenderer& ren) {
  Isometry3 start = handlePose(0);
  start.translation() *= 1.3;
  ren.reset(start);
  for (int i = 0; i < 200; ++i) (void)ren.tick({.dt = 1e-3, .devicePose = handlePose(i)});
}

fcl::Transform3d toFcl(const Isometry3& p) {
  fcl::Transform3d f = fcl::Transform3d::Identity();
  f.linear() = p.linear();
  f.translation() = p.translation();
  return f;
}

// The peer's collision step: collide (up to 256 contacts) and distance
// between the tool at `pose` and the environment at the origin; the contact count.
std::size_t fclQuery(const std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>>& tool, const Isometry3& pose,
                     const std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>>& env) {
  fcl::CollisionObjectd oa(tool, toFcl(pose)), ob(env, fcl::Transform3d::Identity());
  fcl::CollisionRequestd creq(256, true);
  fcl::CollisionResultd cres;
  fcl::collide(&oa, &ob, creq, cres);
  fcl::DistanceRequestd dreq(true);
  fcl::DistanceResultd dres;
  fcl::distance(&oa, &ob, dreq, dres);
  return cres.numContacts();
}

}  // namespace

int main(int argc, char** argv) {
  const int ticks = argc > 1 ? std::max(100, std::atoi(argv[1])) : 20000;
  const int envLevel = argc > 2 ? std::clamp(std::atoi(argv[2]), 1, 7) : 5;
  const double surfaceTolerance = argc > 3 ? std::max(0.0, std::atof(argv[3])) : 0.1;
  const bool soft = argc <= 4 || std::atoi(argv[4]) != 0;
  const dm::Mesh tooth = dm::makeIcosphere(0.010, envLevel);
  const dm::Mesh probe = probeMesh();
  const auto t0 = std::chrono::steady_clock::now();
  auto toothTree = dm::buildSphereTreeFitted(tooth, {.levels = 6});
  auto probeTree = dm::buildSphereTreeFitted(probe, {.levels = 6});
  if (!toothTree || !probeTree) {
    std::fprintf(stderr, "sphere tree build failed: %s\n",
                 (!toothTree ? toothTree.error() : probeTree.error()).message().c_str());
    return 1;
  }
  std::printf(
      "haptics_spheretree_bench: %d ticks; tooth icosphere level %d (%zu triangles, %zu leaf spheres), "
      "probe %zu triangles; trees built in %.2f s\n",
      ticks, envLevel, tooth.triangles.size(), (*toothTree)->level(5).size(), probe.triangles.size(),
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  auto fTooth = fclModel(tooth), fProbe = fclModel(probe);

  std::printf("%-6s %8s %10s %10s %10s %10s %9s %9s %12s %12s %8s\n", "level", "spheres", "mean_us", "p99_us",
              "max_us", "rate_kHz", "cand", "contacts", "fcl_mean_us", "fcl_p99_us", "ratio");
  for (int level : {3, 4, 5}) {
    auto r = dm::SphereTree6DofRenderer::create(*probeTree, {{.tree = *toothTree, .name = "tooth"}},
                                                {.toolLevel = level, .surfaceTolerance = surfaceTolerance});
    if (!r) {
      std::fprintf(stderr, "%s\n", r.error().message().c_str());
      return 1;
    }
    dm::SphereTree6DofRenderer& ren = **r;
    startOnPath(ren);
    std::vector<Isometry3> graphic(static_cast<std::size_t>(ticks));
    dm::LatencyHistogram ours, peer;
    double candidates = 0, contacts = 0, depth = 0;
    for (int i = 0; i < ticks; ++i) {
      graphic[static_cast<std::size_t>(i)] = ren.graphicPose();
      const dm::HapticInput in{.timeNs = i * 1000000LL, .dt = 1e-3, .devicePose = handlePose(200 + i)};
      const std::int64_t a = cpuNs();
      const dm::HapticResponse out = ren.tick(in);
      ours.record(cpuNs() - a);
      candidates += static_cast<double>(ren.lastCandidateCount());
      contacts += out.contacts;
      depth += out.penetration;
    }
    long fclContacts = 0;
    for (int i = 0; i < ticks; ++i) {
      const std::int64_t a = cpuNs();
      const std::size_t n = fclQuery(fProbe, graphic[static_cast<std::size_t>(i)], fTooth);
      peer.record(cpuNs() - a);
      fclContacts += static_cast<long>(n);
    }
    const dm::LatencyHistogram::Summary s = ours.summary(), f = peer.summary();
    std::printf("%-6d %8zu %10.2f %10.2f %10.2f %10.2f %9.1f %9.1f %12.2f %12.2f %8.3f\n", level,
                ren.toolSphereCount(), s.mean_us, s.p99_us, s.max_us, 1e3 / s.mean_us, candidates / ticks,
                contacts / ticks, f.mean_us, f.p99_us, s.mean_us / f.mean_us);
    std::printf("       (mean handle-tool distance %.3f mm; FCL triangle contacts per tick %.1f)\n",
                1e3 * depth / ticks, static_cast<double>(fclContacts) / ticks);
  }
  std::printf("rate_kHz = 1/mean tick; goal >= 2 kHz at level 4. ratio = dm tick / FCL collide+distance.\n");
  if (!soft) return 0;

  // A soft tooth: the same scene with the tooth a spring network on level 2
  // or 3 of its tree (dm::SphereTreeDeformation), tool level 4. The tick now
  // also steps the network and moves the tree. FCL has no deformation: its
  // row refits the OBBRSS tree to the deformed triangles (our skinning of
  // the mesh, untimed) and then collides and measures distance.
  const int softTicks = std::min(ticks, 2000);  // FCL's refit takes tens of ms a tick
  std::printf(
      "\nsoft tooth (anchor 200 N/m, links 500 N/m), tool level 4, %d ticks:\n%-9s %8s %10s %10s %10s %10s "
      "%9s %12s %12s %8s %12s\n",
      softTicks, "skeleton", "nodes", "mean_us", "p99_us", "max_us", "rate_kHz", "contacts", "fcl_mean_us",
      "fcl_p99_us", "ratio", "max_dent_mm");
  for (int skeletonLevel : {2, 3}) {
    auto def = dm::SphereTreeDeformation::create(
        *toothTree,
        {.skeletonLevel = skeletonLevel, .mass = 0.02, .anchorStiffness = 200, .linkStiffness = 500});
    if (!def) {
      std::fprintf(stderr, "%s\n", def.error().message().c_str());
      return 1;
    }
    auto r = dm::SphereTree6DofRenderer::create(*probeTree,
                                                {{.tree = *toothTree, .name = "tooth", .deformation = *def}},
                                                {.toolLevel = 4, .surfaceTolerance = surfaceTolerance});
    if (!r) {
      std::fprintf(stderr, "%s\n", r.error().message().c_str());
      return 1;
    }
    dm::SphereTree6DofRenderer& ren = **r;
    startOnPath(ren);
    const dm::SphereTreeDeformation::Binding binding = (*def)->bind(tooth.positions);
    std::vector<Vec3> deformed(tooth.positions.size());
    auto fSoft = fclIndexedModel(tooth);
    dm::LatencyHistogram ours, peer;
    double contacts = 0, dent = 0;
    for (int i = 0; i < softTicks; ++i) {
      const dm::HapticInput in{.timeNs = i * 1000000LL, .dt = 1e-3, .devicePose = handlePose(200 + i)};
      const std::int64_t a = cpuNs();
      const dm::HapticResponse out = ren.tick(in);
      ours.record(cpuNs() - a);
      contacts += out.contacts;
      (*def)->deform(binding, tooth.positions, deformed);
      for (std::size_t v = 0; v < deformed.size(); v += 97)
        dent = std::max(dent, (deformed[v] - tooth.positions[v]).norm());
      const Isometry3 g = ren.graphicPose();
      const std::int64_t b = cpuNs();
      fSoft->beginReplaceModel();
      for (const Vec3& p : deformed) fSoft->replaceVertex(p);
      fSoft->endReplaceModel(true, true);  // refit, bottom-up
      (void)fclQuery(fProbe, g, fSoft);
      peer.record(cpuNs() - b);
    }
    const dm::LatencyHistogram::Summary s = ours.summary(), f = peer.summary();
    std::printf("%-9d %8zu %10.2f %10.2f %10.2f %10.2f %9.1f %12.2f %12.2f %8.3f %12.3f\n", skeletonLevel,
                (*def)->skeleton().size(), s.mean_us, s.p99_us, s.max_us, 1e3 / s.mean_us,
                contacts / softTicks, f.mean_us, f.p99_us, s.mean_us / f.mean_us, 1e3 * dent);
  }
  std::printf("soft ratio = dm tick (deformation included) / FCL refit + collide + distance.\n");
  return 0;
}
