// A rigid needle in FEM tissue: pressing, puncture, cutting, shaft friction
// and release; see dm/physics/needle.hpp for the model and its references.
#include <dm/core/volume.hpp>
#include <dm/physics/needle.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <utility>

namespace dm {

namespace {
namespace needleimpl {

Error invalidNeedle(std::string what, std::string where, std::string hint = {}) {
  return fail(ErrorCode::InvalidArgument, std::move(what), std::move(where), std::move(hint));
}

bool positiveFinite(double v) { return v > 0.0 && std::isfinite(v); }

// What a shaft point (the tissue at `point`, sticking at arc length
// `stick`, friction limit `limit`) does to the needle: across, the spring
// to its nearest shaft point; along the tangent there, the spring to its
// stick position, at most the limit (past it the point slips: `stick`
// moves to where the spring pulls with the limit). Applied at the spring's
// anchor; zero off the shaft. The step's report and the local model both
// use it, so they agree.
Wrench shaftPointWrench(const NeedleShaft& shaft, const Vec3& point, double& stick, double limit,
                        double across, double along) noexcept {
  const double u = shaft.coordinate(point);
  if (u > 0.0 || u < -shaft.length) return {};
  double onTissue = along * (stick - u);
  if (std::abs(onTissue) > limit) {
    onTissue = std::copysign(limit, onTissue);
    stick = u + onTissue / along;
  }
  const Vec3 tangent = shaft.tangentAt(u), nearest = shaft.point(u);
  const Vec3 f = across * (point - nearest) - onTissue * tangent;
  return {f, (nearest + (stick - u) * tangent - shaft.tip).cross(f)};
}

}  // namespace needleimpl
}  // namespace

Result<NeedleInsertion> NeedleInsertion::create(FemBody& body, std::span<const std::uint8_t> tetLayers,
                                                std::span<const NeedleLayer> layers,
                                                const NeedleOptions& options) {
  using needleimpl::invalidNeedle;
  constexpr const char* where = "NeedleInsertion::create";
  if (tetLayers.size() != body.tetCount())
    return invalidNeedle("tetLayers has " + std::to_string(tetLayers.size()) + " entries but the body has " +
                             std::to_string(body.tetCount()) + " tetrahedra",
                         where, "give one layer index per tetrahedron");
  if (layers.empty()) return invalidNeedle("layers is empty", where, "give at least one NeedleLayer");
  if (layers.size() > 256)
    return invalidNeedle("layers has " + std::to_string(layers.size()) + " entries", where,
                         "at most 256 layers (tetLayers holds bytes)");
  for (std::size_t t = 0; t < tetLayers.size(); ++t)
    if (tetLayers[t] >= layers.size())
      return invalidNeedle("tetLayers[" + std::to_string(t) + "] = " + std::to_string(tetLayers[t]) +
                               " but there are " + std::to_string(layers.size()) + " layers",
                           where, "each entry indexes layers");
  for (std::size_t l = 0; l < layers.size(); ++l) {
    const NeedleLayer& y = layers[l];
    const std::pair<const char*, double> fields[] = {
        {"punctureForce", y.punctureForce}, {"cuttingForce", y.cuttingForce}, {"friction", y.friction}};
    for (const auto& [name, value] : fields)
      if (!(value >= 0.0) || !std::isfinite(value))
        return invalidNeedle("layers[" + std::to_string(l) + "]." + name + " = " + std::to_string(value) +
                                 " is negative or not finite",
                             where, "forces in N and friction in N/m, >= 0");
  }
  const std::pair<const char*, double> opts[] = {{"length", options.length},
                                                 {"couplingSpacing", options.couplingSpacing},
                                                 {"acrossStiffness", options.acrossStiffness},
                                                 {"alongStiffness", options.alongStiffness},
                                                 {"tipStiffness", options.tipStiffness}};
  if (!(options.radius >= 0.0) || !std::isfinite(options.radius))
    return invalidNeedle("options.radius = " + std::to_string(options.radius) + " is negative or not finite",
                         where, "0 for a straight needle, else the arc's radius in m");
  if (options.radius > 0.0 && options.length > 1.5 * std::numbers::pi * options.radius)
    return invalidNeedle("options.length = " + std::to_string(options.length) +
                             " m is more than a ¾ circle of radius " + std::to_string(options.radius) + " m",
                         where, "a curved needle's arc is at most 1.5·π·radius long");
  for (const auto& [name, value] : opts)
    if (!needleimpl::positiveFinite(value))
      return invalidNeedle(
          std::string("options.") + name + " = " + std::to_string(value) + " is not positive and finite",
          where, "lengths in m, stiffnesses in N/m, > 0");
  NeedleInsertion n;
  n.body_ = &body;
  n.tetLayer_.assign(tetLayers.begin(), tetLayers.end());
  n.layers_.assign(layers.begin(), layers.end());
  n.options_ = options;
  return n;
}

NeedleShaft NeedleShaft::fromPose(const Isometry3& pose, double radius, double length) noexcept {
  return {.tip = pose.translation(),
          .tangent = pose.linear().col(2),
          .normal = pose.linear().col(0),
          .radius = radius,
          .length = length};
}

NeedleShaft NeedleShaft::straight(const Vec3& tip, const Vec3& direction, double length) noexcept {
  // Any unit normal: a straight shaft has no plane.
  const Vec3 other = std::abs(direction.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
  return {.tip = tip,
          .tangent = direction,
          .normal = direction.cross(other).normalized(),
          .radius = 0.0,
          .length = length};
}

// The arc: centre c = tip + R·n; the point at u is c + R(−n cos(u/R) + t sin(u/R)).
double NeedleShaft::coordinate(const Vec3& p) const noexcept {
  if (radius == 0.0) return (p - tip).dot(tangent);
  const Vec3 q = p - (tip + radius * normal);
  return radius * std::atan2(q.dot(tangent), -q.dot(normal));
}

Vec3 NeedleShaft::point(double u) const noexcept {
  if (radius == 0.0) return tip + u * tangent;
  const double a = u / radius;
  return tip + radius * ((1.0 - std::cos(a)) * normal + std::sin(a) * tangent);
}

Vec3 NeedleShaft::tangentAt(double u) const noexcept {
  if (radius == 0.0) return tangent;
  const double a = u / radius;
  return std::sin(a) * normal + std::cos(a) * tangent;
}

Vec3 NeedleInsertion::positionOf(const MaterialPoint& m) const {
  const auto& x = body_->positions();
  const Tet& t = body_->tets()[m.tet];
  return m.weights[0] * x[t[0]] + m.weights[1] * x[t[1]] + m.weights[2] * x[t[2]] + m.weights[3] * x[t[3]];
}

// The tetrahedron holding p at the current positions, and p's barycentric
// weights in it: the hint first (the tip moves little in a step), then
// every tetrahedron whose box holds p.
bool NeedleInsertion::locate(const Vec3& p, std::uint32_t hint, MaterialPoint& out) const {
  const auto& x = body_->positions();
  const auto& tets = body_->tets();
  constexpr double kSlack = 1e-12;
  const auto inside = [&](std::uint32_t t) {
    const Tet& e = tets[t];
    const Vec3 &a = x[e[0]], &b = x[e[1]], &c = x[e[2]], &d = x[e[3]];
    for (int k = 0; k < 3; ++k) {
      const double lo = std::min({a[k], b[k], c[k], d[k]}), hi = std::max({a[k], b[k], c[k], d[k]});
      if (p[k] < lo - kSlack || p[k] > hi + kSlack) return false;
    }
    Mat3 D;
    D << b - a, c - a, d - a;
    const double det = D.determinant();
    if (!(std::abs(det) > 0.0)) return false;  // a flattened element holds nothing
    const Vec3 l = D.inverse() * (p - a);
    const double l0 = 1.0 - l.sum();
    if (l0 < -kSlack || l.minCoeff() < -kSlack) return false;
    out.tet = t;
    out.weights = {l0, l.x(), l.y(), l.z()};
    // Round-off may leave a weight a hair below zero: clamp and renormalise
    // so the point is a valid FemPointSpring.
    double sum = 0.0;
    for (double& w : out.weights) sum += (w = std::max(w, 0.0));
    for (double& w : out.weights) w /= sum;
    return true;
  };
  if (hint < tets.size() && inside(hint)) return true;
  for (std::uint32_t t = 0; t < tets.size(); ++t)
    if (t != hint && inside(t)) return true;
  return false;
}

FemPointSpring NeedleInsertion::springAt(const MaterialPoint& m) const {
  const Tet& t = body_->tets()[m.tet];
  return FemPointSpring{.nodes = {t[0], t[1], t[2], t[3]}, .weights = m.weights};
}

void NeedleInsertion::beginMembrane(const MaterialPoint& m) {
  state_ = NeedleTip::Pressing;
  membrane_ = m;
  pressedFrom_ = positionOf(m);
  pressSunk_ = pressForce_ = pressStiffness_ = 0.0;
  tipLayer_ = tetLayer_[m.tet];
}

void NeedleInsertion::addTrackPoint(const MaterialPoint& m) {
  track_.push_back({.at = m, .stick = shaft_.coordinate(positionOf(m)), .active = true});
}

std::size_t NeedleInsertion::activeCouplingCount() const noexcept {
  return std::size_t(
      std::count_if(track_.begin(), track_.end(), [](const TrackPoint& p) { return p.active; }));
}

double NeedleInsertion::trackLength() const noexcept {
  if (track_.empty() || !haveEnd_) return 0.0;
  return std::max(0.0,
                  shaft_.coordinate(positionOf(end_)) - shaft_.coordinate(positionOf(track_.front().at)));
}

Result<FemStepReport> NeedleInsertion::step(const Vec3& tip, const Vec3& direction, double h) {
  using needleimpl::invalidNeedle;
  constexpr const char* where = "NeedleInsertion::step";
  if (options_.radius > 0.0)
    return invalidNeedle("a curved needle (options.radius = " + std::to_string(options_.radius) +
                             " m) needs the plane of its arc",
                         where, "step it with its pose: step(Isometry3, h)");
  if (!tip.allFinite()) return invalidNeedle("the tip is not finite", where, "give a point in metres");
  const double norm = direction.norm();
  if (!(norm > 1e-12) || !std::isfinite(norm))
    return invalidNeedle("the direction is zero or not finite", where,
                         "give the shaft's direction, handle to tip");
  return stepShaft(NeedleShaft::straight(tip, direction / norm, options_.length), h);
}

Result<FemStepReport> NeedleInsertion::step(const Isometry3& needlePose, double h) {
  if (!isRigidPose(needlePose))
    return needleimpl::invalidNeedle("the needle's pose is not a finite rigid transform",
                                     "NeedleInsertion::step", "give a rotation and a translation");
  return stepShaft(NeedleShaft::fromPose(needlePose, options_.radius, options_.length), h);
}

Result<FemStepReport> NeedleInsertion::stepShaft(const NeedleShaft& shaft, double h) {
  using needleimpl::invalidNeedle;
  constexpr const char* where = "NeedleInsertion::step";
  if (!needleimpl::positiveFinite(h))
    return invalidNeedle("h is not positive and finite", where, "e.g. 1e-3 s");
  // The tip cuts only while it advances: tissue springing back over a tip
  // that holds still or withdraws is not cut.
  const bool advancing = (shaft.tip - shaft_.tip).dot(shaft.tangent) > 0.0;
  shaft_ = shaft;
  const double spacing = options_.couplingSpacing;

  // The tip: entering, reaching past the track's end, or leaving.
  MaterialPoint at;
  switch (state_) {
    case NeedleTip::Outside:
      if (locate(shaft_.tip, haveEnd_ ? end_.tet : 0, at)) {
        const bool reentry = !track_.empty() && [&] {
          const Vec3 r = positionOf(track_.front().at);
          return (r - shaft_.point(shaft_.coordinate(r))).norm() < spacing;
        }();
        if (reentry) {
          state_ = NeedleTip::InTrack;
          tipLayer_ = tetLayer_[at.tet];
        } else {
          track_.clear();
          haveEnd_ = false;
          if (layers_[tetLayer_[at.tet]].punctureForce > 0.0) {
            beginMembrane(at);
          } else {
            state_ = NeedleTip::Cutting;
            tipLayer_ = tetLayer_[at.tet];
            end_ = at, haveEnd_ = true;
            addTrackPoint(at);
          }
        }
      }
      break;
    case NeedleTip::Pressing:
      break;  // the membrane holds the tip until it breaks or is let go (after the step)
    case NeedleTip::Cutting:
    case NeedleTip::InTrack:
      if (haveEnd_ && advancing && shaft_.coordinate(positionOf(end_)) < 0.0) {
        if (!locate(shaft_.tip, end_.tet, at)) {
          state_ = NeedleTip::InTrack;  // out through the far side
        } else if (const int layer = tetLayer_[at.tet];
                   layer != tetLayer_[end_.tet] && layers_[std::size_t(layer)].punctureForce > 0.0) {
          beginMembrane(at);
        } else {
          state_ = NeedleTip::Cutting;
          tipLayer_ = layer;
          end_ = at;
          // A new shaft point every `spacing` of track, half a spacing
          // behind the tip: cut tissue on the shaft, which the cutting load
          // at the tip does not carry past the tip during the step.
          MaterialPoint behind;
          if (track_.empty() || -0.5 * spacing - shaft_.coordinate(positionOf(track_.back().at)) >= spacing)
            addTrackPoint(locate(shaft_.point(-0.5 * spacing), at.tet, behind) ? behind : at);
        }
      } else {
        state_ = NeedleTip::InTrack;
      }
      if (state_ == NeedleTip::InTrack && !track_.empty() &&
          shaft_.coordinate(positionOf(track_.front().at)) > 0.0) {
        state_ = NeedleTip::Outside;  // pulled out behind the entry
        tipLayer_ = -1;
      }
      break;
  }

  // Track points on the shaft hold it; off it (ahead of the tip, behind the
  // shaft's end, or the needle out) they let go, and take hold again, where
  // they are, when the shaft comes back over them.
  axial_.resize(track_.size());
  for (std::size_t k = 0; k < track_.size(); ++k) {
    TrackPoint& p = track_[k];
    const double s = axial_[k] = shaft_.coordinate(positionOf(p.at));
    const bool on = state_ != NeedleTip::Outside && s <= 0.0 && s >= -options_.length;
    if (on && !p.active) p.stick = s;
    p.active = on;
  }
  // Coulomb stick–slip along the shaft. Each point stands for the shaft
  // between the midpoints to its neighbours on the track (the shallowest
  // from itself, the deepest to the tip), measured now: the track stretches
  // and shortens with the tissue, and the friction is per metre of shaft in
  // contact. Where the needle's move would stretch a point's axial spring
  // past its limit, the point slides this step: along the shaft it feels
  // exactly the limit (a load), across it the spring still holds.
  std::size_t prev = track_.size();
  for (std::size_t k = 0; k < track_.size(); ++k) {
    TrackPoint& p = track_[k];
    p.slide = 0.0;
    if (!p.active) continue;
    std::size_t next = k + 1;
    while (next < track_.size() && !track_[next].active) ++next;
    const double from = prev < track_.size() ? 0.5 * (axial_[prev] + axial_[k]) : axial_[k];
    const double to = next < track_.size() ? 0.5 * (axial_[k] + axial_[next]) : 0.0;
    const double limit = p.limit = layers_[tetLayer_[p.at.tet]].friction * std::max(0.0, to - from);
    // A point the tip has just cut is dragged in by the needle moving
    // through it: it starts sliding at its limit, not unloaded (which
    // would drop the friction by the share it takes from its neighbour
    // each time the track grows a point).
    if (p.fresh) p.stick = axial_[k] + limit / options_.alongStiffness, p.fresh = false;
    const double along = options_.alongStiffness * (p.stick - axial_[k]);  // on the tissue, along the needle
    if (std::abs(along) > limit) p.slide = std::copysign(limit, along);
    prev = k;
  }

  // The springs for this step: the shaft's couplings, the tip's membrane
  // spring or its cutting load.
  springs_.clear();
  // A point at arc length u on the shaft: across, held to the shaft's point
  // there; along the tangent there, to its stick position (the anchor is
  // offset along that tangent, so the spring's force along it is exactly
  // alongStiffness·(stick − u), straight or curved).
  for (std::size_t k = 0; k < track_.size(); ++k) {
    const TrackPoint& p = track_[k];
    if (!p.active) continue;
    const double u = axial_[k];
    const Vec3 tangent = shaft_.tangentAt(u);
    FemPointSpring s = springAt(p.at);
    s.anchor = shaft_.point(u) + (p.stick - u) * tangent;
    s.stiffness = FemPointSpring::axial(tangent, options_.acrossStiffness,
                                        p.slide != 0.0 ? 0.0 : options_.alongStiffness);
    s.load = p.slide * tangent;
    springs_.push_back(s);
  }
  std::int32_t tipSpring = -1;
  if (state_ == NeedleTip::Pressing) {
    FemPointSpring s = springAt(membrane_);
    s.anchor = shaft_.tip;
    s.stiffness = options_.tipStiffness * Mat3::Identity();
    tipSpring = std::int32_t(springs_.size());
    springs_.push_back(s);
  } else if (state_ == NeedleTip::Cutting) {
    FemPointSpring s = springAt(end_);
    s.anchor = shaft_.tip;
    s.load = layers_[std::size_t(tipLayer_)].cuttingForce * shaft_.tangent;
    springs_.push_back(s);
  }
  if (Status st = body_->setPointSprings(springs_); !st) return std::move(st).error().within(where);
  auto report = body_->step(h);
  if (!report) return std::move(report).error().within(where);

  // What the needle feels, and where each shaft point sticks now. A point
  // that slid sticks where its spring pulls with the limit, so stopping
  // holds it there and reversing unloads it first; one that stuck but was
  // stretched past its limit during the step (the tissue moved under it)
  // slipped, and sticks at the limit too. The shaft's points act on the
  // axis at their anchors with at most their limit along it (a point the
  // tissue carried off the shaft during the step, past the tip, no longer
  // touches it); the tip's spring and cutting load with what the body took.
  // The tissue's stiffness along the track: how far the points that stuck
  // through this step and the last moved along the shaft for the change in
  // their springs' pull (for the local model's yielding points).
  wrench_ = Wrench{};
  std::size_t i = 0;
  double pulled = 0.0, moved = 0.0;
  std::size_t stuck = 0;
  for (TrackPoint& p : track_) {
    if (!p.active) {
      p.stuck = false;
      continue;
    }
    ++i;
    const Vec3 point = positionOf(p.at);
    if (p.slide != 0.0) p.stick = shaft_.coordinate(point) + p.slide / options_.alongStiffness;
    wrench_ += needleimpl::shaftPointWrench(shaft_, point, p.stick, p.limit, options_.acrossStiffness,
                                            options_.alongStiffness);
    const double u = shaft_.coordinate(point);
    const double force = std::clamp(options_.alongStiffness * (p.stick - u), -p.limit, p.limit);
    if (p.slide == 0.0 && p.stuck) {
      pulled += force - p.force;
      moved += (point - p.where).dot(shaft_.tangentAt(u));
      ++stuck;
    }
    p.stuck = p.slide == 0.0;
    p.force = force;
    p.where = point;
  }
  if (stuck > 0 && std::abs(moved) > 1e-9 * double(stuck) && std::abs(pulled) > 1e-6 * double(stuck)) {
    const double k = pulled / moved;  // per point: Σ Δf / Σ Δx
    if (k > 0.0) trackStiffness_ = std::clamp(k, 1e-2 * options_.alongStiffness, 1e2 * options_.alongStiffness);
  }
  for (; i < springs_.size(); ++i) {
    const Vec3 f = -body_->pointSpringForce(i);
    wrench_ += Wrench{f, (springs_[i].anchor - shaft_.tip).cross(f)};
  }
  // Puncture, or the tip drawn back off its membrane.
  tipForce_ = 0.0;
  if (tipSpring >= 0) {
    tipForce_ = body_->pointSpringForce(std::size_t(tipSpring)).dot(shaft_.tangent);
    // The tissue's tangent stiffness under the tip, from this step's and the
    // last one's force and sink (for the local model's yielding membrane).
    const double sunk = (positionOf(membrane_) - pressedFrom_).dot(shaft_.tangent);
    if (sunk - pressSunk_ > 1e-9 && tipForce_ > pressForce_)
      pressStiffness_ = (tipForce_ - pressForce_) / (sunk - pressSunk_);
    pressSunk_ = sunk, pressForce_ = tipForce_;
    if (tipForce_ >= layers_[std::size_t(tipLayer_)].punctureForce) {
      ++punctures_;
      state_ = NeedleTip::Cutting;
      end_ = membrane_, haveEnd_ = true;
      addTrackPoint(membrane_);
    } else if (tipForce_ < 0.0) {
      state_ = track_.empty() ? NeedleTip::Outside : NeedleTip::InTrack;
      if (state_ == NeedleTip::Outside) tipLayer_ = -1;
    }
  }
  return report;
}

void NeedleInsertion::localModel(NeedleLocalModel& out) const {
  out.state = state_;
  out.shaft = shaft_;
  out.across = options_.acrossStiffness;
  out.along = options_.alongStiffness;
  out.tipStiffness = options_.tipStiffness;
  out.punctureForce = state_ == NeedleTip::Pressing ? layers_[std::size_t(tipLayer_)].punctureForce : 0.0;
  out.cuttingForce = tipLayer_ >= 0 ? layers_[std::size_t(tipLayer_)].cuttingForce : 0.0;
  out.membrane = state_ == NeedleTip::Pressing ? positionOf(membrane_) : Vec3::Zero();
  // Unknown until the tip has pushed the tissue for a step: it then yields
  // fully (no stiffness is made up) for that one step.
  out.membraneYield = 0.0;
  if (state_ == NeedleTip::Pressing)
    out.membraneYield =
        pressStiffness_ > 0.0 ? options_.tipStiffness / (options_.tipStiffness + pressStiffness_) : 1.0;
  // Until the points have stuck for two steps the tissue's stiffness under
  // the tip when it last pressed a membrane stands in for the track's.
  const double track = trackStiffness_ > 0.0 ? trackStiffness_ : pressStiffness_;
  out.shaftYield = track > 0.0 ? options_.alongStiffness / (options_.alongStiffness + track) : 0.0;
  out.hasTrack = haveEnd_;
  out.trackEnd = haveEnd_ ? positionOf(end_) : Vec3::Zero();
  std::size_t n = 0;
  for (const TrackPoint& p : track_) {
    if (!p.active) continue;
    if (n == NeedleLocalModel::kMaxPoints) {  // merge pairwise to make room
      for (std::size_t k = 0; k < n / 2; ++k) {
        const auto &a = out.points[2 * k], &b = out.points[2 * k + 1];
        out.points[k] = {0.5 * (a.position + b.position), 0.5 * (a.stick + b.stick), a.limit + b.limit,
                         (a.tangent + b.tangent).normalized()};
      }
      n /= 2;
    }
    const Vec3 point = positionOf(p.at);
    out.points[n++] = {point, p.stick, p.limit, shaft_.tangentAt(shaft_.coordinate(point))};
  }
  out.pointCount = n;
}

void NeedleLocalModel::assign(const NeedleLocalModel& o) noexcept {
  state = o.state, shaft = o.shaft;
  across = o.across, along = o.along, membrane = o.membrane, membraneYield = o.membraneYield;
  shaftYield = o.shaftYield;
  tipStiffness = o.tipStiffness;
  punctureForce = o.punctureForce, cuttingForce = o.cuttingForce, hasTrack = o.hasTrack,
  trackEnd = o.trackEnd;
  std::copy_n(o.points.begin(), o.pointCount, points.begin());
  pointCount = o.pointCount;
}

Wrench NeedleLocalModel::evaluate(const NeedleShaft& at) noexcept {
  Wrench w;
  const Vec3& d = at.tangent;
  const double advance = (at.tip - shaft.tip).dot(d);  // since the step, along the tip's tangent
  // Each point yields along the shaft with its share of the advance (the
  // shaft moves along itself by `advance` at every point).
  const double follow = shaftYield * advance;
  for (std::size_t k = 0; k < pointCount; ++k)
    w += needleimpl::shaftPointWrench(at, points[k].position + follow * points[k].tangent, points[k].stick,
                                      points[k].limit, across, along);
  if (state == NeedleTip::Pressing) {
    const Vec3 yielded = membrane + membraneYield * advance * d;
    const Vec3 onTissue = tipStiffness * (at.tip - yielded);
    if (onTissue.dot(d) >= punctureForce) {
      state = NeedleTip::Cutting;  // broken: the tip cuts from here
      hasTrack = true;
      trackEnd = yielded;
    } else {
      w.force -= onTissue;
    }
  }
  // The tip cuts while it advances: cutting at the step and not drawn back
  // from the step's pose, or in the track at the step and pushed on past
  // its end since.
  const bool cutting =
      (state == NeedleTip::Cutting && advance >= 0.0) ||
      (state == NeedleTip::InTrack && hasTrack && advance > 0.0 && at.coordinate(trackEnd) < 0.0);
  if (cutting) w.force -= cuttingForce * d;
  return w;
}

Result<std::vector<std::uint8_t>> tetLayersFromLabels(const TetMesh& mesh, const Volume& labels,
                                                      std::span<const std::uint8_t> layerOfLabel) {
  std::vector<std::uint8_t> out(mesh.tets.size());
  const Vec3i& dims = labels.dims();
  for (std::size_t t = 0; t < mesh.tets.size(); ++t) {
    Vec3 c = Vec3::Zero();
    for (std::uint32_t n : mesh.tets[t]) c += 0.25 * mesh.nodes[n];
    const Vec3 ijk = labels.worldToIndex() * c;
    const int i = int(std::lround(ijk.x())), j = int(std::lround(ijk.y())), k = int(std::lround(ijk.z()));
    double value = 0.0;
    if (i >= 0 && j >= 0 && k >= 0 && i < dims.x() && j < dims.y() && k < dims.z())
      value = labels.value(i, j, k);
    if (!std::isfinite(value))
      return needleimpl::invalidNeedle(
          "tetrahedron " + std::to_string(t) + " lies on a label that is not finite", "tetLayersFromLabels",
          "give a label volume of whole numbers");
    const long label = std::lround(value);
    if (label < 0 || std::size_t(label) >= layerOfLabel.size())
      return needleimpl::invalidNeedle("tetrahedron " + std::to_string(t) + " lies on label " +
                                           std::to_string(label) + ", which layerOfLabel (" +
                                           std::to_string(layerOfLabel.size()) + " entries) does not map",
                                       "tetLayersFromLabels", "give a layer for every label of the volume");
    out[t] = layerOfLabel[std::size_t(label)];
  }
  return out;
}

}  // namespace dm
