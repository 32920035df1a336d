// dm/renderer/scene_renderer.hpp — the forward mesh renderer: dm::Mesh data
// drawn straight from the data model with Blinn–Phong, metallic–roughness PBR
// or unlit materials, directional/point/spot lights and PCF shadow maps.
//
// Resources live on the GPU behind generational handles: addMesh() uploads a
// dm::Mesh once (float vertices, uint32 indices; normals and per-vertex
// tangents computed on upload when missing), updateMesh() rewrites the vertex
// data in place while the topology stays the same (a deforming organ from
// physics), addTexture() uploads a dm::Image (any stride, RGB or OpenCV's BGR
// order) with or without mipmaps, updateTexture() replaces its pixels (a
// video frame per render frame), and addMaterial() registers a material:
// colour, normal and height textures. A height texture gives the surface
// relief by parallax occlusion mapping (a ray march through the height field,
// 8..32 layers by view angle, then a linear refinement; Material::heightScale
// metres deep); it moves the texturing, not the silhouette, depth or shadows.
// A frame is a span of DrawItems and a span of Lights: render() culls each
// item's world box against the view frustum, picks a level of detail by
// projected size, sorts what is left by program, material and mesh, and
// draws items sharing mesh and material as one instanced draw call. Shadow
// maps (one per shadow-casting directional or spot light, at most
// kMaxShadowMaps) are rendered first: orthographic light frusta fitted to
// the bounds of the visible items for directional lights, perspective ones
// for spot lights, slope-scaled depth bias, 3x3 PCF.
//
// Photometry: shaders work in linear colour (the target stores sRGB). A
// white diffuse surface facing a directional light of intensity 1 renders 1;
// point and spot intensities are that value at 1 m (inverse-square falloff,
// smoothly windowed to zero at `range`). Texture v = 0 is the image's top row.
// All calls need the owning GlContext current on the calling thread.
//
// @code
//   auto scene = dm::SceneRenderer::create();
//   dm::MeshId ball = *scene->addMesh(dm::makeIcosphere(0.02, 3));
//   dm::MaterialId red = *scene->addMaterial({.baseColor = dm::Vec4f(0.8f, 0.1f, 0.1f, 1)});
//   dm::DrawItem item{.mesh = ball, .material = red};
//   auto stats = scene->render(*target, camera, {&item, 1}, {&sun, 1});
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/renderer/camera.hpp>
#include <dm/renderer/render_target.hpp>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace dm {

class MeshBvh;

/// A generational handle to an object a SceneRenderer owns; a default one
/// (generation 0) is invalid, and a handle goes stale when its object is
/// removed (the slot may be reused under a new generation).
template <class Tag>
struct RenderHandle {
  std::uint32_t index = 0;
  std::uint32_t generation = 0;  ///< 0 = no object
  bool valid() const { return generation != 0; }
  friend bool operator==(const RenderHandle&, const RenderHandle&) = default;
};
using MeshId = RenderHandle<struct MeshTag>;
using TextureId = RenderHandle<struct TextureTag>;

/// How addTexture() reads and keeps an image.
struct SceneTextureOptions {
  bool srgb = true;     ///< colour data (sRGB-encoded); false for normal maps and other linear data
  bool bgr = false;     ///< channels in B,G,R(,A) order (OpenCV's): sampled through a texture swizzle,
                        ///< so the bytes are uploaded as they are, with no conversion
  bool mipmaps = true;  ///< full mipmap chain (trilinear); false for per-frame video (bilinear, no regeneration)
};
using MaterialId = RenderHandle<struct MaterialTag>;

/// How a material is lit.
enum class ShadingModel : std::uint8_t {
  Unlit,       ///< flat base colour (helpers, HUD geometry); lights ignored
  BlinnPhong,  ///< Lambert diffuse + Blinn specular lobe
  Pbr,         ///< metallic–roughness: Cook–Torrance GGX, Smith, Schlick
};

/// Surface appearance. Colours are linear RGB(A) in [0, 1]. The rendered
/// base colour is baseColor x colour texture x vertex colour (when enabled
/// and the mesh has colours). Opaque: alpha is not blended.
struct Material {
  ShadingModel model = ShadingModel::BlinnPhong;
  Vec4f baseColor{0.8f, 0.8f, 0.8f, 1.0f};  ///< diffuse (Blinn–Phong), base (PBR) or flat (Unlit) colour
  Vec3f specular{0.2f, 0.2f, 0.2f};         ///< Blinn–Phong specular colour
  float shininess = 32;                     ///< Blinn–Phong exponent, >= 1
  float metallic = 0;                       ///< PBR, [0, 1]
  float roughness = 0.5f;                   ///< PBR perceptual roughness, [0, 1] (clamped to >= 0.04)
  Vec3f emissive{0, 0, 0};                  ///< added to the lit colour, linear
  TextureId colorTexture;                   ///< optional; sRGB textures are decoded to linear
  TextureId normalTexture;                  ///< optional tangent-space normal map (upload with srgb = false)
  /// Optional height map for parallax occlusion mapping (upload with srgb =
  /// false): red channel, 1 = the mesh surface, 0 = `heightScale` below it.
  /// Shifts the uv of the colour, normal and height lookups; the silhouette,
  /// depth and shadows stay those of the mesh.
  TextureId heightTexture;
  /// Relief depth from height 1 to height 0, metres (world units, so the same
  /// whatever the uv mapping or tiling); finite, >= 0; 0 turns the relief off.
  float heightScale = 0;
  bool useVertexColors = true;  ///< multiply by the mesh's per-vertex colours when it has them
  bool doubleSided = false;     ///< draw back faces too (normals flipped); else back faces are culled
};

/// A light source. Directions are the way the light travels (need not be unit).
struct Light {
  enum class Type : std::uint8_t { Directional, Point, Spot };
  Type type = Type::Directional;
  Vec3 position{0, 1, 0};    ///< point, spot: world position, m
  Vec3 direction{0, -1, 0};  ///< directional, spot: travel direction, world
  Vec3f color{1, 1, 1};      ///< linear RGB
  float intensity = 1;       ///< directional: irradiance scale; point, spot: the same at 1 m
  double range = 10;         ///< point, spot: m; the falloff window reaches zero here
  double innerConeDeg = 20;  ///< spot: half-angle of full intensity, degrees
  double outerConeDeg = 30;  ///< spot: half-angle where it reaches zero (smoothstep between), degrees
  bool castsShadow = false;  ///< directional and spot lights only; the first kMaxShadowMaps get maps

  /// A directional light travelling along `dir`.
  static Light directional(const Vec3& dir, float intensity = 1, const Vec3f& color = Vec3f(1, 1, 1));
  /// A point light at `pos`.
  static Light point(const Vec3& pos, float intensity = 1, double range = 10,
                     const Vec3f& color = Vec3f(1, 1, 1));
  /// A spot light at `pos` aimed along `dir`, cone half-angles in degrees.
  static Light spot(const Vec3& pos, const Vec3& dir, double innerDeg, double outerDeg, float intensity = 1,
                    double range = 10, const Vec3f& color = Vec3f(1, 1, 1));
};

/// One object to draw: a mesh, its material and its local-to-world transform.
struct DrawItem {
  MeshId mesh;
  MaterialId material;
  Affine3 model = Affine3::Identity();  ///< local (mesh) frame to world, m
  bool visible = true;
  bool castsShadow = true;
};

/// Per-frame settings.
struct RenderSettings {
  Vec4f background{0, 0, 0, 1};        ///< linear clear colour
  Vec3f ambient{0.03f, 0.03f, 0.03f};  ///< constant ambient irradiance, linear
  bool clear = true;                   ///< clear colour and depth of the viewport first
  bool wireframe = false;              ///< draw triangle edges only
  bool shadows = true;                 ///< render shadow maps for shadow-casting lights
};

/// What a render call did (the camera passes; shadow passes counted apart).
struct RenderStats {
  int drawCalls = 0;          ///< camera-pass draw calls
  int instances = 0;          ///< camera-pass instances drawn
  std::size_t triangles = 0;  ///< camera-pass triangles submitted (instances x mesh triangles)
  int itemsCulled = 0;        ///< visible items outside the view frustum
  int clustersCulled = 0;     ///< clusters of clustered meshes (setMeshTree) outside the view frustum
  int lodSwitches = 0;        ///< items drawn with a coarser level than their base mesh
  int shadowMaps = 0;         ///< shadow maps rendered
  int shadowDrawCalls = 0;    ///< draw calls of the shadow passes
  RenderStats& operator+=(const RenderStats& o);
};

/// What the renderer holds for a mesh.
struct MeshInfo {
  std::size_t vertexCount = 0;
  std::size_t triangleCount = 0;
  Aabb bounds;                     ///< local frame, m
  int uploads = 0;                 ///< full uploads (addMesh, topology-changing updateMesh)
  int inPlaceUpdates = 0;          ///< updateMesh calls that rewrote the vertex buffer in place
  std::size_t clusters = 0;        ///< culling clusters from setMeshTree (0: drawn whole)
  std::uint32_t vertexBuffer = 0;  ///< GL name of the vertex buffer; kept by in-place updates
};

/// One coarser version of a mesh: used while the item's projected bounding
/// sphere diameter is at most `maxScreenFraction` of the viewport height (of
/// several such levels, the one with the smallest fraction wins).
struct LodLevel {
  MeshId mesh;
  double maxScreenFraction = 0.1;
};

/// Renderer-wide options.
struct SceneRendererOptions {
  int shadowMapSize = 1024;         ///< pixels per side of each shadow map, 64..8192
  float shadowSlopeBias = 2.0f;     ///< glPolygonOffset factor of the shadow pass
  float shadowNormalOffset = 1.5f;  ///< receiver offset along the normal, shadow-map texels
};

/// The forward renderer (see the file comment). Move-only; frees its GL
/// objects on destruction (with its context current).
class SceneRenderer {
 public:
  static constexpr int kMaxLights = 8;      ///< lights per frame; more fail
  static constexpr int kMaxShadowMaps = 4;  ///< shadow-casting lights beyond these render unshadowed

  /// Compiles the programs and allocates the shadow maps. Needs a current
  /// 4.5 context; fails on bad options or a driver refusal.
  /// @code
  ///   auto scene = dm::SceneRenderer::create({.shadowMapSize = 2048});
  ///   if (!scene) return scene.error();
  /// @endcode
  static Result<SceneRenderer> create(const SceneRendererOptions& options = {});

  SceneRenderer();
  SceneRenderer(SceneRenderer&&) noexcept;
  SceneRenderer& operator=(SceneRenderer&&) noexcept;
  SceneRenderer(const SceneRenderer&) = delete;
  SceneRenderer& operator=(const SceneRenderer&) = delete;
  ~SceneRenderer();

  /// Uploads a mesh (validated first: InvalidArgument naming the bad vertex
  /// or triangle). Missing normals are computed (angle-weighted), tangents are
  /// computed from uvs; the caller's mesh is not modified. O(n).
  Result<MeshId> addMesh(const Mesh& mesh);
  /// Replaces a mesh's data. Same vertex count and triangles: the vertex
  /// buffer is rewritten in place (glNamedBufferSubData, no reallocation);
  /// otherwise the mesh is re-uploaded. NotFound for a stale id. O(n).
  Status updateMesh(MeshId id, const Mesh& mesh);
  /// Cluster culling through a DMCollide tree of the mesh (one the
  /// application already has for collision or haptics, built from the same
  /// triangles): the index buffer is reordered into the tree's leaf order
  /// and cut into clusters, the largest subtrees of at most
  /// `clusterTriangles` triangles, each with its box. A single instance of
  /// the mesh then draws only the clusters inside the view frustum (one
  /// glMultiDrawElements); instanced draws and shadow passes draw it whole.
  /// In-place updateMesh() keeps the clusters and recomputes their boxes
  /// (O(n)); a topology change drops them. Fails (InvalidArgument) on a
  /// tree of other triangles or clusterTriangles = 0, NotFound for a stale
  /// id. O(n).
  /// @code
  ///   auto tree = dm::MeshBvh::build(skin);              // also the god-object's
  ///   scene->setMeshTree(skinId, *tree);                 // zoomed in: draws what is in view
  /// @endcode
  Status setMeshTree(MeshId id, const MeshBvh& tree, std::size_t clusterTriangles = 2048);
  /// Frees a mesh and its LOD list (not the LOD meshes). NotFound for a stale id.
  Status removeMesh(MeshId id);
  /// What the renderer holds for `id`; NotFound for a stale id.
  Result<MeshInfo> meshInfo(MeshId id) const;
  /// Registers coarser versions of `base` (each a mesh of this renderer);
  /// an empty list removes them. Fails on stale ids or a non-positive fraction.
  Status setLods(MeshId base, std::vector<LodLevel> levels);

  /// Uploads a U8 gray, RGB or RGBA image (any row stride, also views) with
  /// a full mipmap chain; `srgb` for colour data, false for normal maps.
  /// Unsupported for other pixel types or channel counts.
  Result<TextureId> addTexture(const Image& image, bool srgb = true);
  /// Same, with the channel order and mipmaps chosen (see SceneTextureOptions).
  /// @code
  ///   auto tex = scene->addTexture(frame, {.bgr = true, .mipmaps = false});  // an OpenCV camera frame
  /// @endcode
  Result<TextureId> addTexture(const Image& image, const SceneTextureOptions& options);
  /// Replaces the pixels of texture `id` with `image` (a video or camera
  /// frame each render frame), keeping its options. Same size and channel
  /// count: rewritten in place (one glTextureSubImage2D, mipmaps regenerated
  /// if the texture has them); otherwise new storage under the same id, so
  /// materials keep pointing at it. Fails like addTexture, or NotFound for a
  /// stale id; on failure the texture keeps its old pixels.
  Status updateTexture(TextureId id, const Image& image);
  /// Frees a texture. NotFound for a stale id.
  Status removeTexture(TextureId id);

  /// Registers a material; InvalidArgument for out-of-range values or stale textures.
  Result<MaterialId> addMaterial(const Material& material);
  /// Replaces a registered material (same checks as addMaterial).
  Status setMaterial(MaterialId id, const Material& material);
  /// Forgets a material. NotFound for a stale id.
  Status removeMaterial(MaterialId id);

  /// Draws `items` lit by `lights` (at most kMaxLights) into the whole
  /// target. Fails (drawing nothing) on an invalid camera, a stale mesh or
  /// material id in a visible item (the message gives its index), or too many
  /// lights. O(items log items) on the CPU.
  /// @code
  ///   auto stats = scene.render(target, dm::Camera::lookAt({0, 0.2, 0.5}, {0, 0, 0}), items, lights);
  ///   if (stats) dm::log::info("%d draw calls", stats->drawCalls);
  /// @endcode
  Result<RenderStats> render(const RenderTarget& target, const Camera& camera,
                             std::span<const DrawItem> items, std::span<const Light> lights,
                             const RenderSettings& settings = {});
  /// The same into a sub-rectangle of the target (aspect = its width/height).
  Result<RenderStats> render(const RenderTarget& target, const Viewport& viewport, const Camera& camera,
                             std::span<const DrawItem> items, std::span<const Light> lights,
                             const RenderSettings& settings = {});
  /// Side-by-side stereo: the left eye into the left half of the target, the
  /// right eye into the right half (Camera::stereoPair: eyes `eyeSeparation`
  /// m apart, zero parallax at `convergence` m). Shadow maps are shared.
  Result<RenderStats> renderStereo(const RenderTarget& target, const Camera& camera, double eyeSeparation,
                                   double convergence, std::span<const DrawItem> items,
                                   std::span<const Light> lights, const RenderSettings& settings = {});

  /// Statistics of the last render call.
  const RenderStats& lastStats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
