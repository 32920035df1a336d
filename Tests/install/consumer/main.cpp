// A user program built against the installed SDK only: the data model and
// errors from DMCore, a mesh written and read back through DMIO (the read
// runs in the installed dm-isolate helper, <libdir>/dmplatform/), and a
// god-object pressed 2 mm into a box from DMHaptics (through DMCollide and
// DMMath), run in lockstep by DMEngine.
#include <dm/collide/bvh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/engine/master_engine.hpp>
#include <dm/haptics/god_object.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/math/primitives.hpp>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>

int main() {
  dm::Result<dm::Vec3> r = dm::Vec3(1.0, 2.0, 2.0);
  if (!r || r->norm() != 3.0) return 1;
  dm::Result<int> e = dm::fail(dm::ErrorCode::NotFound, "no such file", "x.nii", "check the path");
  std::cout << "consumer ok; sample error: " << e.error() << '\n';
  if (e) return 1;

  const dm::Mesh box = dm::makeBox(dm::Vec3(0.05, 0.05, 0.05));
  const std::filesystem::path stl =
      std::filesystem::temp_directory_path() / ("dm_consumer_" + std::to_string(::getpid()) + ".stl");
  if (auto s = dm::writeMesh(box, stl); !s) return 1;
  auto back = dm::readMesh(stl);  // Isolation::Helper, the default
  std::filesystem::remove(stl);
  if (!back) {
    std::cerr << back.error() << '\n';
    return 1;
  }
  std::cout << "read back " << back->triangleCount() << " triangles through the isolation helper\n";
  if (back->triangleCount() != box.triangleCount()) return 1;

  auto bvh = dm::MeshBvh::build(box);
  if (!bvh) return 1;
  std::vector<dm::GodObjectObject> objects(1);
  objects[0].bvh = std::make_shared<const dm::MeshBvh>(std::move(*bvh));
  objects[0].material.stiffness = 500.0;
  auto proxy = dm::GodObjectRenderer::create(std::move(objects), {});
  if (!proxy) return 1;
  dm::HapticResponse last;
  auto haptics = dm::makeFunctionEngine("haptics", [&](const dm::TickInfo& t) {
    const double z = 0.06 - 0.012 * std::min(1.0, static_cast<double>(t.index) / 100.0);  // to 2 mm deep
    dm::HapticInput in;
    in.dt = t.dt();
    in.devicePose.translation() = dm::Vec3(0, 0, z);
    if (t.index == 0) (*proxy)->reset(in.devicePose);
    last = (*proxy)->tick(in);
    return true;
  });
  dm::MasterEngine master;
  if (!master.addEngine(haptics, {.rateHz = 1000}) || !master.load() ||
      !master.start(dm::RunMode::Lockstep) || !master.advance(0.2) || !master.stop())
    return 1;
  std::cout << "god-object force " << last.force.transpose() << " N\n";
  return std::abs(last.force.z() - 1.0) < 1e-3 ? 0 : 1;  // 500 N/m x 2 mm
}
