// dm/renderer/fluid_renderer.hpp — screen-space fluid rendering: a particle
// fluid (dm::SphFluid's positions) drawn as a smooth, refracting, absorbing
// liquid surface over an already rendered scene, headless like the rest.
//
// The method of van der Laan, Green and Sainz (I3D 2009), as Green's
// "Screen Space Fluid Rendering for Games" (GDC 2010) lays it out, in five
// passes into buffers the size of the viewport:
//   1. depth: each particle a camera-facing quad whose fragments intersect
//      the view ray with the particle's sphere (exact for perspective and
//      orthographic cameras); the nearest hit's eye depth is kept, and a hit
//      behind the scene's own depth (a mesh in front) is discarded;
//   2. thickness: the same spheres' chord lengths summed with additive
//      blending, scaled by particleVolume / (4/3 π r³) so that a lattice of
//      particles integrates to the fluid's true depth along the ray;
//   3. smoothing: `smoothingIterations` separable bilateral passes over the
//      eye depth (spatial radius `smoothingRadius` particle radii on screen,
//      range weight Tukey's biweight (1 − (Δz / 2r)²)², nothing beyond two
//      radii; at most 16 pixels each way), which turn the bumps of the spheres
//      and the steps between particle layers into one surface and keep
//      silhouettes against fluid lying well behind; the thickness is
//      blurred once with the same radius;
//   4. normals: the view-space position reconstructed from the smoothed
//      depth, differenced with the neighbour whose depth is closer
//      (forward or backward), so edges do not bend the normal;
//   5. composite: Schlick's Fresnel with `fresnelF0` splits reflection
//      (ambient and Blinn–Phong highlights of the scene's lights) from
//      transmission; the transmitted part is the scene behind, shifted by
//      the normal's screen tilt × `refractionPixels` and attenuated by
//      Beer–Lambert, exp(−σ t), plus the body colour, diffusely lit, in
//      the proportion 1 − exp(−σ̄ t) the mean absorption σ̄ hides the scene.
// The surface's depth is written, so what is drawn later (volumes, the HUD)
// is occluded by the fluid as by a mesh.
//
// @code
//   auto fluid = dm::FluidRenderer::create();
//   sceneRenderer.render(rt, cam, items, lights, settings);   // opaque scene first
//   dm::FluidLook look = dm::FluidLook::fromTransmittance({0.5f, 0.02f, 0.02f}, 1e-3f);
//   look.particleVolume = spacing * spacing * spacing;
//   fluid->render(rt, cam, positions, 0.5 * spacing, look, lights, ambient);
// @endcode
#pragma once

#include <dm/core/image.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/renderer/camera.hpp>
#include <dm/renderer/render_target.hpp>
#include <dm/renderer/scene_renderer.hpp>

#include <memory>
#include <span>

namespace dm {

/// How a fluid surface looks. Colours are linear RGB.
struct FluidLook {
  Vec3f color{0.30f, 0.01f, 0.01f};            ///< body colour: what a thick layer shows, diffusely lit
  Vec3f absorption{700.0f, 3900.0f, 3900.0f};  ///< Beer–Lambert σ per channel, 1/m (blood-like)
  float fresnelF0 = 0.02f;         ///< reflectance at normal incidence (water 0.020, blood about 0.025)
  float specular = 1.0f;           ///< scale of the lights' Blinn–Phong highlights
  float shininess = 200.0f;        ///< Blinn–Phong exponent of those highlights
  float refractionPixels = 12.0f;  ///< background shift, pixels per unit of the normal's screen tilt
  int smoothingIterations = 3;     ///< bilateral passes over the depth (each horizontal + vertical), 0..16
  float smoothingRadius = 2.0f;    ///< filter radius in particle radii (on screen), > 0
  float particleVolume = 0;        ///< m³ each particle stands for (the spacing³); 0 = its sphere's volume

  /// A look whose layer `depth` m thick transmits `transmittance` of the
  /// light behind it per channel (σ = −ln(transmittance) / depth, each
  /// channel clamped to [1e-4, 1]); the body colour is `transmittance` too.
  static FluidLook fromTransmittance(const Vec3f& transmittance, float depth);
};

/// What one FluidRenderer::render() drew.
struct FluidRenderStats {
  int particles = 0;  ///< particles sent to the GPU
  int width = 0;      ///< size of the fluid's buffers (the viewport), pixels
  int height = 0;
};

/// Draws particle fluids over a rendered scene (see the file comment).
/// Move-only; frees its GL objects with its context current.
class FluidRenderer {
 public:
  /// Compiles the passes' programs. Fails when no GL 4.5 context is current.
  static Result<FluidRenderer> create();

  FluidRenderer();
  FluidRenderer(FluidRenderer&&) noexcept;
  FluidRenderer& operator=(FluidRenderer&&) noexcept;
  FluidRenderer(const FluidRenderer&) = delete;
  FluidRenderer& operator=(const FluidRenderer&) = delete;
  ~FluidRenderer();

  /// Draws the particles at `positions` (world, m), spheres of `radius` m,
  /// into `viewport` of `target` (whole target when empty) as seen by
  /// `camera`, over what the target holds (its colour is what refracts, its
  /// depth what occludes). `lights` (at most 8) and `ambient` light the
  /// surface as SceneRenderer lights meshes (shadows aside). Fails naming
  /// the field on a radius or look out of range, or on more than 8 lights;
  /// no particles draws nothing.
  Result<FluidRenderStats> render(const RenderTarget& target, const Camera& camera,
                                  std::span<const Vec3> positions, double radius, const FluidLook& look,
                                  std::span<const Light> lights, const Vec3f& ambient,
                                  const Viewport& viewport = {});

  /// The last render's buffers, rows top to bottom, F32, one channel, the
  /// viewport's size: eye depth of the nearest sphere hit (m, 0 where no
  /// fluid), the same after smoothing, and the fluid's thickness (m).
  Result<Image> readRawDepth() const;
  Result<Image> readSmoothedDepth() const;
  Result<Image> readThickness() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace dm
