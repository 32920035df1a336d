// dm/renderer/volume_renderer.hpp — GPU volume rendering of medical volumes:
// composite ray casting, maximum intensity projection, first-hit isosurface,
// slice planes and slice views, and voxel cubes for debugging.
//
// Placement. Rays are cast in world space through the volume's own
// index-to-world affine (anisotropic spacing, rotations and mirrored axes
// included): the renderer rasterises the back faces of the volume's bounding
// box [-0.5, dims - 0.5] (voxel centres at integer indices) with the
// camera's view-projection, and each fragment unprojects its ray, moves it
// into voxel-index space with the inverse affine and marches it there. A
// mesh extracted from the same volume (dm/math/isosurface.hpp) therefore
// lines up with the rendering pixel for pixel.
//
// Depth. Before drawing, render() resolves the target and copies its depth,
// so rays stop at the opaque geometry drawn before (meshes occlude the
// volume). Composite and iso modes write the depth of their first opaque hit
// (accumulated opacity ≥ VolumeRenderSettings::depthAlpha, or the
// isosurface), so geometry drawn afterwards is hidden behind opaque tissue.
//
// Values. Each volume is uploaded as a 3-D texture normalised to [0, 1] over
// its value range [lo, hi] (R16 for 8- and 16-bit integer voxels, where the
// mapping is exact; R32F for 32-bit and floating voxels); transfer functions,
// windows and isovalues are given in the volume's own units and mapped
// through the recorded range.
//
// Empty-space skipping. addVolume() computes the min/max of every macro cell
// (8³ voxels by default, with a one-voxel apron so trilinear samples near a
// cell border are covered). setTransferFunction() marks cells whose value
// interval maps to zero opacity everywhere; rays jump over such cells to the
// next sample position beyond them. Sample positions lie on a fixed lattice
// along each ray, so skipping never changes the image (only skipped samples
// contribute nothing). MIP skips cells whose maximum cannot raise the ray's
// maximum; iso mode skips cells entirely below the isovalue.
//
// Colours are linear; alpha blending is premultiplied "over" what the target
// holds. All calls need the GlContext current on the calling thread.
//
// @code
//   auto vr = dm::VolumeRenderer::create();
//   auto id = vr->addVolume(*volume);                          // uploads; fails on oversized volumes
//   vr->setTransferFunction(*id, *dm::TransferFunction::mriSkin(0, 255));
//   rt->clear();  vr->render(*rt, camera, *id, {.mode = dm::VolumeRenderMode::Composite});
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/core/volume.hpp>
#include <dm/renderer/camera.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/transfer_function.hpp>

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>

namespace dm {

/// Handle of a volume owned by a VolumeRenderer (generational: a removed
/// volume's id stays invalid even when its slot is reused).
struct VolumeId {
  std::uint32_t index = 0;
  std::uint32_t generation = 0;  ///< 0 = never valid
  friend bool operator==(const VolumeId&, const VolumeId&) = default;
};

/// What render() draws.
enum class VolumeRenderMode : unsigned char {
  Composite,  ///< emission–absorption front to back through the transfer function, shaded
  Mip,        ///< maximum intensity projection, grey over the window
  Iso,        ///< first hit of the isovalue, Blinn–Phong shaded, opaque
  Slice,      ///< one axis-aligned world plane through the volume, textured (grey window or TF colour)
  Voxels,     ///< a flat-shaded cube per voxel at or above voxelThreshold (debugging)
};

/// World planes of slices (RAS+ world: x right, y anterior, z superior).
enum class SliceAxis : unsigned char {
  Sagittal,  ///< plane x = const
  Coronal,   ///< plane y = const
  Axial,     ///< plane z = const
};

/// Per-draw settings of render(). Values are in the volume's units unless
/// stated; NaN window bounds mean the volume's value range.
struct VolumeRenderSettings {
  VolumeRenderMode mode = VolumeRenderMode::Composite;
  Viewport viewport;              ///< where to draw; default the whole target
  double stepVoxels = 0.5;         ///< sample spacing along rays, voxel-index units (0.05..8)
  bool emptySpaceSkipping = true;  ///< jump over macro cells that cannot contribute
  double terminationAlpha = 0.99;  ///< composite: stop a ray at this accumulated opacity (1 = never)
  double depthAlpha = 0.95;        ///< composite: accumulated opacity that counts as the opaque hit (depth)
  bool writeDepth = true;          ///< composite/iso: write the opaque hit's depth
  bool shading = true;             ///< composite: gradient Blinn–Phong; off = emission only
  Vec3 lightDirection = Vec3::Zero();  ///< world direction towards the light; zero = headlight
  /// Blinn–Phong weights and exponent (Voxels: ambient + diffuse only).
  double ambient = 0.35, diffuse = 0.65, specular = 0.25, shininess = 24;
  double isoValue = 0.5;                                         ///< Iso: the surface value
  Vec3 isoColor{0.9, 0.85, 0.8};                                 ///< Iso: linear colour
  double windowLow = std::numeric_limits<double>::quiet_NaN();   ///< Mip/Slice: value shown black
  double windowHigh = std::numeric_limits<double>::quiet_NaN();  ///< Mip/Slice: value shown white
  SliceAxis sliceAxis = SliceAxis::Axial;                        ///< Slice
  Vec3 slicePosition = Vec3::Zero();                             ///< Slice: a world point on the plane, m
  bool sliceUsesTransferFunction = false;  ///< Slice/Voxels: TF colour (opaque) instead of the grey window
  double voxelThreshold = 0.5;             ///< Voxels: draw voxels with value ≥ this
  bool collectStats = false;               ///< count rays and samples (lastStats()); costs atomics
};

/// Counters of the last render() with collectStats (ray-casting modes).
struct VolumeRenderStats {
  std::uint64_t rays = 0;            ///< fragments that marched a ray through the volume
  std::uint64_t samples = 0;         ///< volume samples taken
  std::uint64_t skippedSamples = 0;  ///< sample positions jumped over by empty-space skipping
  std::uint64_t voxelsDrawn = 0;     ///< Voxels mode: cubes drawn
};

/// What addVolume() uploaded.
struct VolumeGpuInfo {
  Vec3i dims = Vec3i::Zero();
  double valueLow = 0, valueHigh = 1;  ///< value range mapped to texture [0, 1]
  bool floatTexture = false;           ///< R32F (else R16 unorm)
  Vec3i cellGrid = Vec3i::Zero();      ///< macro cells per axis
  int cellSize = 8;                    ///< voxels per macro cell edge
  std::size_t activeCells = 0;         ///< cells visible under the current transfer function
};

/// Options of addVolume().
struct VolumeUploadOptions {
  int cellSize = 8;  ///< macro cell edge for empty-space skipping, voxels (2..64)
};

/// Owns GPU copies of volumes and draws them. Move-only; destroy with the
/// context current.
class VolumeRenderer {
 public:
  /// Compiles the shader programs. Fails when no context is current or a
  /// program does not compile (the message names it).
  static Result<VolumeRenderer> create();

  VolumeRenderer();
  VolumeRenderer(VolumeRenderer&&) noexcept;
  VolumeRenderer& operator=(VolumeRenderer&&) noexcept;
  VolumeRenderer(const VolumeRenderer&) = delete;
  VolumeRenderer& operator=(const VolumeRenderer&) = delete;
  ~VolumeRenderer();

  /// Uploads a volume (any voxel type) as a normalised 3-D texture and
  /// computes its macro-cell min/max grid; the transfer function starts as a
  /// grey ramp over the value range. O(voxels). Fails (InvalidArgument) on
  /// an empty volume, non-finite values, or a dimension above
  /// GL_MAX_3D_TEXTURE_SIZE (the message names axis and limit).
  /// @code
  ///   auto id = vr.addVolume(head);
  ///   if (!id) std::cerr << id.error() << '\n';
  /// @endcode
  Result<VolumeId> addVolume(const Volume& volume, const VolumeUploadOptions& options = {});
  /// Frees a volume's GPU memory; NotFound for a stale id.
  Status removeVolume(VolumeId id);
  /// Sets the transfer function (values in the volume's units) and updates
  /// which macro cells are empty. O(cells + table). NotFound for a stale id.
  Status setTransferFunction(VolumeId id, const TransferFunction& tf);
  /// Upload facts, including the active cell count under the current TF.
  Result<VolumeGpuInfo> info(VolumeId id) const;

  /// Draws volume `id` into `target` (see VolumeRenderSettings::mode) with
  /// `camera`, blending over the target's colour and stopping at its depth.
  /// Leaves `target` bound. Fails on a stale id, an invalid camera or target,
  /// or settings out of range (naming the field).
  /// @code
  ///   dm::VolumeRenderSettings s{.mode = dm::VolumeRenderMode::Mip};
  ///   if (auto r = vr.render(rt, cam, id, s); !r) std::cerr << r.error() << '\n';
  /// @endcode
  Status render(const RenderTarget& target, const Camera& camera, VolumeId id,
                const VolumeRenderSettings& settings);

  /// A 2-D slice image: the plane `axis` through `worldPosition`, seen
  /// orthographically so the volume's in-plane extent fills `viewport` with
  /// equal metres per pixel on both axes (letterboxed), using
  /// settings.window*/sliceUsesTransferFunction. Radiological orientation:
  /// axial seen from the feet (anterior up, patient right on the image
  /// left), coronal from the front (superior up, right on the left),
  /// sagittal from the patient's left (superior up, anterior on the left).
  Status renderSliceView(const RenderTarget& target, const Viewport& viewport, VolumeId id, SliceAxis axis,
                         const Vec3& worldPosition, const VolumeRenderSettings& settings = {});
  /// The orthographic camera renderSliceView() uses for a viewport of
  /// width/height `aspect` (for mapping world points to pixels).
  Result<Camera> sliceViewCamera(VolumeId id, SliceAxis axis, const Vec3& worldPosition, double aspect) const;

  /// Counters of the last render() that had collectStats set.
  const VolumeRenderStats& lastStats() const { return stats_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  VolumeRenderStats stats_;
};

}  // namespace dm
