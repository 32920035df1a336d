// surgery.cpp — the millable bone, critical structures and burr of a scene.
#include "surgery.hpp"

#include <dm/collide/voxel_model.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/io/scene_resources.hpp>
#include <dm/math/mesh_topology.hpp>
#include <dm/math/voxelize.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace dm {

namespace {

// The mesh of object `o` in the frame `toFrame` (object frame → that
// frame), its scale baked in and coincident vertices welded: voxelizing
// needs a closed 2-manifold, and shapes with sharp rims (a cylinder — the
// typical nerve or vessel) duplicate their rim vertices for the normals.
Result<Mesh> placedMesh(const SceneResources& resources, const SceneObject& o, const Isometry3& toFrame) {
  auto mesh = resources.mesh(o.mesh);
  if (!mesh) return fail(ErrorCode::NotFound, "mesh \"" + o.mesh + "\" was not loaded", "objects/" + o.name);
  Mesh m = *mesh;
  m.normals.clear();
  Affine3 t(toFrame.matrix());
  t.scale(o.scale);
  m.transform(t);
  if (auto w = weldVertices(m, 0.0); !w) return w.error().within("objects/" + o.name);
  return m;
}

// The bone's signed distance on the grid it is milled on (m, negative
// inside): its mesh voxelized at `voxel_size`, or, from a CT volume, the
// distance that gives each voxel its partial-volume occupancy
// o = clamp((I − empty) / (full − empty)) through MillableVolume::fromSdf's
// o = clamp(1/2 − d/h), i.e. d = (1/2 − o)·h.
Result<Volume> boneDistance(const SceneResources& resources, const SceneObject& bone) {
  const SceneMillable& m = *bone.millable;
  const std::string where = "objects/" + bone.name + "/millable";
  if (m.volume.empty()) {
    auto mesh = placedMesh(resources, bone, Isometry3::Identity());
    if (!mesh) return mesh.error();
    auto sdf = voxelizeMesh(*mesh, {.voxelSize = m.voxelSize, .paddingVoxels = 2, .signedDistance = true});
    if (!sdf) return sdf.error().within(where);
    return sdf;
  }
  auto ct = resources.volume(m.volume);
  if (!ct) return fail(ErrorCode::NotFound, "volume \"" + m.volume + "\" was not loaded", where + "/volume");
  auto sdf = Volume::create(ct->dims(), VoxelType::F32, ct->indexToWorld());
  if (!sdf) return sdf.error().within(where);
  const double h = ct->spacing().minCoeff();
  float* d = sdf->data<float>();
  for (std::size_t v = 0; v < ct->voxelCount(); ++v) {
    const double value = ct->valueAt(v);
    if (!std::isfinite(value))
      return fail(ErrorCode::InvalidArgument, "voxel " + std::to_string(v) + " of the volume is not finite",
                  where + "/volume");
    const double o = std::clamp((value - m.empty) / (m.full - m.empty), 0.0, 1.0);
    d[v] = static_cast<float>((0.5 - o) * h);
  }
  return sdf;
}

}  // namespace

Result<SceneBurrBuild> buildSceneBurr(const SceneDesc& scene, const SceneResources& resources) {
  const SceneHapticsEngine& h = *scene.engines.haptics;
  const std::string where = "engines/haptics";
  const SceneObject* bone = h.objects.size() == 1 ? scene.object(h.objects[0]) : nullptr;
  if (bone == nullptr || !bone->millable || !h.burr)
    return fail(ErrorCode::InvalidArgument,
                "the burr renderer needs one millable object and a \"burr\" block", where);
  const std::string boneWhere = "objects/" + bone->name;
  const SceneMaterial* mat = scene.material(bone->material);
  if (mat == nullptr || !mat->haptic)
    return fail(ErrorCode::InvalidArgument, "the millable object has no haptic material",
                boneWhere + "/material", "give its material a \"haptic\" block with the stiffness (N/m)");
  auto sdf = boneDistance(resources, *bone);
  if (!sdf) return sdf.error();
  const double voxel = bone->millable->volume.empty() ? bone->millable->voxelSize : sdf->spacing().minCoeff();

  // The parts inside the bone (critical structures and inclusions), in the
  // bone's frame and in scene order, a later part taking the voxels it shares
  // with an earlier one: each is a material where it lies inside the grid,
  // with the union of bone and part as the occupancy (a burr can cut into a
  // nerve); the critical ones together are the distance the burr measures.
  std::vector<MillingMaterial> materials{
      {.name = bone->material.empty() ? bone->name : bone->material, .hardness = bone->millable->hardness}};
  const Vec4 boneColor = mat->color;
  std::vector<Vec4f> colors{Vec4f::Ones()};  // multiplied by the bone material's colour
  const Isometry3 boneInverse = bone->pose.isometry().inverse();
  std::vector<std::shared_ptr<const VoxelModel>> critical;
  auto labels = Volume::create(sdf->dims(), VoxelType::U8, sdf->indexToWorld());
  if (!labels) return labels.error().within(boneWhere);
  float* d = sdf->data<float>();
  std::uint8_t* label = labels->data<std::uint8_t>();
  for (const SceneObject& c : scene.objects) {
    if (!c.critical && !c.inclusion) continue;
    const std::string key = c.critical ? "critical" : "inclusion";
    const std::string cWhere = "objects/" + c.name;
    if (materials.size() == 256)
      return fail(ErrorCode::InvalidArgument, "more than 255 parts inside the bone", cWhere);
    auto cm = placedMesh(resources, c, boneInverse * c.pose.isometry());
    if (!cm) return cm.error();
    auto model = VoxelModel::fromMesh(*cm, {.voxelSize = voxel, .paddingVoxels = 2});
    if (!model) return model.error().within(cWhere + "/" + key);
    const auto index = static_cast<std::uint8_t>(materials.size());
    materials.push_back({.name = c.name,
                         .hardness = c.critical ? c.critical->hardness : c.inclusion->hardness,
                         .forbidden = c.critical.has_value()});
    // Its own colour where it shows, relative to the bone's.
    const SceneMaterial* cmat = scene.material(c.material);
    const Vec4 want = cmat != nullptr ? cmat->color : boneColor;
    Vec4f rel;
    for (int ch = 0; ch < 4; ++ch)
      rel[ch] = static_cast<float>(boneColor[ch] > 0 ? std::clamp(want[ch] / boneColor[ch], 0.0, 1.0) : 1.0);
    colors.push_back(rel);
    const Vec3i n = sdf->dims();
    std::size_t v = 0;
    for (int k = 0; k < n.z(); ++k)
      for (int j = 0; j < n.y(); ++j)
        for (int i = 0; i < n.x(); ++i, ++v) {
          const double dc = (*model)->distance(sdf->indexToWorld() * Vec3(i, j, k));
          if (!(dc < 0.5 * voxel)) continue;  // beyond the part's partial-volume ramp
          // Inside the part, or where its surface reaches as far as the
          // bone's (a layer sharing the bone's face owns the surface voxels;
          // the two voxelizations agree there to a small part of a voxel).
          if (dc < 0.0 || dc <= d[v] + 0.05 * voxel) label[v] = index;
          if (dc < d[v]) d[v] = static_cast<float>(dc);
        }
    if (c.critical) critical.push_back(*model);
  }
  auto volume = MillableVolume::fromSdf(*sdf, materials[0]);
  if (!volume) return volume.error().within(boneWhere + "/millable");
  if (auto s = volume->setMaterials(materials, &*labels); !s) return s.error().within(boneWhere);

  BurrOptions o;
  const SceneBurr& b = *h.burr;
  o.tool = b.shape == SceneBurr::Shape::Cylinder ? MillingTool::cylinder(b.radius, b.halfLength)
                                                 : MillingTool::sphere(b.radius);
  o.stiffness = mat->haptic->stiffness;
  o.damping = mat->haptic->damping;
  o.rpm = b.rpm;
  o.wearCoefficient = b.wear;
  o.walkCoefficient = b.walk;
  o.vibrationAmplitude = b.vibration;
  o.vibrationHz = b.vibrationHz;
  o.warningDistance = b.warningDistance;
  if (h.maxForce > 0) o.maxForce = h.maxForce;
  o.critical = std::move(critical);
  auto shared = std::make_shared<MillableVolume>(std::move(*volume));
  SceneBurrBuild out;
  auto feed = MillableSurfaceFeed::create(*shared, std::move(colors));
  if (!feed) return feed.error().within(boneWhere);
  out.feed = std::move(*feed);
  auto renderer = BurrRenderer::create(shared, o);
  if (!renderer) return renderer.error().within(where + "/burr");
  (*renderer)->setObjectPose(0, bone->pose.isometry());
  out.renderer = std::move(*renderer);
  out.object = bone->name;
  out.initialVolume = out.renderer->volume().materialVolume();
  return out;
}

nlohmann::json burrSummary(const BurrRenderer& burr, const MillableSurfaceFeed* feed, double initialVolume) {
  const MillableVolume& v = burr.volume();
  const BurrMetrics& m = burr.metrics();
  nlohmann::json removed = nlohmann::json::object();
  for (std::size_t k = 0; k < v.materials().size(); ++k) removed[v.materials()[k].name] = v.removedVolume(k);
  nlohmann::json j = {{"removed_m3", removed},
                      {"removed_total_m3", m.removed},
                      {"removed_forbidden_m3", m.removedForbidden},
                      {"initial_m3", initialVolume},
                      {"remaining_m3", v.materialVolume()},
                      {"seconds_within_warning", m.secondsWithinWarning},
                      {"rpm", burr.rpm()},
                      {"voxel_size_m", v.voxelSize()},
                      {"dims", {v.dims().x(), v.dims().y(), v.dims().z()}}};
  j["closest_approach_m"] =
      std::isfinite(m.closestApproach) ? nlohmann::json(m.closestApproach) : nlohmann::json();
  if (feed != nullptr) j["surface_blocks_sent"] = feed->blocksSent();
  return j;
}

}  // namespace dm
