// HapticTissue (dm/haptics/tissue.hpp): a FemBody felt and deformed through
// the god-object, exchanging surfaces and grips through triple buffers.
#include <dm/haptics/tissue.hpp>

#include <cmath>

namespace dm {

Result<std::unique_ptr<HapticTissue>> HapticTissue::create(FemBody& body, const HapticTissueOptions& options) {
  constexpr const char* where = "HapticTissue::create";
  if (!std::isfinite(options.stiffness) || !(options.stiffness > 0))
    return fail(ErrorCode::InvalidArgument, formatString("stiffness is %g N/m", options.stiffness),
                std::string(where) + ": options.stiffness", "give the haptic material's stiffness, > 0");
  if (!std::isfinite(options.tipRadius) || options.tipRadius < 0)
    return fail(ErrorCode::InvalidArgument, formatString("tipRadius is %g m", options.tipRadius),
                std::string(where) + ": options.tipRadius", "give the proxy radius plus skin, >= 0");
  if (body.surfaceTriangles().empty())
    return fail(ErrorCode::InvalidArgument, "the body has no boundary triangles", where,
                "build the body from a non-empty TetMesh");
  Mesh surface;
  surface.positions = body.positions();
  surface.triangles = body.surfaceTriangles();
  auto tree = MeshBvh::build(surface, options.tree);
  if (!tree) return tree.error().within(where);
  return std::unique_ptr<HapticTissue>(new HapticTissue(body, options, std::move(*tree)));
}

HapticTissue::HapticTissue(FemBody& body, const HapticTissueOptions& options, MeshBvh rest)
    : body_(&body), options_(options), rest_(std::make_shared<const MeshBvh>(rest)), surfaces_(rest) {}

bool HapticTissue::applyTo(GodObjectRenderer& renderer, std::size_t object) noexcept {
  if (!surfaces_.update()) return false;
  return renderer.deformObject(object, &surfaces_.readBuffer());
}

void HapticTissue::publishGrip(const GodObjectRenderer& renderer, std::size_t object,
                               const Vec3& devicePoint) noexcept {
  Grip& g = grips_.writeBuffer();
  const GodObjectContact& c = renderer.contact();
  g.active = c.active && c.object == object && object < renderer.objectCount() && devicePoint.allFinite();
  if (g.active) {
    // The surface point is pulled to where it would be with the proxy on
    // the device point: the device point less the tip radius along the normal.
    const Isometry3& pose = renderer.objectPose(object);
    g.nodes = c.vertices;
    g.weights = c.barycentric.cwiseMax(0.0);
    const double sum = g.weights.sum();
    g.weights = sum > 0 ? Vec3(g.weights / sum) : Vec3::Constant(1.0 / 3.0);
    g.anchor = pose.inverse() * (devicePoint - options_.tipRadius * c.normal);
  }
  grips_.publish();
}

Result<FemStepReport> HapticTissue::step(double h) {
  const Grip& g = grips_.read();
  bool gripped = false;
  if (g.active) gripped = body_->setContactSpring(g.nodes, g.weights, g.anchor, options_.stiffness).ok();
  if (!gripped) body_->clearContactSpring();
  auto report = body_->step(h);
  if (!report) return report;
  grippedSteps_ += gripped;
  MeshBvh& spare = surfaces_.writeBuffer();
  if (auto s = spare.refit(body_->positions()); !s) return s.error().within("HapticTissue::step");
  surfaces_.publish();
  published_.fetch_add(1, std::memory_order_relaxed);
  return report;
}

TissueGodObject::TissueGodObject(GodObjectRenderer& renderer, std::span<const TissueBinding> tissues)
    : renderer_(&renderer) {
  for (const TissueBinding& b : tissues)
    if (b.tissue != nullptr && b.object < renderer.objectCount()) tissues_.push_back(b);
}

HapticResponse TissueGodObject::tick(const HapticInput& input) noexcept {
  for (const TissueBinding& b : tissues_) b.tissue->applyTo(*renderer_, b.object);
  const HapticResponse out = renderer_->tick(input);
  for (const TissueBinding& b : tissues_) b.tissue->publishGrip(*renderer_, b.object, input.devicePose.translation());
  return out;
}

}  // namespace dm
