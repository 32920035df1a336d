// dm/physics/blade.hpp — the resistance tissue puts up to a cutting blade,
// felt at the haptic rate.
//
// What it is for: a scalpel or scissors felt at 1 kHz while the tissue is
// cut at the physics rate (dm::TetCutter): the blade meets resistance until
// the force on it reaches what the material needs to fracture, then the cut
// advances with the hand.
//
// Model (Mahvash & Hayward 2001, "Haptic rendering of cutting: a fracture
// mechanics approach", Haptics-e 2(3); Atkins 2009, "The science and
// engineering of cutting"): cutting a crack of area dA takes the energy
// J·dA, J the material's fracture toughness (J/m², an energy per cut area).
// A blade whose edge is engaged over a length w and advances by ds cuts
// dA = w·ds, so the force along the advance is J·w. BladeResistance keeps
// the cut's front (where the edge has cut to) and the blade's cutting
// direction u (the way its edge faces, given each tick):
//  * behind the front (in the cut already made) the blade moves freely;
//  * ahead of it by a, the tissue holds the blade's cutting point at the
//    front: the hand feels k·a back along u (k the coupling stiffness);
//  * once k·a reaches J·w the front advances with the device, a = J·w/k,
//    and the force stays J·w.
// Across u the blade is not held (the tissue's elastic grip on the blade's
// sides is the FEM's, not this model's). The work the hand does while
// cutting is J times the area cut plus the spring's energy (energy
// balance), and the spring holds at most ½(J·w)²/k: the loop is passive,
// like a friction proxy. The front's path, at the physics rate, is the
// path the edge sweeps (dm::bladeSweep) to cut the mesh. Disengaged (w = 0)
// the front follows the device: the next cut starts where the blade enters.
//
// Real-time: tick() does not allocate, lock or throw; a non-finite input
// gives zero force and keeps the proxy; the force is clamped to maxForce.
//
// @code
//   auto blade = dm::BladeResistance::create({.toughness = 800.0, .stiffness = 1500.0});
//   blade->reset(deviceTip);
//   // 1 kHz: w from the physics thread (the edge's length inside the tissue)
//   dm::Vec3 onHand = blade->tick(deviceTip, edgeFacing, engagedLength);
// @endcode
#pragma once

#include <dm/core/mesh.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

namespace dm {

/// The length (m) of the segment a→b (a blade's edge) inside a closed,
/// outward-facing surface (the tissue's boundary at its current positions,
/// e.g. FemBody::surfaceMesh): where it starts by the winding number
/// (dm::windingNumber > 0.5), then in and out at each crossing. What
/// BladeResistance::tick() takes as the engaged length; a physics-rate
/// query: O(triangles), allocates.
double engagedLength(const Vec3& a, const Vec3& b, const Mesh& surface);

/// Parameters of BladeResistance.
struct BladeResistanceOptions {
  /// J, J/m² (> 0): the energy to cut a unit area. Soft tissues: ~10²–10³
  /// (liver ~ 200, skin ~ 10³–10⁴).
  double toughness = 500.0;
  /// k, N/m (> 0): the coupling between device and proxy.
  double stiffness = 1000.0;
  /// N (> 0): the largest force sent to the hand.
  double maxForce = 10.0;
};

/// A blade's cutting point felt against tissue; see the file comment.
class BladeResistance {
 public:
  /// Fails (InvalidArgument naming the field) on a toughness, stiffness or
  /// maxForce that is not positive and finite.
  static Result<BladeResistance> create(const BladeResistanceOptions& options);

  /// Puts the device, the proxy and the front at p and clears the cut's
  /// totals.
  void reset(const Vec3& p) noexcept;
  /// One haptic tick: the device's cutting point (m), the blade's cutting
  /// direction (the way its edge faces; normalised here) and the length of
  /// the edge engaged in tissue (m, ≥ 0). Returns the force on the hand
  /// (N), k·(proxy − device), clamped to maxForce. Non-finite input, a
  /// zero direction or a negative length: zero force, nothing moves.
  Vec3 tick(const Vec3& device, const Vec3& direction, double engaged) noexcept;

  /// The blade's cutting point as the tissue holds it.
  const Vec3& proxy() const noexcept { return proxy_; }
  /// Where the cut has reached (only its position along the direction
  /// matters).
  const Vec3& front() const noexcept { return front_; }
  /// Whether the last tick advanced the cut (the force was at J·w).
  bool cutting() const noexcept { return cutting_; }
  /// Σ w·ds over the ticks that cut: the area cut, m².
  double cutArea() const noexcept { return area_; }
  /// Σ F·Δdevice over all ticks: the work the hand did on the blade, J.
  double work() const noexcept { return work_; }
  const BladeResistanceOptions& options() const noexcept { return options_; }

 private:
  BladeResistanceOptions options_;
  Vec3 proxy_ = Vec3::Zero();
  Vec3 device_ = Vec3::Zero();
  Vec3 front_ = Vec3::Zero();
  bool cutting_ = false;
  double area_ = 0.0;
  double work_ = 0.0;
};

}  // namespace dm
