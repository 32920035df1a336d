// Rigid-body contact: PhysicsWorld's built-in pipeline (DMCollide contacts +
// sequential impulses) against ODE's dWorldQuickStep (through dm::OdeWorld)
// and Bullet's btDiscreteDynamicsWorld with btSequentialImpulseConstraintSolver
// on the same scenes:
//   * rain:    1,000 boxes (0.2 m cubes, 1 kg) in a 10 × 10 × 10 lattice
//              falling onto a ground plane, simulated 2 s;
//   * pyramid: a 2-D pyramid of 20 rows (210 boxes) resting on the plane,
//              simulated 4 s;
// at dt = 1 ms and 1/60 s, each solver with 20 iterations, μ = 0.5, e = 0.
// Prints per engine the time per step (thread CPU time, one thread), the
// largest penetration into the ground seen at the end (lowest box corner
// below z = 0) and, for the pyramid, how far the top box drifted from its
// start (a collapsed pyramid shows metres); then the ratios ours/ODE and
// ours/Bullet of the step time (below 1: we are faster). Each engine's time
// is the best of 3 runs, the engines taking turns run by run: this host's
// speed drifts in spells, and turns let every engine meet the same spells.
//
// Each scene runs twice: all bodies awake (our ContactSettings::sleep off,
// Bullet's bodies DISABLE_DEACTIVATION, ODE as always), then with resting
// bodies put to sleep (ours: sleep on; Bullet: its default deactivation;
// dm::OdeWorld has no sleeping, so no ODE row there).
//
// What is matched: shapes, masses, inertia, friction, gravity, dt,
// iteration counts. What is not: ODE runs through dm::OdeWorld (the state is
// copied in and out each step, O(n), small next to collision), ODE and our
// solver run in double precision, the system Bullet in float with its
// default collision margins (0.04 m on the plane; boxes keep their shape);
// ODE uses its hash space and dCollide, Bullet its dynamic AABB tree and
// GJK/EPA + box–box, we sort-and-sweep and DMCollide's box–box / plane–box.
//
//   cmake -S . -B build-phr-bench -G Ninja -DCMAKE_BUILD_TYPE=Release -DDM_BUILD_BENCH=ON -DDM_WERROR=OFF
//   ninja -C build-phr-bench physics_rigid_bench && build-phr-bench/Bench/physics_rigid_bench
//
// Arguments (optional, any order) pick cases, for profiling one of them:
// "rain" or "pyramid", "awake" or "sleep", "1ms" or "60hz", and "ours" to
// run only our engine (no peers, no ratios), e.g.
//   physics_rigid_bench pyramid awake 60hz ours
#include <dm/collide/shapes.hpp>
#include <dm/physics/ode_backend.hpp>
#include <dm/physics/world.hpp>

#include <btBulletDynamicsCommon.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <memory>
#include <string_view>
#include <vector>

namespace {

constexpr double kG = 9.81;
constexpr double kHalf = 0.1;  // box half extent, m
constexpr double kMu = 0.5;
constexpr int kIterations = 20;

double cpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

struct Scene {
  const char* name;
  std::vector<dm::Vec3> start;  // box centres
  double seconds;
};

Scene rain() {
  Scene s{"rain 1000", {}, 2.0};
  for (int k = 0; k < 10; ++k)
    for (int j = 0; j < 10; ++j)
      for (int i = 0; i < 10; ++i)
        s.start.emplace_back(0.3 * i + 0.01 * (k % 3), 0.3 * j + 0.01 * (k % 2), 0.3 + 0.3 * k);
  return s;
}

Scene pyramid(int rows) {
  Scene s{"pyramid 20", {}, 4.0};
  const double gap = 0.005;
  for (int r = 0; r < rows; ++r)
    for (int i = 0; i < rows - r; ++i)
      s.start.emplace_back((2 * kHalf + gap) * (i + 0.5 * r), 0.0, kHalf + 2 * kHalf * r);
  return s;
}

// Penetration of a box (centre x, rotation R) into the ground z = 0, m.
double groundPenetration(const dm::Vec3& x, const dm::Mat3& R) {
  const double reach = kHalf * (std::abs(R(2, 0)) + std::abs(R(2, 1)) + std::abs(R(2, 2)));
  return std::max(0.0, reach - x.z());
}

struct Outcome {
  double secondsPerStep = 0;
  double penetration = 0;  // m, largest at the end
  double topDrift = 0;     // m, last box (the pyramid's top)
};

std::unique_ptr<dm::PhysicsWorld> buildOurs(const Scene& scene, bool sleep = false) {
  auto w = std::make_unique<dm::PhysicsWorld>();
  dm::BodyDesc ground;
  ground.kind = dm::BodyKind::Static;
  ground.shape = std::make_shared<dm::Plane>(dm::Vec3::UnitZ(), 0.0);
  const dm::BodyId g = *w->addBody(ground);
  (void)w->setMaterial(g, {.friction = kMu});
  const auto box = std::make_shared<dm::Box>(dm::Vec3::Constant(kHalf));
  for (const dm::Vec3& x : scene.start) {
    dm::BodyDesc d;
    d.kind = dm::BodyKind::Rigid;
    d.mass = 1.0;
    d.inertia = dm::boxInertia(1.0, dm::Vec3::Constant(kHalf));
    d.position = x;
    d.shape = box;
    const dm::BodyId id = *w->addBody(d);
    (void)w->setMaterial(id, {.friction = kMu});
  }
  (void)w->setGravity({0, 0, -kG});
  dm::ContactSettings cs;
  cs.solver.velocityIterations = kIterations;
  cs.sleep = sleep;
  (void)w->setContactSettings(cs);
  return w;
}

Outcome measure(const Scene& scene, const dm::PhysicsWorld& w, const dm::WorldState& s, double seconds,
                int steps) {
  Outcome o;
  o.secondsPerStep = seconds / steps;
  for (std::size_t i = 1; i < w.bodyCount(); ++i) {
    const dm::BodyId id{static_cast<std::uint32_t>(i)};
    o.penetration =
        std::max(o.penetration, groundPenetration(s.position(id), s.orientation(id).toRotationMatrix()));
  }
  const dm::BodyId top{static_cast<std::uint32_t>(w.bodyCount() - 1)};
  o.topDrift = (s.position(top) - scene.start.back()).norm();
  return o;
}

constexpr int kRuns = 3;

Outcome runOurs(const Scene& scene, double dt, bool sleep) {
  const auto w = buildOurs(scene, sleep);
  dm::WorldState s = w->makeState();
  const int steps = static_cast<int>(std::lround(scene.seconds / dt));
  const double t0 = cpuSeconds();
  for (int i = 0; i < steps; ++i)
    if (auto st = w->step(s, dt); !st) {
      std::printf("ours failed: %s\n", st.error().message().c_str());
      break;
    }
  return measure(scene, *w, s, cpuSeconds() - t0, steps);
}

Outcome runOde(const Scene& scene, double dt) {
  const auto w = buildOurs(scene);
  auto ode = dm::OdeWorld::create(*w, {.iterations = kIterations});
  if (!ode) {
    std::printf("ODE failed: %s\n", ode.error().message().c_str());
    return {};
  }
  dm::WorldState s = w->makeState();
  const int steps = static_cast<int>(std::lround(scene.seconds / dt));
  const double t0 = cpuSeconds();
  for (int i = 0; i < steps; ++i)
    if (auto st = ode->step(s, dt); !st) {
      std::printf("ODE failed: %s\n", st.error().message().c_str());
      break;
    }
  return measure(scene, *w, s, cpuSeconds() - t0, steps);
}

Outcome runBullet(const Scene& scene, double dt, bool sleep) {
  btDefaultCollisionConfiguration config;
  btCollisionDispatcher dispatcher(&config);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btDiscreteDynamicsWorld world(&dispatcher, &broadphase, &solver, &config);
  world.setGravity(btVector3(0, 0, btScalar(-kG)));
  world.getSolverInfo().m_numIterations = kIterations;
  btStaticPlaneShape plane(btVector3(0, 0, 1), 0);
  btRigidBody ground(btRigidBody::btRigidBodyConstructionInfo(0, nullptr, &plane));
  ground.setFriction(btScalar(kMu));
  world.addRigidBody(&ground);
  const btScalar h = static_cast<btScalar>(kHalf);
  btBoxShape box{btVector3(h, h, h)};
  btVector3 inertia;
  box.calculateLocalInertia(1, inertia);
  std::vector<std::unique_ptr<btDefaultMotionState>> motions;
  std::vector<std::unique_ptr<btRigidBody>> bodies;
  for (const dm::Vec3& x : scene.start) {
    btTransform t;
    t.setIdentity();
    t.setOrigin(btVector3(btScalar(x.x()), btScalar(x.y()), btScalar(x.z())));
    motions.push_back(std::make_unique<btDefaultMotionState>(t));
    btRigidBody::btRigidBodyConstructionInfo info(1, motions.back().get(), &box, inertia);
    info.m_friction = btScalar(kMu);
    bodies.push_back(std::make_unique<btRigidBody>(info));
    if (!sleep) bodies.back()->setActivationState(DISABLE_DEACTIVATION);
    world.addRigidBody(bodies.back().get());
  }
  const int steps = static_cast<int>(std::lround(scene.seconds / dt));
  const double t0 = cpuSeconds();
  for (int i = 0; i < steps; ++i) world.stepSimulation(btScalar(dt), 0, btScalar(dt));
  Outcome o;
  o.secondsPerStep = (cpuSeconds() - t0) / steps;
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    const btTransform& t = bodies[i]->getWorldTransform();
    dm::Mat3 R;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) R(r, c) = double(t.getBasis()[r][c]);
    const dm::Vec3 x(double(t.getOrigin().x()), double(t.getOrigin().y()), double(t.getOrigin().z()));
    o.penetration = std::max(o.penetration, groundPenetration(x, R));
    if (i + 1 == bodies.size()) o.topDrift = (x - scene.start.back()).norm();
  }
  for (auto& b : bodies) world.removeRigidBody(b.get());
  world.removeRigidBody(&ground);
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  // Optional filters, for profiling one case: a scene ("rain", "pyramid"),
  // "awake" or "sleep", "1ms" or "60hz", and "ours" (skip the peers).
  const auto wanted = [&](const char* word, const char* group[], int groupSize) {
    bool any = false;
    for (int a = 1; a < argc; ++a)
      for (int g = 0; g < groupSize; ++g)
        if (std::string_view(argv[a]) == group[g]) {
          any = true;
          if (std::string_view(argv[a]) == word) return true;
        }
    return !any;
  };
  const char* scenes[] = {"rain", "pyramid"};
  const char* modes[] = {"awake", "sleep"};
  const char* steps[] = {"1ms", "60hz"};
  const char* engines[] = {"ours"};
  const bool oursOnly = !wanted("peers", engines, 1);
  std::printf("rigid contact, 20 iterations each; time per step = thread CPU time\n");
  for (const bool sleep : {false, true}) {
    if (!wanted(sleep ? "sleep" : "awake", modes, 2)) continue;
    std::printf("\n%s\n", sleep ? "resting bodies sleep (ours: ContactSettings::sleep; Bullet: default deactivation)"
                                 : "all bodies awake (Bullet: DISABLE_DEACTIVATION)");
    std::printf("%-11s %-7s %-7s %12s %14s %13s\n", "scene", "dt", "engine", "ms/step", "penetration mm",
                "top drift mm");
    for (const Scene& scene : {rain(), pyramid(20)}) {
      if (!wanted(scene.name[0] == 'r' ? "rain" : "pyramid", scenes, 2)) continue;
      for (const double dt : {1e-3, 1.0 / 60.0}) {
        if (!wanted(dt < 2e-3 ? "1ms" : "60hz", steps, 2)) continue;
        // Best of kRuns per engine, in turns. Penetration and drift come
        // from the fastest run: ours and Bullet's are the same every run;
        // ODE's quickstep shuffles its rows with a random generator that
        // runs on from run to run, so its outcome varies a little.
        Outcome ours, bullet, ode;
        const auto keepFaster = [](Outcome& best, const Outcome& o, int run) {
          if (run == 0 || o.secondsPerStep < best.secondsPerStep) best = o;
        };
        for (int run = 0; run < kRuns; ++run) {
          keepFaster(ours, runOurs(scene, dt, sleep), run);
          if (oursOnly) continue;
          keepFaster(bullet, runBullet(scene, dt, sleep), run);
          if (!sleep) keepFaster(ode, runOde(scene, dt), run);
        }
        if (oursOnly) {
          std::printf("%-11s %-7s %-7s %12.4f %14.3f\n", scene.name, dt < 2e-3 ? "1 ms" : "1/60 s", "ours",
                      1e3 * ours.secondsPerStep, 1e3 * ours.penetration);
          continue;
        }
        const char* dtName = dt < 2e-3 ? "1 ms" : "1/60 s";
        const std::pair<const char*, const Outcome*> rows[] = {
            {"ours", &ours}, {"ODE", &ode}, {"Bullet", &bullet}};
        const bool isPyramid = scene.name[0] == 'p';  // drift only means something for the pyramid
        for (const auto& [engine, o] : rows) {
          if (sleep && o == &ode) continue;
          std::printf("%-11s %-7s %-7s %12.4f %14.3f ", scene.name, dtName, engine, 1e3 * o->secondsPerStep,
                      1e3 * o->penetration);
          if (isPyramid)
            std::printf("%13.3f\n", 1e3 * o->topDrift);
          else
            std::printf("%13s\n", "-");
        }
        if (sleep)
          std::printf("%-11s %-7s ratio ours/Bullet = %.2f\n", scene.name, dtName,
                      ours.secondsPerStep / bullet.secondsPerStep);
        else
          std::printf("%-11s %-7s ratio ours/ODE = %.2f, ours/Bullet = %.2f\n", scene.name, dtName,
                      ours.secondsPerStep / ode.secondsPerStep, ours.secondsPerStep / bullet.secondsPerStep);
      }
    }
  }
  return 0;
}
