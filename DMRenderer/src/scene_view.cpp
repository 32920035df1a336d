// scene_view.cpp — scene description → SceneRenderer + VolumeRenderer.
#include <dm/math/primitives.hpp>
#include <dm/renderer/scene_view.hpp>
#include <dm/renderer/transfer_function.hpp>

#include <cmath>
#include <map>
#include <numbers>
#include <optional>

namespace dm {

namespace {

Vec4f toF(const Vec4& v) { return v.cast<float>(); }
Vec3f toF(const Vec3& v) { return v.cast<float>(); }

Affine3 modelMatrix(const Isometry3& pose, double scale) {
  Affine3 m = Affine3::Identity();
  m.linear() = pose.linear() * scale;
  m.translation() = pose.translation();
  return m;
}

Light toLight(const SceneLight& l) {
  const auto intensity = static_cast<float>(l.intensity);
  const double range = l.range > 0 ? l.range : 1e6;
  Light out;
  switch (l.type) {
    case SceneLight::Type::Directional:
      out = Light::directional(l.direction, intensity, toF(l.color));
      break;
    case SceneLight::Type::Point:
      out = Light::point(l.position, intensity, range, toF(l.color));
      break;
    case SceneLight::Type::Spot:
      out = Light::spot(l.position, l.direction, l.innerConeDeg, l.outerConeDeg, intensity, range,
                        toF(l.color));
      break;
  }
  out.castsShadow = l.shadows;
  return out;
}

SliceAxis toAxis(SceneVolume::Axis a) {
  switch (a) {
    case SceneVolume::Axis::Axial:
      return SliceAxis::Axial;
    case SceneVolume::Axis::Coronal:
      return SliceAxis::Coronal;
    case SceneVolume::Axis::Sagittal:
      return SliceAxis::Sagittal;
  }
  return SliceAxis::Axial;
}

Aabb worldBounds(const Volume& v) {
  Aabb box;
  const Vec3i d = v.dims();
  for (int c = 0; c < 8; ++c) {
    const Vec3 idx((c & 1) ? d.x() - 1 : 0, (c & 2) ? d.y() - 1 : 0, (c & 4) ? d.z() - 1 : 0);
    box.extend(v.indexToWorld() * idx);
  }
  return box;
}

}  // namespace

struct SceneView::Impl {
  SceneViewOptions options;
  SceneRenderer meshes;
  VolumeRenderer volumes;
  struct Object {
    std::string name;
    std::string resource;
    Isometry3 pose = Isometry3::Identity();
    double scale = 1;
    DrawItem item;
  };
  struct VolumeEntry {
    std::string name;
    VolumeId id;
    VolumeRenderSettings settings;
    bool visible = true;
  };
  struct CameraEntry {
    SceneCamera desc;
    Camera base;
    std::optional<CameraPath> path;
  };
  std::map<std::string, MeshId, std::less<>> meshByResource;
  std::vector<Object> objects;
  std::vector<VolumeEntry> volumeEntries;
  std::vector<Light> lights;
  std::vector<CameraEntry> cameras;
  Camera framing;               // when the scene has no camera
  std::vector<DrawItem> items;  // per frame, reused
  struct ParticleSet {
    std::string name;
    double radius = 0;
    MeshId sphere;
    MaterialId material;
    Vec4f color = Vec4f::Zero();
    std::vector<Vec3> positions;
    std::optional<FluidLook> surface;  // drawn by `fluid` when set
    double drawRadius = 0;
  };
  std::vector<ParticleSet> particles;
  std::optional<FluidRenderer> fluid;  // created with the first surface

  ParticleSet& particleSet(std::string_view name) {
    for (auto& p : particles)
      if (p.name == name) return p;
    return particles.emplace_back(ParticleSet{.name = std::string(name)});
  }

  Object* object(std::string_view name) {
    for (auto& o : objects)
      if (o.name == name) return &o;
    return nullptr;
  }
  const CameraEntry* cameraEntry(std::string_view name) const {
    if (name.empty()) return cameras.empty() ? nullptr : &cameras.front();
    for (const auto& c : cameras)
      if (c.desc.name == name) return &c;
    return nullptr;
  }
};

SceneView::SceneView() = default;
SceneView::SceneView(SceneView&&) noexcept = default;
SceneView& SceneView::operator=(SceneView&&) noexcept = default;
SceneView::~SceneView() = default;

Result<SceneView> SceneView::create(const SceneDesc& scene, const SceneResources& resources,
                                    const SceneViewOptions& options) {
  SceneView view;
  view.impl_ = std::make_unique<Impl>();
  Impl& im = *view.impl_;
  im.options = options;
  auto meshes = SceneRenderer::create(options.meshes);
  if (!meshes) return meshes.error();
  im.meshes = std::move(*meshes);
  auto volumes = VolumeRenderer::create();
  if (!volumes) return volumes.error();
  im.volumes = std::move(*volumes);

  // Textures, then materials.
  std::map<std::string, TextureId, std::less<>> textures;
  auto texture = [&](const std::string& name, bool srgb, const std::string& where) -> Result<TextureId> {
    if (name.empty()) return TextureId{};
    const std::string key = name + (srgb ? "#srgb" : "#linear");
    if (auto it = textures.find(key); it != textures.end()) return it->second;
    auto img = resources.image(name);
    if (!img) return fail(ErrorCode::NotFound, "image resource \"" + name + "\" was not loaded", where);
    auto id = im.meshes.addTexture(*img, srgb);
    if (!id) return id.error().within(where);
    textures.emplace(key, *id);
    return *id;
  };
  std::map<std::string, MaterialId, std::less<>> materials;
  for (const SceneMaterial& m : scene.materials) {
    const std::string where = "materials/" + m.name;
    Material mat;
    mat.model = m.model == SceneMaterial::Model::Pbr ? ShadingModel::Pbr : ShadingModel::BlinnPhong;
    mat.baseColor = toF(m.color);
    mat.specular = toF(m.specular);
    mat.shininess = static_cast<float>(m.shininess);
    mat.metallic = static_cast<float>(m.metallic);
    mat.roughness = static_cast<float>(m.roughness);
    mat.emissive = toF(m.emissive);
    auto color = texture(m.texture, true, where + "/texture");
    if (!color) return color.error();
    mat.colorTexture = *color;
    auto normal = texture(m.normalMap, false, where + "/normal_map");
    if (!normal) return normal.error();
    mat.normalTexture = *normal;
    auto height = texture(m.heightMap, false, where + "/height_map");
    if (!height) return height.error();
    mat.heightTexture = *height;
    mat.heightScale = static_cast<float>(m.heightScale);
    auto id = im.meshes.addMaterial(mat);
    if (!id) return id.error().within(where);
    materials.emplace(m.name, *id);
  }
  auto defaultMaterial = im.meshes.addMaterial(Material{});
  if (!defaultMaterial) return defaultMaterial.error();

  // Objects: one GPU mesh per resource, shared.
  Aabb sceneBox;
  for (const SceneObject& o : scene.objects) {
    const std::string where = "objects/" + o.name;
    // Drawn: render_mesh when given (e.g. a coarser skin), else the mesh.
    const std::string& drawn = o.renderMesh.empty() ? o.mesh : o.renderMesh;
    auto it = im.meshByResource.find(drawn);
    if (it == im.meshByResource.end()) {
      auto mesh = resources.mesh(drawn);
      if (!mesh)
        return fail(ErrorCode::NotFound, "mesh resource \"" + drawn + "\" was not loaded",
                    where + (o.renderMesh.empty() ? "/mesh" : "/render_mesh"));
      auto id = im.meshes.addMesh(*mesh);
      if (!id) return id.error().within(where);
      it = im.meshByResource.emplace(drawn, *id).first;
    }
    Impl::Object obj;
    obj.name = o.name;
    obj.resource = drawn;
    obj.pose = o.pose.isometry();
    obj.scale = o.scale;
    obj.item.mesh = it->second;
    auto mat = materials.find(o.material);
    obj.item.material = mat != materials.end() ? mat->second : *defaultMaterial;
    obj.item.model = modelMatrix(obj.pose, obj.scale);
    obj.item.visible = o.visible;
    if (o.visible)
      if (auto info = im.meshes.meshInfo(it->second); info && !info->bounds.isEmpty())
        for (int c = 0; c < 8; ++c)
          sceneBox.extend(obj.item.model * info->bounds.corner(static_cast<Aabb::CornerType>(c)));
    im.objects.push_back(std::move(obj));
  }

  // Volumes with their transfer functions.
  for (const SceneVolume& v : scene.volumes) {
    const std::string where = "volumes/" + v.name;
    auto vol = resources.volume(v.volume);
    if (!vol)
      return fail(ErrorCode::NotFound, "volume resource \"" + v.volume + "\" was not loaded",
                  where + "/volume");
    auto id = im.volumes.addVolume(*vol);
    if (!id) return id.error().within(where);
    if (!v.transferFunction.empty()) {
      std::vector<TfControlPoint> points;
      for (const SceneTransferPoint& p : v.transferFunction) points.push_back({p.value, p.rgba});
      auto tf = TransferFunction::create(std::move(points));
      if (!tf) return tf.error().within(where + "/transfer_function");
      if (auto s = im.volumes.setTransferFunction(*id, *tf); !s) return s.error().within(where);
    }
    Impl::VolumeEntry e;
    e.name = v.name;
    e.id = *id;
    e.visible = v.visible;
    e.settings.stepVoxels = options.volumeStepVoxels;
    const Aabb box = worldBounds(*vol);
    switch (v.mode) {
      case SceneVolume::Mode::Composite:
        e.settings.mode = VolumeRenderMode::Composite;
        break;
      case SceneVolume::Mode::Mip:
        e.settings.mode = VolumeRenderMode::Mip;
        break;
      case SceneVolume::Mode::Slice: {
        e.settings.mode = VolumeRenderMode::Slice;
        e.settings.sliceAxis = toAxis(v.sliceAxis);
        Vec3 p = box.center();
        const int axis = v.sliceAxis == SceneVolume::Axis::Sagittal  ? 0
                         : v.sliceAxis == SceneVolume::Axis::Coronal ? 1
                                                                     : 2;
        p[axis] = v.slicePosition;
        e.settings.slicePosition = p;
        e.settings.sliceUsesTransferFunction = !v.transferFunction.empty();
        break;
      }
    }
    if (v.visible) sceneBox.extend(box);
    im.volumeEntries.push_back(e);
  }

  for (const SceneLight& l : scene.lights) im.lights.push_back(toLight(l));
  if (im.lights.empty()) im.lights.push_back(Light::directional(Vec3(-0.4, -0.5, -0.75), 1.0f));

  for (const SceneCamera& c : scene.cameras) {
    Impl::CameraEntry e;
    e.desc = c;
    e.base.projection = c.projection == SceneCamera::Projection::Orthographic
                            ? Camera::Projection::Orthographic
                            : Camera::Projection::Perspective;
    e.base.fovYDeg = c.fovYDeg;
    e.base.orthoHeight = c.orthoHeight;
    e.base.position = c.position;
    e.base.target = c.target;
    e.base.up = c.up;
    e.base.nearPlane = c.near;
    e.base.farPlane = c.far;
    if (!c.path.empty()) {
      std::vector<CameraKey> keys;
      for (const SceneCameraKey& k : c.path) keys.push_back({k.t, k.position, k.target});
      auto path = CameraPath::create(std::move(keys));
      if (!path) return path.error().within("cameras/" + c.name);
      e.path = std::move(*path);
    }
    if (auto s = e.base.validate(); !s && c.path.empty()) return s.error().within("cameras/" + c.name);
    im.cameras.push_back(std::move(e));
  }
  // Default framing: the whole scene from the front right, z up (RAS).
  const Vec3 centre = sceneBox.isEmpty() ? Vec3(Vec3::Zero()) : Vec3(sceneBox.center());
  const double radius = sceneBox.isEmpty() ? 1.0 : std::max(0.5 * sceneBox.diagonal().norm(), 1e-3);
  im.framing.fovYDeg = 35;
  const double dist = radius / std::sin(im.framing.fovYDeg * std::numbers::pi / 360.0) * 1.05;
  im.framing = Camera::lookAt(centre + dist * Vec3(0.55, 0.75, 0.37).normalized(), centre, Vec3(0, 0, 1));
  im.framing.fovYDeg = 35;
  im.framing.nearPlane = std::max(dist - 2 * radius, dist * 0.01);
  im.framing.farPlane = dist + 2 * radius;
  return view;
}

Status SceneView::setObjectPose(std::string_view name, const Isometry3& pose) {
  Impl::Object* o = impl_->object(name);
  if (o == nullptr) return fail(ErrorCode::NotFound, "no object \"" + std::string(name) + "\"", "SceneView");
  o->pose = pose;
  o->item.model = modelMatrix(pose, o->scale);
  return ok();
}

Status SceneView::setObjectVisible(std::string_view name, bool visible) {
  Impl::Object* o = impl_->object(name);
  if (o == nullptr) return fail(ErrorCode::NotFound, "no object \"" + std::string(name) + "\"", "SceneView");
  o->item.visible = visible;
  return ok();
}

Status SceneView::updateObjectMesh(std::string_view name, const Mesh& mesh) {
  Impl::Object* o = impl_->object(name);
  if (o == nullptr) return fail(ErrorCode::NotFound, "no object \"" + std::string(name) + "\"", "SceneView");
  return impl_->meshes.updateMesh(o->item.mesh, mesh);
}

Result<Isometry3> SceneView::objectPose(std::string_view name) const {
  const Impl::Object* o = impl_->object(name);
  if (o == nullptr) return fail(ErrorCode::NotFound, "no object \"" + std::string(name) + "\"", "SceneView");
  return o->pose;
}

Result<Camera> SceneView::camera(std::string_view name, double t) const {
  const Impl::CameraEntry* e = impl_->cameraEntry(name);
  if (e == nullptr) {
    if (name.empty()) return impl_->framing;
    return fail(ErrorCode::NotFound, "no camera \"" + std::string(name) + "\"", "SceneView",
                "name one of the scene's cameras, or none for the first");
  }
  Camera c = e->path ? e->path->at(e->base, t) : e->base;
  if (!e->desc.track.empty()) {
    auto pose = objectPose(e->desc.track);
    if (!pose) return pose.error();
    c.target = pose->translation();
  }
  if (auto s = c.validate(); !s) return s.error().within("cameras/" + e->desc.name);
  return c;
}

bool SceneView::isStereo(std::string_view name) const {
  const Impl::CameraEntry* e = impl_->cameraEntry(name);
  return e != nullptr && e->desc.stereo;
}

Result<SceneFrameStats> SceneView::render(const RenderTarget& target, std::string_view cameraName, double t) {
  auto cam = camera(cameraName, t);
  if (!cam) return cam.error();
  const Impl::CameraEntry* e = impl_->cameraEntry(cameraName);
  return renderImpl(target, *cam, e != nullptr && e->desc.stereo ? &e->desc : nullptr);
}

Result<SceneFrameStats> SceneView::render(const RenderTarget& target, const Camera& camera) {
  return renderImpl(target, camera, nullptr);
}

Result<SceneFrameStats> SceneView::renderImpl(const RenderTarget& target, const Camera& cam,
                                              const SceneCamera* stereo) {
  Impl& im = *impl_;
  im.items.clear();
  for (const auto& o : im.objects) im.items.push_back(o.item);
  for (const auto& set : im.particles)
    if (!set.surface)
      for (const Vec3& p : set.positions) {
        DrawItem item{.mesh = set.sphere, .material = set.material};
        item.model.translation() = p;
        im.items.push_back(item);
      }
  RenderSettings settings;
  settings.background = im.options.background;
  settings.ambient = im.options.ambient;
  SceneFrameStats stats;
  Result<RenderStats> r = stereo ? im.meshes.renderStereo(target, cam, stereo->eyeSeparation,
                                                          stereo->convergence, im.items, im.lights, settings)
                                 : im.meshes.render(target, cam, im.items, im.lights, settings);
  if (!r) return r.error();
  stats.meshes = *r;
  // Liquid surfaces over the meshes (they refract and are hidden by them).
  for (const auto& set : im.particles) {
    if (!set.surface || set.positions.empty()) continue;
    auto draw = [&](const Camera& eye, const Viewport& vp) -> Status {
      auto f = im.fluid->render(target, eye, set.positions, set.drawRadius, *set.surface, im.lights,
                                im.options.ambient, vp);
      if (!f) return f.error().within("particles/" + set.name);
      return ok();
    };
    if (stereo) {
      const auto [left, right] = cam.stereoPair(stereo->eyeSeparation, stereo->convergence);
      const int half = target.width() / 2;
      if (auto st = draw(left, {0, 0, half, target.height()}); !st) return st.error();
      if (auto st = draw(right, {half, 0, target.width() - half, target.height()}); !st) return st.error();
    } else if (auto st = draw(cam, {}); !st) {
      return st.error();
    }
  }
  // Volumes over the meshes: rays stop at the depth the meshes left.
  for (const auto& v : im.volumeEntries) {
    if (!v.visible) continue;
    if (stereo) {
      const auto [left, right] = cam.stereoPair(stereo->eyeSeparation, stereo->convergence);
      const int half = target.width() / 2;
      VolumeRenderSettings s = v.settings;
      s.viewport = {0, 0, half, target.height()};
      if (auto st = im.volumes.render(target, left, v.id, s); !st)
        return st.error().within("volumes/" + v.name);
      s.viewport = {half, 0, target.width() - half, target.height()};
      if (auto st = im.volumes.render(target, right, v.id, s); !st)
        return st.error().within("volumes/" + v.name);
    } else if (auto st = im.volumes.render(target, cam, v.id, v.settings); !st) {
      return st.error().within("volumes/" + v.name);
    }
    ++stats.volumes;
  }
  return stats;
}

Status SceneView::setParticles(std::string_view name, std::span<const Vec3> positions, double radius,
                               const Vec4f& color) {
  if (!(radius > 0.0) || !std::isfinite(radius))
    return fail(ErrorCode::InvalidArgument, formatString("particle radius %g m", radius),
                "particles/" + std::string(name), "a positive radius, e.g. half the particle spacing");
  Impl& im = *impl_;
  Impl::ParticleSet* set = &im.particleSet(name);
  if (!set->sphere.valid() || set->radius != radius) {
    if (set->sphere.valid()) (void)im.meshes.removeMesh(set->sphere);
    auto mesh = im.meshes.addMesh(makeIcosphere(radius, 1));  // 80 triangles: a droplet on screen
    if (!mesh) return mesh.error().within("particles/" + std::string(name));
    set->sphere = *mesh;
    set->radius = radius;
  }
  if (!set->material.valid() || set->color != color) {
    if (set->material.valid()) (void)im.meshes.removeMaterial(set->material);
    auto material =
        im.meshes.addMaterial({.baseColor = color, .specular = Vec3f(0.5f, 0.5f, 0.5f), .shininess = 64});
    if (!material) return material.error().within("particles/" + std::string(name));
    set->material = *material;
    set->color = color;
  }
  set->positions.assign(positions.begin(), positions.end());
  return ok();
}

Status SceneView::setParticleSurface(std::string_view name, const std::optional<FluidLook>& look,
                                     double drawRadius) {
  if (look && (!(drawRadius > 0.0) || !std::isfinite(drawRadius)))
    return fail(ErrorCode::InvalidArgument, formatString("particle draw radius %g m", drawRadius),
                "particles/" + std::string(name), "a positive radius, e.g. 3/4 of the particle spacing");
  Impl& im = *impl_;
  if (look && !im.fluid) {
    auto fluid = FluidRenderer::create();
    if (!fluid) return fluid.error().within("particles/" + std::string(name));
    im.fluid = std::move(*fluid);
  }
  Impl::ParticleSet& set = im.particleSet(name);
  set.surface = look;
  set.drawRadius = drawRadius;
  return ok();
}

SceneRenderer& SceneView::meshRenderer() { return impl_->meshes; }
VolumeRenderer& SceneView::volumeRenderer() { return impl_->volumes; }

}  // namespace dm
