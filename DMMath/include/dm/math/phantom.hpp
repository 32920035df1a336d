// dm/math/phantom.hpp — CT-like phantoms from analytic shapes, in Hounsfield
// units: bone data with known geometry for drilling, for tests and for
// scenes, since no real CT volume ships with the project's data
// (docs/phantoms.md says what each one models and where its numbers come
// from).
//
// The calvarium phantom is the vertex of an adult skull as a pre-operative
// CT shows it: concentric spherical layers about a centre at (0, 0, −radius),
// so the outer table's surface has its apex at the origin with +z its
// outward normal. From outside in (HU defaults): air (−1000 HU); scalp
// (soft tissue, 40 HU); outer table (cortical bone, 1800 HU); diploë
// (cancellous bone, 700 HU, with a trabecular texture of ±textureHu);
// inner table (cortical); dura (60 HU); brain (35 HU).
// Each voxel's value is the volume-weighted mean of the layers it holds —
// CT's partial-volume effect — computed exactly for a plane through the
// voxel (the layer boundary's curvature within a voxel, h²/(8·radius), is
// below 1e-4 voxel at the defaults), so a voxel's bone fraction is
// (I − empty)/(cortical − empty) wherever bone meets one soft value
// (scalp above, dura below, as in a patient's scan: bone meets air only
// where the scalp is cut, which the scan predates).
// The texture is smooth value noise (hashed lattice of `textureScale`,
// seeded), deterministic across machines.
//
// @code
//   dm::CalvariumPhantom p;             // 40 × 40 mm patch, 0.3 mm voxels
//   auto ct = dm::makeCalvariumPhantom(p);   // I16 HU, z up, apex at 0
//   dm::writeVolume(*ct, "calvarium.nrrd");  // any CT tool reads it
// @endcode
#pragma once

#include <dm/core/result.hpp>
#include <dm/core/volume.hpp>

#include <cstdint>

namespace dm {

/// A patch of skull vault with scalp, dura and brain (see the file comment).
/// Lengths in metres, values in Hounsfield units.
struct CalvariumPhantom {
  double spacing = 0.3e-3;     ///< isotropic voxel size, > 0
  double halfWidth = 0.02;     ///< the grid covers |x|, |y| ≤ halfWidth, > 0
  double above = 0.008;        ///< the grid reaches this far above the apex, ≥ 0
  double below = 0.010;        ///< and this far below it, > 0
  double radius = 0.09;        ///< radius of the outer table's surface, > halfWidth
  double scalp = 0.006;        ///< scalp thickness, ≥ 0 (0: none)
  double outerTable = 0.0015;  ///< > 0
  double diploe = 0.0035;      ///< ≥ 0
  double innerTable = 0.0010;  ///< > 0
  double dura = 0.0005;        ///< ≥ 0
  double airHu = -1000.0;
  double softTissueHu = 40.0;  ///< scalp
  double corticalHu = 1800.0;  ///< outer and inner table
  double diploeHu = 700.0;     ///< mean of the cancellous layer
  double duraHu = 60.0;
  double brainHu = 35.0;
  double textureHu = 250.0;      ///< amplitude of the diploë's texture, ≥ 0 (0: uniform)
  double textureScale = 0.0008;  ///< lattice spacing of the texture, ≥ 1e-6
  std::uint32_t seed = 1;        ///< the texture's

  bool operator==(const CalvariumPhantom&) const = default;
};

/// Checks the options' ranges; the error names the field.
Status validate(const CalvariumPhantom& p);

/// The scan's dimensions: round(2·halfWidth/spacing) across, and
/// round((above + below)/spacing) up, each at least 1. The options must be
/// valid.
Vec3i calvariumPhantomDims(const CalvariumPhantom& p) noexcept;

/// The phantom's scan: I16 HU (saturated to the type's range), axis-aligned,
/// voxel centres symmetric about the z axis from z = −below + spacing/2
/// upwards. InvalidArgument for bad options (see validate), or when the
/// grid's bytes exceed `maxBytes`.
Result<Volume> makeCalvariumPhantom(const CalvariumPhantom& p,
                                    std::size_t maxBytes = Volume::kDefaultMaxBytes);

/// The fraction of an axis-aligned cube of side `h` centred at `centre` that
/// lies on the negative side of the plane n·x < offset (n a unit normal):
/// exact, the partial volume a CT voxel cut by a flat boundary sees.
double cubeFractionBelowPlane(const Vec3& centre, double h, const Vec3& n, double offset) noexcept;

}  // namespace dm
