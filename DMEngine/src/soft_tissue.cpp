// soft_tissue.cpp — a scene's soft objects as FEM bodies (soft_tissue.hpp).
#include "soft_tissue.hpp"

#include <dm/collide/bvh.hpp>
#include <dm/core/triple_buffer.hpp>
#include <dm/haptics/god_object.hpp>
#include <dm/haptics/needle.hpp>
#include <dm/haptics/tissue.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/math/voxelize.hpp>
#include <dm/physics/fem.hpp>
#include <dm/physics/needle.hpp>
#include <dm/physics/soft_rigid.hpp>
#include <dm/physics/world.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

#include "deformed_surface.hpp"
#include "engine_json.hpp"
#include "scene_obstacles.hpp"

namespace dm {

namespace {

// The tetrahedra of soft object `o` in its frame, at its scale (m): from
// `volume`'s voxels when it has one, else its box shape or voxelized mesh;
// on a uniform grid, or graded (levels).
Result<TetMesh> softTetMesh(const SceneObject& o, const SceneResource& res, const Mesh& mesh,
                            const Volume* volume) {
  const SceneSoft& s = *o.soft;
  // The occupied voxels: the volume's from the threshold up, a box split
  // into cuboids of about voxel_size that fill it exactly (the tissue's
  // surface is the box the scene draws), or the voxelized mesh.
  std::vector<std::uint8_t> occupancy;
  Vec3i dims;
  Vec3 spacing, origin;
  if (volume != nullptr) {
    // The volume's own voxels (its affine places them).
    if (s.levels == 0) return tetMeshFromVolume(*volume, {.threshold = s.threshold, .maxTets = s.maxTets});
    const Mat3 a = volume->indexToWorld().linear();
    if (!a.isDiagonal(1e-12) || a.diagonal().minCoeff() <= 0.0)
      return fail(ErrorCode::InvalidArgument, "a graded grid needs a volume whose axes are the world's",
                  "levels", "use \"levels\": 0 on this volume, or resample it axis-aligned");
    dims = volume->dims();
    spacing = a.diagonal();
    origin = volume->indexToWorld() * Vec3::Constant(-0.5);  // the first voxel's corner
    occupancy.resize(static_cast<std::size_t>(dims.prod()));
    for (std::size_t i = 0; i < occupancy.size(); ++i)
      occupancy[i] = volume->valueAt(i) >= s.threshold ? 1 : 0;
  } else if (res.type == SceneResource::Type::Shape && res.shape == SceneResource::Shape::Box) {
    const Vec3 size = 2.0 * res.halfExtents * o.scale;
    for (int a = 0; a < 3; ++a)
      dims[a] = static_cast<int>(std::clamp(std::round(size[a] / s.voxelSize), 1.0, 1e6));
    if (s.levels == 0) return tetMeshBox(dims, size, -0.5 * size, s.maxTets);
    spacing = size.cwiseQuotient(dims.cast<double>());
    origin = -0.5 * size;
    occupancy.assign(static_cast<std::size_t>(dims.prod()), 1);
  } else {
    Mesh scaled = mesh;
    if (o.scale != 1.0) scaled.transform(Affine3(Eigen::Scaling(o.scale)));
    auto v = voxelizeMesh(scaled, {.voxelSize = s.voxelSize, .paddingVoxels = 1});
    if (!v) return v.error();
    if (s.levels == 0) return tetMeshFromVolume(*v, {.threshold = 0.5, .maxTets = s.maxTets});
    dims = v->dims();
    spacing = Vec3::Constant(s.voxelSize);
    origin = v->indexToWorld() * Vec3::Constant(-0.5);  // the first voxel's corner
    occupancy.resize(static_cast<std::size_t>(dims.prod()));
    for (std::size_t i = 0; i < occupancy.size(); ++i) occupancy[i] = v->valueAt(i) >= 0.5 ? 1 : 0;
  }
  HierarchicalTetOptions h{.levels = s.levels, .maxTets = s.maxTets};
  if (s.fineRegion) h.fineRegion = Aabb(s.fineRegion->min * o.scale, s.fineRegion->max * o.scale);
  return tetMeshHierarchical(occupancy, dims, spacing, origin, h);
}

// Each tetrahedron's needle layer: the layer whose slab (top down from the
// +z face of the rest bounding box) holds its centroid; the last layer
// reaches the bottom.
std::vector<std::uint8_t> tetLayersBySlab(const TetMesh& mesh, double top,
                                          const std::vector<SceneSoftLayer>& layers) {
  std::vector<std::uint8_t> out(mesh.tetCount());
  for (std::size_t t = 0; t < mesh.tetCount(); ++t) {
    Vec3 c = Vec3::Zero();
    for (std::uint32_t n : mesh.tets[t]) c += mesh.nodes[n];
    const double depth = top - 0.25 * c.z();
    std::size_t layer = 0;
    double bottom = 0.0;
    for (; layer + 1 < layers.size(); ++layer) {
      bottom += layers[layer].thickness;
      if (depth < bottom) break;
    }
    out[t] = static_cast<std::uint8_t>(layer);
  }
  return out;
}

// Each tetrahedron's needle layer: by slabs, or by the label of the voxel
// of a label volume its centroid is in (the tissue placed in the world by
// the object's pose, where the volume is).
// Errors name `where` + "/labels".
Result<std::vector<std::uint8_t>> tetLayers(const SceneObject& o, const TetMesh& mesh, double top,
                                            const SceneResources& resources, const std::string& where) {
  const SceneSoft& s = *o.soft;
  if (s.labels.empty()) return tetLayersBySlab(mesh, top, s.layers);
  auto volume = resources.volume(s.labels);
  const std::string at = where + "/labels";
  if (!volume) return fail(ErrorCode::NotFound, "volume \"" + s.labels + "\" was not loaded", at);
  constexpr std::uint8_t kNoLayer = 255;  // (at most 255 layers: 0..254)
  int maxLabel = 0;
  for (const SceneSoftLayer& l : s.layers) maxLabel = std::max(maxLabel, l.label);
  std::vector<std::uint8_t> layerOfLabel(static_cast<std::size_t>(maxLabel) + 1, kNoLayer);
  for (std::size_t i = 0; i < s.layers.size(); ++i)
    layerOfLabel[static_cast<std::size_t>(s.layers[i].label)] = static_cast<std::uint8_t>(i);
  TetMesh world = mesh;
  const Isometry3 pose = o.pose.isometry();
  for (Vec3& p : world.nodes) p = pose * p;
  auto layers = tetLayersFromLabels(world, *volume, layerOfLabel);
  if (!layers) return layers.error().within(at);
  for (std::size_t t = 0; t < layers->size(); ++t)
    if ((*layers)[t] == kNoLayer)
      return fail(ErrorCode::InvalidArgument,
                  "tetrahedron " + std::to_string(t) + " lies on a label that no layer names", at,
                  "give a layer for every label the tissue covers (0 is the background)");
  return layers;
}

}  // namespace

// The punch renderer: a rigid indenter bonded to nodes of a soft object.
// Haptic thread: tick() hands the device point to the physics thread and
// answers the force of the newest step, held between steps. Physics thread:
// step() moves the bonded nodes with the tool's displacement since its
// first sample (their velocity the displacement of the step over h, as a
// prescribed motion of held nodes), steps the tissue and publishes the force
// the tissue puts on them (−Σ of their constraint forces, world). Neither
// side allocates, locks or waits.
class SoftTissues::PunchTool final : public HapticRenderer {
 public:
  PunchTool(FemBody& fem, std::vector<std::size_t> nodes, const Isometry3& pose)
      : fem_(fem),
        nodes_(std::move(nodes)),
        pose_(pose),
        reaction_(fem.nodeCount(), Vec3::Zero()),
        toPhysics_(Vec3::Constant(std::numeric_limits<double>::quiet_NaN())),
        toHand_(Vec3::Zero()) {}

  std::string_view name() const noexcept override { return "punch"; }
  void reset(const Isometry3&) noexcept override {}
  std::size_t objectCount() const noexcept override { return 0; }
  void setObjectPose(std::size_t, const Isometry3&) noexcept override {}

  HapticResponse tick(const HapticInput& input) noexcept override {
    const Vec3 p = input.devicePose.translation();
    if (p.allFinite()) toPhysics_.write(p);
    if (!first_.allFinite()) first_ = p;
    HapticResponse r;
    r.force = toHand_.read();
    r.proxyPose = input.devicePose;  // bonded: the tool is where the hand holds it
    r.contacts = 1;
    r.penetration = first_.allFinite() ? (p - first_).norm() : 0.0;  // m, from the first pose
    return r;
  }

  Result<FemStepReport> step(double h) {
    if (toPhysics_.update()) device_ = toPhysics_.readBuffer();
    if (device_.allFinite()) {
      if (!started_) previous_ = device_;
      started_ = true;
      const Vec3 v = pose_.linear().transpose() * (device_ - previous_) / h;
      previous_ = device_;
      for (std::size_t i : nodes_) fem_.setVelocity(i, v);
    }
    auto report = fem_.step(h);
    if (!report) return report;
    fem_.computeConstraintForces(reaction_);  // sized at build: no allocation
    Vec3 f = Vec3::Zero();
    for (std::size_t i : nodes_) f -= reaction_[i];
    onTool_ = pose_.linear() * f;
    toHand_.write(onTool_);
    return report;
  }

  /// The punch's force on the tissue (object frame), last step.
  Vec3 toolForce() const noexcept { return -(pose_.linear().transpose() * onTool_); }
  std::size_t nodeCount() const noexcept { return nodes_.size(); }

 private:
  FemBody& fem_;
  std::vector<std::size_t> nodes_;
  Isometry3 pose_;  // object → world
  std::vector<Vec3> reaction_;
  TripleBuffer<Vec3> toPhysics_, toHand_;
  Vec3 first_ = Vec3::Constant(std::numeric_limits<double>::quiet_NaN());   // haptic thread
  Vec3 device_ = Vec3::Constant(std::numeric_limits<double>::quiet_NaN());  // physics thread
  Vec3 previous_ = Vec3::Zero(), onTool_ = Vec3::Zero();
  bool started_ = false;
};

struct SoftTissues::Body {
  std::string name;
  Isometry3 pose = Isometry3::Identity();  // object → world
  double scale = 1.0;
  std::unique_ptr<FemBody> fem;
  std::optional<SoftRigidCoupling> coupling;  // the world's bodies as its obstacles
  std::unique_ptr<HapticTissue> haptic;     // pressed by the god-object, or
  std::unique_ptr<NeedleInsertion> needle;  // a needle goes into it,
  std::unique_ptr<HapticNeedle> felt;       // felt through this renderer, or
  std::unique_ptr<PunchTool> punch;         // a punch is bonded to it
  std::vector<std::string> layerNames;      // the needle's layers, by index
  std::size_t fixedNodes = 0;
  // The surface the render engine draws: its vertices are these body nodes.
  std::vector<std::uint32_t> surfaceNodes;
  std::vector<Triangle> surfaceTriangles;  // indexing surfaceNodes
  std::unique_ptr<TripleBuffer<std::vector<Vec3>>> surface;
  // Counters (physics thread; read after the run).
  std::uint64_t steps = 0, unconverged = 0, cgIterations = 0;
  int cgMax = 0;
  double maxToolForce = 0.0;
  Vec3 restCenterOfMass = Vec3::Zero();  // object frame
  Vec3 fluidForce = Vec3::Zero();        // world: the sum of the last fluid loads set
};

SoftTissues::~SoftTissues() = default;

// The surface the render engine draws: the boundary's nodes, renumbered.
// With `creases` (a box: its faces are exact) a node on an edge gets one
// vertex per face it lies on (rest normals more than 60° apart), so the
// renderer's per-vertex normals keep the edges sharp as the tissue deforms;
// otherwise (a voxelized mesh) one vertex per node, whose averaged normals
// smooth the voxels' steps.
void SoftTissues::drawnSurface(const FemBody& fem, bool creases, Body& b) {
  constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
  const std::vector<Vec3>& x = fem.positions();
  std::vector<std::uint32_t> first(fem.nodeCount(), kNone);  // node → its first vertex
  std::vector<std::uint32_t> next;                           // vertex → the node's next vertex
  std::vector<Vec3> normal;                                  // vertex → the rest normal of its face
  for (const Triangle& t : fem.surfaceTriangles()) {
    const Vec3 n = (x[t[1]] - x[t[0]]).cross(x[t[2]] - x[t[0]]).normalized();
    Triangle r;
    for (int k = 0; k < 3; ++k) {
      std::uint32_t v = first[t[k]];
      while (v != kNone && creases && normal[v].dot(n) < 0.5) v = next[v];
      if (v == kNone) {
        v = static_cast<std::uint32_t>(b.surfaceNodes.size());
        b.surfaceNodes.push_back(t[k]);
        normal.push_back(n);
        next.push_back(first[t[k]]);
        first[t[k]] = v;
      }
      r[k] = v;
    }
    b.surfaceTriangles.push_back(r);
  }
}

Result<std::unique_ptr<SoftTissues>> SoftTissues::build(const SceneDesc& scene,
                                                        const SceneResources& resources,
                                                        const PhysicsWorld& world) {
  std::unique_ptr<SoftTissues> out(new SoftTissues());
  // The world's bodies that collide, static and dynamic: obstacles every
  // soft object meets (a dynamic one moved by it in turn).
  if (std::any_of(scene.objects.begin(), scene.objects.end(), [](const SceneObject& o) { return o.soft; })) {
    auto obstacles = sceneObstacles(scene, resources, world);
    if (!obstacles) return obstacles.error();
    out->obstacles_ = std::move(*obstacles);
  }
  const auto& haptics = scene.engines.haptics;
  const Vec3 gravity = scene.engines.physics ? scene.engines.physics->gravity : Vec3::Zero();
  for (const SceneObject& o : scene.objects) {
    if (!o.soft) continue;
    const std::string where = "objects/" + o.name;
    const SceneSoft& s = *o.soft;
    const SceneResource* res = scene.resource(o.mesh);
    auto mesh = resources.mesh(o.mesh);
    if (res == nullptr || !mesh)
      return fail(ErrorCode::NotFound, "mesh \"" + o.mesh + "\" was not loaded", where);
    const bool isBox = res->type == SceneResource::Type::Shape && res->shape == SceneResource::Shape::Box;
    std::shared_ptr<const Volume> volume;
    if (!s.volume.empty()) {
      volume = resources.volume(s.volume);
      if (!volume)
        return fail(ErrorCode::NotFound, "volume \"" + s.volume + "\" was not loaded",
                    where + "/soft/volume");
    }
    // The tetrahedra's size: voxel_size, or the volume's smallest spacing.
    const double h = volume ? volume->indexToWorld().linear().colwise().norm().minCoeff() : s.voxelSize;
    auto tets = softTetMesh(o, *res, *mesh, volume.get());
    if (!tets) return tets.error().within(where + "/soft");
    auto fem = FemBody::create(
        *tets, {.youngsModulus = s.youngsModulus, .poissonRatio = s.poissonRatio, .density = s.density},
        {.alpha = s.alpha, .beta = s.beta});
    if (!fem) return fem.error().within(where + "/soft");
    auto b = std::make_unique<Body>();
    b->name = o.name;
    b->pose = o.pose.isometry();
    b->scale = o.scale;
    b->fem = std::make_unique<FemBody>(std::move(*fem));
    b->fem->setGravity(b->pose.linear().transpose() * gravity);
    // The world's bodies, each node held out of them by a penalty spring
    // (implicit; a dynamic body's velocity solved with the tissue's).
    std::vector<SoftRigidContact> contacts;
    const double contactStiffness = s.contactStiffness > 0 ? s.contactStiffness : 20.0 * s.youngsModulus * h;
    for (const SceneObstacle& ob : out->obstacles_)
      contacts.push_back({.body = ob.body,
                          .tree = ob.tree.get(),
                          .stiffness = contactStiffness,
                          .friction = s.contactFriction});
    auto coupling = SoftRigidCoupling::create(world, *b->fem, contacts, b->pose);
    if (!coupling) return coupling.error().within(where + "/soft");
    b->coupling = std::move(*coupling);
    b->restCenterOfMass = b->fem->centerOfMass();
    // The held faces: nodes within a quarter of a tetrahedron's size of a
    // face of the rest bounding box.
    Aabb box;
    for (const Vec3& p : tets->nodes) box.extend(p);
    const double tol = 0.25 * h;
    b->fixedNodes = b->fem->fixNodesWhere([&](const Vec3& p) {
      for (const SceneBox& fb : s.fixedBoxes)
        if (Aabb(fb.min * o.scale, fb.max * o.scale).contains(p)) return true;
      for (int f = 0; f < 6; ++f) {
        if (((s.fixedFaces >> f) & 1u) == 0) continue;
        const int axis = f / 2;
        const double face = (f % 2 == 0) ? box.min()[axis] : box.max()[axis];
        if (std::abs(p[axis] - face) <= tol) return true;
      }
      return false;
    });
    const SceneMaterial* mat = scene.material(o.material);
    const double stiffness = mat != nullptr && mat->haptic ? mat->haptic->stiffness : 0.0;
    const bool punched = haptics && haptics->punch &&
                         haptics->renderer == SceneHapticsEngine::Renderer::Punch &&
                         haptics->punch->object == o.name;
    if (punched) {
      // The punch's nodes: those in its region (world, at rest), held and
      // moved with the tool.
      const Aabb region(haptics->punch->region.min, haptics->punch->region.max);
      std::vector<std::size_t> bonded;
      for (std::size_t i = 0; i < b->fem->nodeCount(); ++i)
        if (region.contains(b->pose * b->fem->positions()[i])) bonded.push_back(i);
      if (bonded.empty())
        return fail(
            ErrorCode::InvalidArgument, "the punch's region holds no node of object \"" + o.name + "\"",
            "engines/haptics/punch/region", "make the region enclose the tissue's nodes under the punch");
      for (std::size_t i : bonded) b->fem->setFixed(i, true);
      b->punch = std::make_unique<PunchTool>(*b->fem, std::move(bonded), b->pose);
    } else if (!s.layers.empty() && haptics) {
      // The needle renderer's tissue (the parser checked that it is).
      auto layerOfTet = tetLayers(o, *tets, box.max().z(), resources, where + "/soft");
      if (!layerOfTet) return layerOfTet.error();
      if (auto st = out->attachNeedle(*b, *layerOfTet, s.layers, *haptics, stiffness); !st)
        return st.error().within(where);
    } else {
      // The god-object's spring on this tissue is its haptic material's.
      HapticTissueOptions ho;
      if (stiffness > 0) ho.stiffness = stiffness;
      if (haptics) ho.tipRadius = haptics->toolRadius + GodObjectOptions{}.skin;
      auto tissue = HapticTissue::create(*b->fem, ho);
      if (!tissue) return tissue.error().within(where);
      b->haptic = std::move(*tissue);
    }
    drawnSurface(*b->fem, isBox, *b);
    std::vector<Vec3> rest(b->surfaceNodes.size());
    for (std::size_t i = 0; i < rest.size(); ++i)
      rest[i] = b->fem->positions()[b->surfaceNodes[i]] / b->scale;
    b->surface = std::make_unique<TripleBuffer<std::vector<Vec3>>>(rest);
    b->surface->publish();  // the rest surface: the first frame draws it
    out->names_.push_back(o.name);
    out->bodies_.push_back(std::move(b));
  }
  return out;
}

Status SoftTissues::attachNeedle(Body& b, std::span<const std::uint8_t> layerOfTet,
                                 const std::vector<SceneSoftLayer>& layers, const SceneHapticsEngine& h,
                                 double tipStiffness) {
  if (!h.needle)
    return fail(ErrorCode::InvalidArgument, "the needle renderer has no needle", "engines/haptics");
  const SceneNeedle& n = *h.needle;
  std::vector<NeedleLayer> needleLayers;
  for (const SceneSoftLayer& l : layers)
    needleLayers.push_back(
        {.punctureForce = l.punctureForce, .cuttingForce = l.cuttingForce, .friction = l.friction});
  NeedleOptions options{.length = n.length,
                        .radius = n.radius,
                        .couplingSpacing = n.couplingSpacing,
                        .acrossStiffness = n.acrossStiffness,
                        .alongStiffness = n.alongStiffness};
  if (tipStiffness > 0) options.tipStiffness = tipStiffness;
  auto needle = NeedleInsertion::create(*b.fem, layerOfTet, needleLayers, options);
  if (!needle) return needle.error().within("soft");
  b.needle = std::make_unique<NeedleInsertion>(std::move(*needle));
  // The hand's limit is the haptic loop's (max_force, else the device's).
  auto felt = HapticNeedle::create(*b.needle, {.tip = n.tip,
                                               .axis = n.axis,
                                               .normal = n.normal,
                                               .tissuePose = b.pose,
                                               .maxForce = 1000.0,
                                               .maxTorque = n.maxTorque});
  if (!felt) return felt.error().within("engines/haptics/needle");
  b.felt = std::move(*felt);
  for (const SceneSoftLayer& l : layers) b.layerNames.push_back(l.name);
  return ok();
}

HapticRenderer* SoftTissues::punch() noexcept {
  for (const auto& b : bodies_)
    if (b->punch) return b->punch.get();
  return nullptr;
}

HapticRenderer* SoftTissues::needle() noexcept {
  for (const auto& b : bodies_)
    if (b->felt) return b->felt.get();
  return nullptr;
}

std::optional<SoftTissues::NeedleProgress> SoftTissues::needleProgress() const noexcept {
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    if (const NeedleInsertion* n = bodies_[i]->needle.get())
      return NeedleProgress{.punctures = n->punctureCount(), .tipLayer = n->tipLayer(), .object = i};
  return std::nullopt;
}

std::string SoftTissues::layerName(std::size_t i, int layer) const {
  if (i >= bodies_.size() || layer < 0) return {};
  const std::vector<std::string>& names = bodies_[i]->layerNames;
  return std::size_t(layer) < names.size() ? names[std::size_t(layer)] : std::string();
}

HapticTissue* SoftTissues::tissue(std::string_view name) noexcept {
  for (const auto& b : bodies_)
    if (b->name == name) return b->haptic.get();
  return nullptr;
}

void SoftTissues::worldNodes(std::size_t i, std::vector<Vec3>& x, std::vector<Vec3>& v) const {
  const Body& b = *bodies_.at(i);
  const std::vector<Vec3>& px = b.fem->positions();
  const std::vector<Vec3>& pv = b.fem->velocities();
  x.resize(px.size());
  v.resize(pv.size());
  for (std::size_t k = 0; k < px.size(); ++k) {
    x[k] = b.pose * px[k];
    v[k] = b.pose.linear() * pv[k];
  }
}

void SoftTissues::setFluidLoads(std::size_t i, std::span<const Vec3> world) {
  Body& b = *bodies_.at(i);
  const Mat3 toObject = b.pose.linear().transpose();
  b.fluidForce = Vec3::Zero();
  for (std::size_t k = 0; k < world.size(); ++k) {
    b.fem->setExternalForce(k, toObject * world[k]);
    b.fluidForce += world[k];
  }
}

const std::vector<Triangle>& SoftTissues::boundaryTriangles(std::size_t i) const {
  return bodies_.at(i)->fem->surfaceTriangles();
}

Status SoftTissues::step(double h, WorldState& state) {
  for (const auto& bp : bodies_) {
    Body& b = *bp;
    if (auto st = b.coupling->beforeTissueStep(state, h); !st)
      return st.error().within("soft object \"" + b.name + "\"");
    auto report = b.felt ? b.felt->step(h) : b.punch ? b.punch->step(h) : b.haptic->step(h);
    if (!report) return report.error().within("soft object \"" + b.name + "\"");
    b.coupling->afterTissueStep(state, h);
    ++b.steps;
    b.unconverged += !report->converged;
    b.cgIterations += static_cast<std::uint64_t>(report->cgIterations);
    b.cgMax = std::max(b.cgMax, report->cgIterations);
    b.maxToolForce = std::max(b.maxToolForce, toolForce(b).norm());
    std::vector<Vec3>& positions = b.surface->writeBuffer();  // sized at build: no allocation
    const std::vector<Vec3>& x = b.fem->positions();
    for (std::size_t i = 0; i < positions.size(); ++i) positions[i] = x[b.surfaceNodes[i]] / b.scale;
    b.surface->publish();
  }
  return ok();
}

bool SoftTissues::latestSurface(std::size_t i, Mesh& out) {
  if (i >= bodies_.size()) return false;
  Body& b = *bodies_[i];
  return latestDeformedSurface(*b.surface, b.surfaceTriangles, out);
}

// The tool's force on the tissue (body frame): the god-object's spring, or
// the reverse of the tissue's force on the needle.
Vec3 SoftTissues::toolForce(const Body& b) noexcept {
  return b.needle ? Vec3(-b.needle->force()) : b.punch ? b.punch->toolForce() : b.haptic->toolForce();
}

void SoftTissues::addBodyForces(std::span<Vec3> force) const {
  for (const auto& b : bodies_)
    for (std::size_t i = 0; i < obstacles_.size(); ++i)
      if (obstacles_[i].body.index < force.size())
        force[obstacles_[i].body.index] += b->coupling->wrench(i).force;
}

nlohmann::json SoftTissues::summary() const {
  Json list = Json::array();
  std::vector<Vec3> held;
  for (const auto& bp : bodies_) {
    const Body& b = *bp;
    const FemBody& f = *b.fem;
    double maxDisplacement = 0.0;
    for (std::size_t i = 0; i < f.nodeCount(); ++i)
      maxDisplacement = std::max(maxDisplacement, (f.positions()[i] - f.restPositions()[i]).norm());
    // What holds the body: the fixed nodes' constraint forces. At rest it
    // balances the tool and the weight.
    f.computeConstraintForces(held);
    Vec3 heldForce = Vec3::Zero();
    for (const Vec3& r : held) heldForce += r;
    const Mat3 R = b.pose.linear();
    list.push_back(
        {{"name", b.name},
         {"tets", f.tetCount()},
         {"nodes", f.nodeCount()},
         {"fixed_nodes", b.fixedNodes},
         {"surface_triangles", b.surfaceTriangles.size()},
         {"mass_kg", f.totalMass()},
         {"steps", b.steps},
         {"cg_iterations_mean", b.steps > 0 ? double(b.cgIterations) / double(b.steps) : 0.0},
         {"cg_iterations_max", b.cgMax},
         {"unconverged_steps", b.unconverged},
         {"gripped_steps", b.haptic ? b.haptic->grippedSteps() : 0},
         {"max_displacement_m", maxDisplacement},
         {"center_of_mass_displacement_m", engine_json::vec3(R * (f.centerOfMass() - b.restCenterOfMass))},
         {"tool_force_N", engine_json::vec3(R * toolForce(b))},
         {"max_tool_force_N", b.maxToolForce},
         {"held_force_N", engine_json::vec3(R * heldForce)},
         {"fluid_force_N", engine_json::vec3(b.fluidForce)},
         {"weight_N", engine_json::vec3(f.totalMass() * (R * f.gravity()))}});
    if (!obstacles_.empty()) {
      Json touching = Json::array();
      for (std::size_t i = 0; i < obstacles_.size(); ++i)
        touching.push_back({{"name", obstacles_[i].name},
                            {"dynamic", obstacles_[i].dynamic},
                            {"force_N", engine_json::vec3(b.coupling->wrench(i).force)}});
      list.back()["obstacles"] = std::move(touching);
      list.back()["obstacle_contacts"] = f.obstacleContactCount();
    }
    if (b.punch) list.back()["punch"] = {{"nodes", b.punch->nodeCount()}};
    if (b.needle) {
      static constexpr const char* kTip[] = {"outside", "pressing", "cutting", "in-track"};
      const NeedleInsertion& n = *b.needle;
      const int layer = n.tipLayer();
      list.back()["needle"] = {{"tip", kTip[static_cast<int>(n.tipState())]},
                               {"tip_layer", layer >= 0 && std::size_t(layer) < b.layerNames.size()
                                                 ? Json(b.layerNames[std::size_t(layer)])
                                                 : Json(nullptr)},
                               {"punctures", n.punctureCount()},
                               {"track_points", n.trackPointCount()},
                               {"active_couplings", n.activeCouplingCount()},
                               {"track_length_m", n.trackLength()},
                               {"force_N", engine_json::vec3(R * n.force())},
                               {"models_published", b.felt->publishedModels()}};
    }
  }
  return list;
}

}  // namespace dm
