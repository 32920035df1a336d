// scene_membranes.cpp — mass–spring membranes built from scene objects,
// stepped and reported (scene_membranes.hpp).
#include "scene_membranes.hpp"

#include <dm/core/triple_buffer.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/physics/mass_spring.hpp>
#include <dm/physics/membrane_rigid.hpp>
#include <dm/physics/world.hpp>

#include <algorithm>
#include <map>
#include <optional>
#include <utility>

#include "deformed_surface.hpp"
#include "engine_json.hpp"
#include "scene_obstacles.hpp"

namespace dm {

struct SceneMembranes::Body {
  std::string name;
  Isometry3 pose = Isometry3::Identity();  // object → world
  double scale = 1.0;
  MassSpringBody springs;
  std::optional<MembraneRigidCoupling> contacts;  // with the world's colliding objects
  std::vector<Vec3> rest;             // world, the particles at the start
  std::vector<std::uint32_t> pinned;  // particle indices
  std::vector<Triangle> triangles;    // the drawn mesh's (= the particles')
  std::unique_ptr<TripleBuffer<std::vector<Vec3>>> surface;
  // Counters (physics thread; read after the run).
  std::uint64_t steps = 0, unconverged = 0, cgIterations = 0;
  int cgMax = 0;
};

SceneMembranes::~SceneMembranes() = default;

namespace {

// Vertices on an edge that only one triangle uses.
std::vector<bool> boundaryVertices(const Mesh& mesh) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> uses;
  for (const Triangle& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = t[k], b = t[(k + 1) % 3];
      ++uses[{std::min(a, b), std::max(a, b)}];
    }
  std::vector<bool> out(mesh.positions.size(), false);
  for (const auto& [edge, n] : uses)
    if (n == 1) out[edge.first] = out[edge.second] = true;
  return out;
}

}  // namespace

Result<std::unique_ptr<SceneMembranes>> SceneMembranes::build(const SceneDesc& scene,
                                                              const SceneResources& resources,
                                                              const PhysicsWorld& world) {
  std::unique_ptr<SceneMembranes> out(new SceneMembranes());
  if (std::none_of(scene.objects.begin(), scene.objects.end(),
                   [](const SceneObject& o) { return o.membrane; }))
    return out;
  auto obstacles = sceneObstacles(scene, resources, world);
  if (!obstacles) return obstacles.error();
  out->obstacles_ = std::move(*obstacles);
  for (const SceneObject& o : scene.objects) {
    if (!o.membrane) continue;
    const SceneMembrane& m = *o.membrane;
    const std::string where = "objects/" + o.name + "/membrane";
    auto mesh = resources.mesh(o.mesh);
    if (!mesh) return fail(ErrorCode::NotFound, "mesh \"" + o.mesh + "\" was not loaded", where);
    auto b = std::make_unique<Body>();
    b->name = o.name;
    b->pose = o.pose.isometry();
    b->scale = o.scale;
    Mesh placed;  // in the world
    placed.triangles = mesh->triangles;
    placed.positions.reserve(mesh->positions.size());
    for (const Vec3& p : mesh->positions) placed.positions.push_back(b->pose * (o.scale * p));
    const auto model =
        m.model == SceneMembrane::Model::Maxwell ? SpringModel::Maxwell : SpringModel::KelvinVoigt;
    MassSpringMeshOptions options{
        .mass = m.mass,
        .structural = {true, m.stiffness, m.damping, model},
        .bend = {m.bendStiffness > 0.0, m.bendStiffness, m.bendDamping, SpringModel::KelvinVoigt}};
    auto springs = MassSpringBody::fromMesh(placed, options);
    if (!springs) return springs.error().within(where);
    b->springs = std::move(*springs);
    b->springs.setGravity(scene.engines.physics->gravity);
    if (auto s = b->springs.setDrag(m.drag); !s) return s.error().within(where + "/drag");
    // Held vertices: the boundary's, and those in a pinned box (the
    // object's frame before its scale).
    const std::vector<bool> boundary =
        m.pinBoundary ? boundaryVertices(*mesh) : std::vector<bool>(mesh->positions.size(), false);
    for (std::uint32_t i = 0; i < mesh->positions.size(); ++i) {
      const Vec3& p = mesh->positions[i];
      bool held = boundary[i];
      for (const SceneBox& box : m.pinnedBoxes)
        held = held || ((p - box.min).minCoeff() >= 0.0 && (box.max - p).minCoeff() >= 0.0);
      if (!held) continue;
      b->springs.setPinned(i, true);
      b->pinned.push_back(i);
    }
    std::vector<MembraneRigidContact> touching;
    for (const SceneObstacle& ob : out->obstacles_)
      touching.push_back({.body = ob.body, .tree = ob.tree.get(), .friction = m.friction});
    auto contacts = MembraneRigidCoupling::create(world, touching, m.thickness);
    if (!contacts) return contacts.error().within(where);
    b->contacts = std::move(*contacts);
    b->rest = placed.positions;
    b->triangles = mesh->triangles;
    b->surface = std::make_unique<TripleBuffer<std::vector<Vec3>>>(mesh->positions);
    out->names_.push_back(o.name);
    out->bodies_.push_back(std::move(b));
  }
  return out;
}

Status SceneMembranes::step(double h, WorldState& state) {
  for (const auto& bp : bodies_) {
    Body& b = *bp;
    auto report = b.contacts->step(b.springs, state, h);
    if (!report) return report.error().within("membrane \"" + b.name + "\"");
    ++b.steps;
    b.unconverged += !report->converged;
    b.cgIterations += static_cast<std::uint64_t>(report->cgIterations);
    b.cgMax = std::max(b.cgMax, report->cgIterations);
    std::vector<Vec3>& positions = b.surface->writeBuffer();  // sized at build: no allocation
    const Isometry3 toObject = b.pose.inverse();
    for (std::size_t i = 0; i < positions.size(); ++i)
      positions[i] = toObject * b.springs.position(i) / b.scale;
    b.surface->publish();
  }
  return ok();
}

bool SceneMembranes::latestSurface(std::size_t i, Mesh& out) {
  if (i >= bodies_.size()) return false;
  Body& b = *bodies_[i];
  return latestDeformedSurface(*b.surface, b.triangles, out);
}

void SceneMembranes::addBodyForces(std::span<Vec3> force) const {
  for (const auto& b : bodies_)
    for (std::size_t i = 0; i < obstacles_.size(); ++i)
      if (obstacles_[i].body.index < force.size())
        force[obstacles_[i].body.index] += b->contacts->contacts().force(i);
}

nlohmann::json SceneMembranes::summary() const {
  nlohmann::json list = nlohmann::json::array();
  for (const auto& bp : bodies_) {
    const Body& b = *bp;
    const MassSpringBody& s = b.springs;
    double maxDisplacement = 0.0;
    Vec3 center = Vec3::Zero();
    for (std::size_t i = 0; i < s.particleCount(); ++i) {
      maxDisplacement = std::max(maxDisplacement, (s.position(i) - b.rest[i]).norm());
      center += s.mass(i) * s.position(i);
    }
    // What the pins carry: the elements' pull on the held vertices and
    // those vertices' own weight (at rest, the membrane's weight).
    Vec3 pinLoad = Vec3::Zero();
    for (std::uint32_t i : b.pinned) pinLoad += s.elementForceOn(i) + s.mass(i) * s.gravity();
    nlohmann::json touching = nlohmann::json::array();
    for (std::size_t i = 0; i < obstacles_.size(); ++i)
      touching.push_back({{"name", obstacles_[i].name},
                          {"dynamic", obstacles_[i].dynamic},
                          {"force_N", engine_json::vec3(b.contacts->contacts().force(i))}});
    list.push_back({{"name", b.name},
                    {"particles", s.particleCount()},
                    {"elements", s.elementCount()},
                    {"pinned", b.pinned.size()},
                    {"mass_kg", s.totalMass()},
                    {"pinned_load_N", engine_json::vec3(pinLoad)},
                    {"center_of_mass_m", engine_json::vec3(center / s.totalMass())},
                    {"max_displacement_m", maxDisplacement},
                    {"kinetic_energy_J", s.kineticEnergy()},
                    {"elastic_energy_J", s.elasticEnergy()},
                    {"steps", b.steps},
                    {"cg_iterations_mean", b.steps ? double(b.cgIterations) / double(b.steps) : 0.0},
                    {"cg_iterations_max", b.cgMax},
                    {"unconverged_steps", b.unconverged},
                    {"contacts", b.contacts->contacts().contacts()},
                    {"obstacles", std::move(touching)}});
  }
  return list;
}

}  // namespace dm
