// collide_mesh_bench — dm mesh–mesh queries (MeshBvh) against FCL 0.7
// (BVHModel<OBBRSSd>) and Bullet 3 GImpact (btGImpactMeshShape, float), on
// the same meshes and poses, one thread per query.
//
//   collide_mesh_bench [poses] [repetitions] [model] [queries]
//
// Defaults: 200 poses (fewer for the largest meshes), best of 3,
// all queries (or a comma-separated subset of build,refit,collide,contacts,
// distance; "-" for the default model),
// /usr/share/assimp/models/PLY/Wuson.ply as the real model (read with
// dm::readMesh, scaled to a 1 m box). Meshes: a torus against a UV sphere of
// about 1k, 10k and 100k triangles each, and the model against a copy of
// itself. Poses: A fixed, B at a random rotation and a random offset of up
// to 1.2 model sizes (about half of them overlapping); the same list for
// every contender. Rows:
//  - collide: boolean, first intersecting pair (dm meshMeshIntersect; FCL
//    collide with one contact, no contact data);
//  - contacts: all intersecting pairs (dm meshMeshContacts; FCL collide with
//    enable_contact and unlimited contacts; GImpact contactPairTest, whose
//    contacts come from its own triangle clipping);
//  - distance: minimum distance with closest points (dm meshMeshDistance;
//    FCL distance with nearest points) — GImpact has no mesh distance;
//  - build: tree construction from the mesh (dm MeshBvh::build inside a
//    one-thread dm::TaskPool, so that its parallel subtrees and per-node
//    boxes run serially like FCL's; FCL BVHModel begin/add/endModel), also
//    in triangles/s;
//  - refit: after moving every vertex (dm MeshBvh::refit; FCL
//    beginUpdateModel/updateSubModel/endUpdateModel, whose refit is bottom-up).
// Queries are timed in thread CPU time (best of the repetitions), so that
// other processes on a loaded machine do not count; build (one thread, see
// above) and refit (dm: all threads) in wall time. The ratio is dm time / peer time:
// below 1 means dm is faster.
#include <dm/collide/bvh.hpp>
#include <dm/collide/mesh_query.hpp>
#include <dm/core/tasks.hpp>
#include <dm/io/mesh_io.hpp>
#include <dm/math/primitives.hpp>

#include <BulletCollision/Gimpact/btGImpactCollisionAlgorithm.h>
#include <BulletCollision/Gimpact/btGImpactShape.h>
#include <btBulletCollisionCommon.h>
#include <fcl/fcl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

namespace {

using dm::Isometry3;
using dm::Vec3;

// Best of `reps` wall-clock runs of f (seconds): for the multi-threaded build.
double bestOf(int reps, const std::function<void()>& f) {
  double best = 1e300;
  for (int r = 0; r < reps; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  return best;
}

// Thread CPU seconds now: unlike wall time it does not count the time this
// thread waits while other processes run on a shared machine.
double cpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

// Best of `reps` runs of f in thread CPU time (seconds): for the one-thread queries.
double bestCpuOf(int reps, const std::function<void()>& f) {
  double best = 1e300;
  for (int r = 0; r < reps; ++r) {
    const double t0 = cpuSeconds();
    f();
    best = std::min(best, cpuSeconds() - t0);
  }
  return best;
}

// Queries selected on the command line (empty: all).
std::string gQueries;
bool wanted(const char* query) {
  return gQueries.empty() || ("," + gQueries + ",").find("," + std::string(query) + ",") != std::string::npos;
}

std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> fclModel(const dm::Mesh& m) {
  auto model = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  std::vector<fcl::Vector3d> v(m.positions.begin(), m.positions.end());
  std::vector<fcl::Triangle> t;
  t.reserve(m.triangles.size());
  for (const auto& tri : m.triangles) t.emplace_back(tri[0], tri[1], tri[2]);
  model->beginModel(static_cast<int>(t.size()), static_cast<int>(v.size()));
  model->addSubModel(v, t);
  model->endModel();
  return model;
}

// Bullet GImpact shape over its own float copy of the mesh.
struct BulletMesh {
  std::vector<btScalar> vertices;
  std::vector<int> indices;
  std::unique_ptr<btTriangleIndexVertexArray> array;
  std::unique_ptr<btGImpactMeshShape> shape;
  explicit BulletMesh(const dm::Mesh& m) {
    for (const Vec3& p : m.positions)
      for (int k = 0; k < 3; ++k) vertices.push_back(static_cast<btScalar>(p[k]));
    for (const auto& t : m.triangles)
      for (int k = 0; k < 3; ++k) indices.push_back(static_cast<int>(t[k]));
    array = std::make_unique<btTriangleIndexVertexArray>(
        static_cast<int>(m.triangles.size()), indices.data(), 3 * static_cast<int>(sizeof(int)),
        static_cast<int>(m.positions.size()), vertices.data(), 3 * static_cast<int>(sizeof(btScalar)));
    shape = std::make_unique<btGImpactMeshShape>(array.get());
    shape->updateBound();
  }
};

btTransform toBullet(const Isometry3& p) {
  const dm::Mat3 r = p.linear();
  btMatrix3x3 b(
      static_cast<btScalar>(r(0, 0)), static_cast<btScalar>(r(0, 1)), static_cast<btScalar>(r(0, 2)),
      static_cast<btScalar>(r(1, 0)), static_cast<btScalar>(r(1, 1)), static_cast<btScalar>(r(1, 2)),
      static_cast<btScalar>(r(2, 0)), static_cast<btScalar>(r(2, 1)), static_cast<btScalar>(r(2, 2)));
  const Vec3 t = p.translation();
  return btTransform(
      b, btVector3(static_cast<btScalar>(t.x()), static_cast<btScalar>(t.y()), static_cast<btScalar>(t.z())));
}

struct CountContacts : btCollisionWorld::ContactResultCallback {
  long count = 0;
  btScalar addSingleResult(btManifoldPoint&, const btCollisionObjectWrapper*, int, int,
                           const btCollisionObjectWrapper*, int, int) override {
    ++count;
    return 0;
  }
};

struct Row {
  std::string scene, query, peer;
  double ours, theirs;  // seconds per operation
  std::string note;
};

void printRows(const std::vector<Row>& rows) {
  std::printf("\n%-22s %-9s %-8s %14s %14s %8s  %s\n", "meshes", "query", "peer", "dm", "peer", "dm/peer",
              "");
  for (const Row& r : rows)
    std::printf("%-22s %-9s %-8s %12.3f us %12.3f us %8.3f  %s\n", r.scene.c_str(), r.query.c_str(),
                r.peer.c_str(), r.ours * 1e6, r.theirs * 1e6, r.ours / r.theirs, r.note.c_str());
}

void benchScene(const std::string& name, const dm::Mesh& ma, const dm::Mesh& mb, int poseCount, int reps,
                std::vector<Row>& rows) {
  const double size = std::max(ma.bounds().sizes().maxCoeff(), mb.bounds().sizes().maxCoeff());
  std::mt19937_64 rng(2024);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<Isometry3> poses;
  for (int i = 0; i < poseCount; ++i) {
    Isometry3 p = Isometry3::Identity();
    p.linear() = dm::Quat(Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng)).normalized()).toRotationMatrix();
    p.translation() = 0.7 * size * Vec3(u(rng), u(rng), u(rng));
    poses.push_back(p);
  }
  const Isometry3 pa = Isometry3::Identity();
  const std::string scene = name + " " + std::to_string(ma.triangleCount() / 1000.0).substr(0, 5) + "k";
  std::printf("%s: A %zu triangles, B %zu triangles, %d poses\n", name.c_str(), ma.triangleCount(),
              mb.triangleCount(), poseCount);

  // Build and refit.
  std::unique_ptr<dm::MeshBvh> a, b;
  const int buildReps = wanted("build") ? reps : 1;
  // One thread for the comparison with FCL's serial build: the pool's arena
  // admits a single thread, the calling one, which runs the task in wait().
  dm::TaskPool serial({.max_concurrency = 1});
  const double ourBuild = bestOf(buildReps, [&] {
    serial.submit([&] { a = std::make_unique<dm::MeshBvh>(std::move(*dm::MeshBvh::build(ma))); });
    serial.wait();
  });
  b = std::make_unique<dm::MeshBvh>(std::move(*dm::MeshBvh::build(mb)));
  std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> fa, fb;
  const double fclBuild = bestOf(buildReps, [&] { fa = fclModel(ma); });
  fb = fclModel(mb);
  char note[96];
  std::snprintf(note, sizeof note, "%.2f vs %.2f Mtri/s (both 1 thread)", ma.triangleCount() / ourBuild / 1e6,
                ma.triangleCount() / fclBuild / 1e6);
  if (wanted("build")) rows.push_back({scene, "build", "FCL", ourBuild, fclBuild, note});
  if (wanted("refit")) {
    std::vector<Vec3> moved = ma.positions;
    for (Vec3& p : moved)
      p += 0.01 * size * Vec3(std::sin(7 * p.y()), std::cos(5 * p.z()), std::sin(3 * p.x()));
    std::vector<fcl::Vector3d> fmoved(moved.begin(), moved.end());
    dm::MeshBvh copy = *a;
    const double ourRefit = bestOf(reps, [&] {
      if (!copy.refit(moved)) std::abort();
    });
    fcl::BVHModel<fcl::OBBRSSd> fcopy(*fa);
    const double fclRefit = bestOf(reps, [&] {
      fcopy.beginUpdateModel();
      fcopy.updateSubModel(fmoved);
      fcopy.endUpdateModel(true, true);
    });
    rows.push_back({scene, "refit", "FCL", ourRefit, fclRefit, ""});
  }

  // Boolean.
  if (wanted("collide")) {
    int ourHits = 0, fclHits = 0;
    const double ourCollide = bestCpuOf(reps, [&] {
      ourHits = 0;
      for (const Isometry3& pb : poses) ourHits += dm::meshMeshIntersect(*a, pa, *b, pb);
    });
    const double fclCollide = bestCpuOf(reps, [&] {
      fclHits = 0;
      for (const Isometry3& pb : poses) {
        fcl::CollisionObjectd oa(fa, pa), ob(fb, pb);
        fcl::CollisionRequestd req;
        fcl::CollisionResultd res;
        fcl::collide(&oa, &ob, req, res);
        fclHits += res.isCollision();
      }
    });
    std::snprintf(note, sizeof note, "overlapping poses: dm %d, FCL %d", ourHits, fclHits);
    rows.push_back({scene, "collide", "FCL", ourCollide / poseCount, fclCollide / poseCount, note});
  }

  // Contacts.
  if (wanted("contacts")) {
    std::vector<dm::MeshContact> contacts;
    long ourContacts = 0, fclContacts = 0, btContacts = 0;
    const double ourAll = bestCpuOf(reps, [&] {
      ourContacts = 0;
      for (const Isometry3& pb : poses)
        ourContacts += static_cast<long>(dm::meshMeshContacts(*a, pa, *b, pb, contacts));
    });
    const double fclAll = bestCpuOf(reps, [&] {
      fclContacts = 0;
      for (const Isometry3& pb : poses) {
        fcl::CollisionObjectd oa(fa, pa), ob(fb, pb);
        fcl::CollisionRequestd req(std::numeric_limits<std::size_t>::max() / 2, true);
        fcl::CollisionResultd res;
        fcl::collide(&oa, &ob, req, res);
        fclContacts += static_cast<long>(res.numContacts());
      }
    });
    BulletMesh ba(ma), bb(mb);
    btDefaultCollisionConfiguration config;
    btCollisionDispatcher dispatcher(&config);
    btGImpactCollisionAlgorithm::registerAlgorithm(&dispatcher);
    // contactPairTest looks up "closest points" algorithms, which
    // registerAlgorithm() does not register for GImpact.
    static btGImpactCollisionAlgorithm::CreateFunc gimpact;
    for (int i = 0; i < MAX_BROADPHASE_COLLISION_TYPES; ++i) {
      dispatcher.registerClosestPointsCreateFunc(GIMPACT_SHAPE_PROXYTYPE, i, &gimpact);
      dispatcher.registerClosestPointsCreateFunc(i, GIMPACT_SHAPE_PROXYTYPE, &gimpact);
    }
    btDbvtBroadphase broadphase;
    btCollisionWorld world(&dispatcher, &broadphase, &config);
    btCollisionObject oa, ob;
    oa.setCollisionShape(ba.shape.get());
    ob.setCollisionShape(bb.shape.get());
    oa.setWorldTransform(toBullet(pa));
    const double btAll = bestCpuOf(reps, [&] {
      btContacts = 0;
      for (const Isometry3& pb : poses) {
        ob.setWorldTransform(toBullet(pb));
        CountContacts cb;
        world.contactPairTest(&oa, &ob, cb);
        btContacts += cb.count;
      }
    });
    std::snprintf(note, sizeof note, "contacts: dm %ld, FCL %ld", ourContacts, fclContacts);
    rows.push_back({scene, "contacts", "FCL", ourAll / poseCount, fclAll / poseCount, note});
    std::snprintf(note, sizeof note, "contacts: dm %ld, GImpact %ld", ourContacts, btContacts);
    rows.push_back({scene, "contacts", "GImpact", ourAll / poseCount, btAll / poseCount, note});
  }

  // Distance.
  if (!wanted("distance")) return;
  double ourSum = 0, fclSum = 0, worst = 0;
  std::vector<double> ours(poses.size());
  const double ourDist = bestCpuOf(reps, [&] {
    ourSum = 0;
    for (std::size_t i = 0; i < poses.size(); ++i) {
      ours[i] = dm::meshMeshDistance(*a, pa, *b, poses[i]).distance;
      ourSum += ours[i];
    }
  });
  const double fclDist = bestCpuOf(reps, [&] {
    fclSum = 0;
    worst = 0;
    for (std::size_t i = 0; i < poses.size(); ++i) {
      fcl::CollisionObjectd oa2(fa, pa), ob2(fb, poses[i]);
      fcl::DistanceRequestd req(true);
      fcl::DistanceResultd res;
      fcl::distance(&oa2, &ob2, req, res);
      const double d = std::max(0.0, res.min_distance);
      fclSum += d;
      if (ours[i] > 0) worst = std::max(worst, std::abs(d - ours[i]) / ours[i]);
    }
  });
  std::snprintf(note, sizeof note, "sum dm %.6g, FCL %.6g; max rel diff %.1e", ourSum, fclSum, worst);
  rows.push_back({scene, "distance", "FCL", ourDist / poseCount, fclDist / poseCount, note});
}

}  // namespace

int main(int argc, char** argv) {
  const int poseCount = argc > 1 ? std::max(1, std::atoi(argv[1])) : 200;
  const int reps = argc > 2 ? std::max(1, std::atoi(argv[2])) : 3;
  const std::string model =
      argc > 3 && std::string(argv[3]) != "-" ? argv[3] : "/usr/share/assimp/models/PLY/Wuson.ply";
  if (argc > 4) gQueries = argv[4];
  std::vector<Row> rows;

  struct Size {
    int nu, nv, rings, segments, poses;
  };
  // Torus 2·nu·nv triangles, sphere 2·segments·(rings − 1).
  for (const Size& s : {Size{32, 16, 17, 32, poseCount}, Size{100, 50, 51, 100, poseCount},
                        Size{316, 158, 159, 316, std::max(1, poseCount / 4)}}) {
    benchScene("torus/sphere", dm::makeTorus(0.35, 0.12, s.nu, s.nv),
               dm::makeUvSphere(0.3, s.rings, s.segments), s.poses, reps, rows);
  }
  dm::MeshImportOptions options;
  auto real = dm::readMesh(model, options);
  if (real) {
    // Scale to a 1 m box centred at the origin.
    const dm::Aabb box = real->bounds();
    const double scale = 1.0 / box.sizes().maxCoeff();
    for (Vec3& p : real->positions) p = (p - box.center()) * scale;
    const std::string name = std::filesystem::path(model).filename().string();
    benchScene(name, *real, *real, poseCount, reps, rows);
  } else {
    std::printf("real model skipped: %s\n", real.error().message().c_str());
  }
  printRows(rows);
  return 0;
}
