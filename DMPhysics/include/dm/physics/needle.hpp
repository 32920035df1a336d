// dm/physics/needle.hpp — a rigid needle (straight, or a curved suture
// needle: a circular arc) inserted into FEM tissue: the
// tissue deforms before puncture, the tip breaks through when its force
// passes the layer's threshold, then the shaft is held by the track it cut,
// with friction along it and a cutting force at the tip; retraction frees
// the track again.
//
// What it is for: biopsy, regional anaesthesia, brachytherapy and lumbar
// puncture trainers, where the force trace (the rise, the pop, the friction
// that grows with depth and the steps at each membrane) is what the trainee
// learns to feel.
//
// Model (the three phases of Okamura, Simone & O'Leary 2004, "Force
// modeling for needle insertion into soft tissue", IEEE TBME 51(10), made
// physical on a dm::FemBody, in the spirit of DiMaio & Salcudean 2003,
// "Needle insertion modeling and simulation", IEEE TRA 19(5)):
//  * Pressing: where the tip first meets tissue (the outer surface, or a
//    layer of another label with a puncture threshold > 0) the material
//    point under the tip is held to the tip by an implicit spring
//    (NeedleOptions::tipStiffness), so the tissue tents around it. The
//    force before puncture is the FEM tissue's own stiffness in series with
//    that spring.
//  * Puncture: once the spring's force along the needle reaches the layer's
//    NeedleLayer::punctureForce the tip breaks through: the spring is let go
//    (the tissue springs back: the force drops) and the tip cuts.
//  * Cutting: while the tip advances into tissue it has not cut, the tissue
//    pushes back on it with the layer's NeedleLayer::cuttingForce (a point
//    load on the tissue at the tip, its reaction on the needle), and every
//    NeedleOptions::couplingSpacing of new track a coupling point is made: a
//    material point of the tissue on the track.
//  * Shaft coupling: each coupling point on the shaft is held to the shaft
//    (its nearest point on the line or arc, NeedleShaft) by an anisotropic
//    implicit spring (dm::FemPointSpring: stiff
//    across the shaft, acrossStiffness; along it, alongStiffness to its
//    stick position). A point whose axial spring force would pass its
//    friction limit at the needle's new pose (the layer's
//    NeedleLayer::friction, N per metre of shaft, times the length of shaft
//    it stands for now: half-way to its neighbours on the track) slides
//    for that step: along the shaft it carries exactly the limit (a load),
//    across it the spring holds; then it sticks where its spring pulls with
//    the limit. Coulomb stick–slip per point, so the sliding friction is the
//    friction times the length in contact and grows with depth, as Okamura
//    et al. measured.
//  * Retraction: a coupling point ahead of the tip or behind the shaft's end
//    is off the needle and lets go; the track stays cut, so moving the
//    needle back in along it cuts nothing and presses no membrane, and the
//    points it passes hold the shaft again. Entering elsewhere starts a new
//    track (one track per needle).
// The needle is kinematic (its pose comes from a device or a script each
// step); the force and torque on it are the springs' and loads' reactions.
//
// Units: SI (m, N, s); the tissue's frame.
//
// @code
//   std::vector<std::uint8_t> layerOfTet(body.tetCount(), 0);  // one homogeneous layer
//   dm::NeedleLayer tissue{.punctureForce = 1.2, .cuttingForce = 0.4, .friction = 60.0};
//   auto needle = dm::NeedleInsertion::create(body, layerOfTet, {&tissue, 1});
//   for (double t = 0; t < 2.0; t += 1e-3) {
//     if (auto r = needle->step(entry + t * speed * dir, dir, 1e-3); !r) return r.error();
//     trace.push_back(-needle->force().dot(dir));  // insertion resistance, N
//   }
// @endcode
#pragma once

#include <dm/core/pose.hpp>
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>
#include <dm/physics/fem.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace dm {

class Volume;

/// A tissue layer's response to the needle (skin, fat, muscle, ligament).
struct NeedleLayer {
  /// N, ≥ 0: the tip force along the needle at which the layer's surface
  /// (or the membrane where the needle enters it from another layer) breaks.
  /// 0: no membrane, the tip cuts in at once (fat).
  double punctureForce = 1.0;
  /// N, ≥ 0: the force on the tip while it advances through uncut tissue.
  double cuttingForce = 0.3;
  /// N/m, ≥ 0: sliding friction per metre of shaft in this layer.
  double friction = 50.0;
};

/// Coupling settings of NeedleInsertion.
struct NeedleOptions {
  double length = 0.1;  ///< m, > 0: shaft length behind the tip
  /// m, ≥ 0: 0 a straight needle; else a curved (suture) needle, a circular
  /// arc of this radius (length ≤ 1.5·π·radius: up to a ¾ circle).
  double radius = 0.0;
  double couplingSpacing = 2e-3;   ///< m, > 0: track length per coupling point
  double acrossStiffness = 400.0;  ///< N/m, > 0: a coupling point across the shaft
  double alongStiffness = 400.0;   ///< N/m, > 0: a coupling point along the shaft while it sticks
  double tipStiffness = 2000.0;    ///< N/m, > 0: the tip holding a membrane before puncture
};

/// Where the tip is.
enum class NeedleTip : std::uint8_t {
  Outside,   ///< not in the tissue
  Pressing,  ///< holding a membrane (surface or layer boundary), not through it yet
  Cutting,   ///< advancing through uncut tissue
  InTrack,   ///< inside the track it cut (or out through the far side)
};

/// The needle's shaft in the tissue's frame: straight, or a circular arc of
/// `radius` (a suture needle), `length` long behind the tip. Points along it
/// are named by their arc length u from the tip: 0 at the tip, −length at
/// the shaft's end.
struct NeedleShaft {
  Vec3 tip = Vec3::Zero();
  Vec3 tangent = Vec3::UnitZ();  ///< unit, at the tip, handle → tip
  Vec3 normal = Vec3::UnitX();   ///< unit, ⊥ tangent: toward the arc's centre
  double radius = 0.0;           ///< m, 0 straight
  double length = 0.1;           ///< m

  /// The shaft of a needle whose frame is `pose` (the tissue's frame): the
  /// tip at its origin, the tangent at the tip its +z axis, the arc's
  /// centre toward its +x axis.
  static NeedleShaft fromPose(const Isometry3& pose, double radius, double length) noexcept;
  /// A straight shaft with its tip at `tip` along the unit `direction`.
  static NeedleShaft straight(const Vec3& tip, const Vec3& direction, double length) noexcept;
  /// Arc length u of the shaft point nearest p (> 0: ahead of the tip; <
  /// −length: past the shaft's end; either way off the shaft).
  double coordinate(const Vec3& p) const noexcept;
  /// The shaft's point and unit tangent at arc length u.
  Vec3 point(double u) const noexcept;
  Vec3 tangentAt(double u) const noexcept;
};

/// The needle's coupling with the tissue frozen as the last step left it:
/// what a haptic loop evaluates at 1 kHz between physics steps
/// (dm/haptics/needle.hpp). The tissue's points stay where they are; the
/// needle moves, and the same rules as the step's act on it: the shaft's
/// points hold across it and stick or slide along it (their stick positions
/// move, so friction reverses at once when the hand does), the membrane
/// spring pulls until its threshold and then breaks (locally, at once: the
/// pop is felt in the tick it happens; the physics breaks it too at the
/// same pose), and the tip feels the cutting force while it advances. A
/// fixed-size value (no allocation to copy or evaluate), so it can pass
/// between threads in a triple buffer.
struct NeedleLocalModel {
  /// Coupling points kept; a longer shaft contact is merged pairwise
  /// (positions and stick positions averaged, limits summed) to fit.
  static constexpr std::size_t kMaxPoints = 256;
  struct Point {
    Vec3 position = Vec3::Zero();  ///< m, the tissue point, frozen
    double stick = 0.0;            ///< m along the needle from the tip where it sticks
    double limit = 0.0;            ///< N, its friction limit
    Vec3 tangent = Vec3::Zero();   ///< the shaft's tangent there at the step (the way it yields)
  };
  NeedleTip state = NeedleTip::Outside;
  NeedleShaft shaft;                 ///< the needle at the step
  double across = 0.0, along = 0.0;  ///< N/m, the points' springs
  Vec3 membrane = Vec3::Zero();      ///< Pressing: the held point
  /// Pressing: the share of the tip's advance (along the needle, since the
  /// step) the membrane follows, k_tip/(k_tip + k_tissue) with k_tissue the
  /// tissue's tangent stiffness under the tip over the last step (1 before
  /// it is known): the tissue yields in series with the tip's spring, where
  /// a frozen membrane would feel the tip's spring alone (ten times too
  /// stiff on soft tissue).
  double membraneYield = 0.0;
  /// The share of the needle's advance along itself (since the step) that
  /// the shaft's points follow, k_along/(k_along + k_track) with k_track the
  /// tissue's stiffness along the track per point, measured while the points
  /// stuck over the last steps (before that, the tissue's stiffness under the
  /// tip when it last pressed a membrane; 0 without either: they stay put):
  /// the tissue holding
  /// a point yields in series with its spring, where a frozen point would
  /// feel the spring alone — too stiff where the hand reverses, and
  /// stepping back at each physics step.
  double shaftYield = 0.0;
  double tipStiffness = 0.0;   ///< N/m
  double punctureForce = 0.0;  ///< N, the membrane's threshold
  double cuttingForce = 0.0;   ///< N, of the layer at the tip
  bool hasTrack = false;
  Vec3 trackEnd = Vec3::Zero();  ///< the deepest point cut
  std::array<Point, kMaxPoints> points{};
  std::size_t pointCount = 0;

  /// Force and torque (about the tip) on the needle with its tip at `tip`
  /// along the unit `direction` (tissue frame); moves the points' stick
  /// positions where they slide and breaks the membrane when its threshold
  /// is reached. Real-time safe.
  Wrench evaluate(const NeedleShaft& at) noexcept;
  /// The same with the needle's frame (NeedleShaft::fromPose), its radius
  /// and length the model's.
  Wrench evaluate(const Isometry3& needlePose) noexcept {
    return evaluate(NeedleShaft::fromPose(needlePose, shaft.radius, shaft.length));
  }
  /// The same for a straight needle, tip and unit direction.
  Wrench evaluate(const Vec3& tip, const Vec3& direction) noexcept {
    return evaluate(NeedleShaft::straight(tip, direction, shaft.length));
  }
  /// Copies the used part of `other` (not the unused points).
  void assign(const NeedleLocalModel& other) noexcept;
};

/// A rigid, straight needle in a FemBody: see the file comment for the
/// model. Holds a pointer to the body (it must outlive the needle) and
/// owns the body's point springs (FemBody::setPointSprings) while it steps
/// it. Not thread-safe.
class NeedleInsertion {
 public:
  /// `tetLayers[t]` is the layer of tetrahedron t (an index into `layers`;
  /// see tetLayersFromLabels). Fails (InvalidArgument naming the field) on a
  /// size mismatch, a layer index out of range, a negative or non-finite
  /// layer value, or a non-positive or non-finite option.
  static Result<NeedleInsertion> create(FemBody& body, std::span<const std::uint8_t> tetLayers,
                                        std::span<const NeedleLayer> layers,
                                        const NeedleOptions& options = {});

  /// Moves the needle to `tip` pointing along `direction` (from the handle
  /// to the tip; normalised here) for the next h seconds, updates the
  /// coupling (entry, puncture, cutting, friction, release) and steps the
  /// body once. Fails (InvalidArgument) on a non-finite pose, a zero
  /// direction or h ≤ 0, and with the body's step error (state unchanged
  /// then, except that the body's own step failed).
  Result<FemStepReport> step(const Vec3& tip, const Vec3& direction, double h);
  /// The same for a needle of any shape (NeedleOptions::radius), its frame
  /// given as NeedleShaft::fromPose takes it: tip at the origin, the tip's
  /// tangent along +z, a curved needle's centre toward +x. Fails also on a
  /// pose that is not rigid and finite; the (tip, direction) form fails for
  /// a curved needle (it needs the plane of its arc).
  Result<FemStepReport> step(const Isometry3& needlePose, double h);
  /// The shaft at the last step.
  const NeedleShaft& shaft() const noexcept { return shaft_; }

  /// Force (N) and torque about the tip (N·m) the tissue applies to the
  /// needle at the end of the last step.
  const Wrench& wrench() const noexcept { return wrench_; }
  Vec3 force() const noexcept { return wrench_.force; }
  NeedleTip tipState() const noexcept { return state_; }
  /// Layer of the tissue at the tip (the pressed membrane's, or the one
  /// being cut), -1 outside.
  int tipLayer() const noexcept { return tipLayer_; }
  /// Membranes broken so far.
  std::size_t punctureCount() const noexcept { return punctures_; }
  /// Coupling points on the track, and those holding the shaft now.
  std::size_t trackPointCount() const noexcept { return track_.size(); }
  std::size_t activeCouplingCount() const noexcept;
  /// Length of the track along the needle, entry to deepest cut (m), at the
  /// current positions.
  double trackLength() const noexcept;
  /// Force along the needle (N, toward the handle positive: what resists
  /// insertion) that the tip's spring applied last step while pressing.
  double tipForce() const noexcept { return tipForce_; }
  const NeedleOptions& options() const noexcept { return options_; }
  /// The tissue the needle is in.
  FemBody& body() noexcept { return *body_; }
  /// The coupling as the last step left it, for a haptic loop (see
  /// NeedleLocalModel). Evaluated at the last step's pose it gives that
  /// step's wrench().
  void localModel(NeedleLocalModel& out) const;

 private:
  NeedleInsertion() = default;
  // A material point of the body: barycentric weights in tetrahedron tet.
  struct MaterialPoint {
    std::uint32_t tet = 0;
    std::array<double, 4> weights{};
  };
  struct TrackPoint {
    MaterialPoint at;
    double stick = 0.0;  // m, its stick position along the needle from the tip
    double slide = 0.0;  // N on the tissue along the needle while it slides this step, else 0
    double limit = 0.0;  // N, its friction limit this step
    bool active = false;
    bool fresh = true;  // made by the last step, not yet coupled
    bool stuck = false;            // on the shaft and not sliding at the last step's end
    double force = 0.0;            // N on the tissue along the needle then
    Vec3 where = Vec3::Zero();     // its position then
  };
  Vec3 positionOf(const MaterialPoint& m) const;
  bool locate(const Vec3& p, std::uint32_t hint, MaterialPoint& out) const;
  FemPointSpring springAt(const MaterialPoint& m) const;
  void beginMembrane(const MaterialPoint& m);
  void addTrackPoint(const MaterialPoint& m);

  FemBody* body_ = nullptr;
  std::vector<std::uint8_t> tetLayer_;
  std::vector<NeedleLayer> layers_;
  NeedleOptions options_;

  NeedleTip state_ = NeedleTip::Outside;
  int tipLayer_ = -1;
  std::size_t punctures_ = 0;
  NeedleShaft shaft_;
  Result<FemStepReport> stepShaft(const NeedleShaft& shaft, double h);
  MaterialPoint membrane_;                     // Pressing: the point the tip holds
  Vec3 pressedFrom_ = Vec3::Zero();            // Pressing: where that point was when the tip took it
  double pressSunk_ = 0.0, pressForce_ = 0.0;  // Pressing: how far it has gone in (m) and the tip force (N)
  double pressStiffness_ = 0.0;  // Pressing: the tissue's tangent stiffness under the tip (N/m), 0 unknown
  double trackStiffness_ = 0.0;  // the tissue's along the track per point (N/m), 0 unknown
  bool haveEnd_ = false;
  MaterialPoint end_;  // the deepest point of the track
  std::vector<TrackPoint> track_;
  std::vector<double> axial_;  // per track point, this step: m along the needle from the tip
  std::vector<FemPointSpring> springs_;
  double tipForce_ = 0.0;
  Wrench wrench_;
};

/// The layer of each tetrahedron from a label volume (a segmentation: 0
/// background, 1 skin, 2 fat, …): the label at the tetrahedron's centroid
/// (nearest voxel; outside the volume, 0), mapped through `layerOfLabel`
/// (label → layer index). Fails (InvalidArgument) on a label that has no
/// entry in `layerOfLabel`, naming the tetrahedron and the label.
Result<std::vector<std::uint8_t>> tetLayersFromLabels(const TetMesh& mesh, const Volume& labels,
                                                      std::span<const std::uint8_t> layerOfLabel);

}  // namespace dm
