// Viscoelastic mass–spring meshes: builders, the symplectic Euler step and
// the linearly implicit (Baraff–Witkin) backward-Euler step. See
// dm/physics/mass_spring.hpp for the model.
#include <dm/core/assert.hpp>
#include <dm/core/host_cpu.hpp>
#include <dm/core/tasks.hpp>
#include <dm/physics/mass_spring.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <string>
#include <type_traits>
#include <utility>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace dm {

namespace {

Error invalid(std::string what, std::string where, std::string hint = {}) {
  return fail(ErrorCode::InvalidArgument, std::move(what), std::move(where), std::move(hint));
}

bool allFinite(const Vec3& v) { return v.allFinite(); }

Vec3 load3(const VecX& a, std::size_t i) { return a.segment<3>(3 * Eigen::Index(i)); }
Vec3 load3(const std::vector<double>& a, std::size_t i) { return Vec3(a[3 * i], a[3 * i + 1], a[3 * i + 2]); }
void store3(std::vector<double>& a, std::size_t i, const Vec3& v) {
  a[3 * i] = v.x(), a[3 * i + 1] = v.y(), a[3 * i + 2] = v.z();
}

// Chunk size of the parallel loops: large enough that a chunk costs tens of
// microseconds, so task overhead stays small.
constexpr std::size_t kGrain = 2048;

}  // namespace

const char* toString(SpringModel model) noexcept {
  switch (model) {
    case SpringModel::KelvinVoigt:
      return "KelvinVoigt";
    case SpringModel::Maxwell:
      return "Maxwell";
  }
  return "?";
}

const char* toString(SpringLayout layout) noexcept {
  switch (layout) {
    case SpringLayout::Structural:
      return "structural";
    case SpringLayout::Shear:
      return "shear";
    case SpringLayout::Bend:
      return "bend";
    case SpringLayout::Custom:
      return "custom";
  }
  return "?";
}

Status validateSpringMaterial(const SpringMaterial& m, const char* where) {
  if (!std::isfinite(m.stiffness) || m.stiffness < 0)
    return invalid(formatString("stiffness is %g N/m", m.stiffness), formatString("%s.stiffness", where),
                   "give k in N/m, finite and >= 0");
  if (!std::isfinite(m.damping) || m.damping < 0)
    return invalid(formatString("damping is %g N*s/m", m.damping), formatString("%s.damping", where),
                   "give c in N*s/m, finite and >= 0");
  if (m.model == SpringModel::Maxwell && m.damping <= 0)
    return invalid("a Maxwell element needs damping > 0 (its damper would carry no force)",
                   formatString("%s.damping", where), "set c > 0, or use SpringModel::KelvinVoigt");
  if (m.model != SpringModel::Maxwell && m.model != SpringModel::KelvinVoigt)
    return invalid(formatString("unknown model %d", int(m.model)), formatString("%s.model", where));
  return ok();
}

// ---------------------------------------------------------------------------
// Building

Result<std::uint32_t> MassSpringBody::addParticle(const Vec3& position, double mass, bool pinned) {
  constexpr const char* where = "MassSpringBody::addParticle";
  if (!allFinite(position)) return invalid("position is not finite", formatString("%s: position", where));
  if (!std::isfinite(mass) || mass <= 0)
    return invalid(formatString("mass is %g kg", mass), formatString("%s: mass", where),
                   "give a finite mass > 0 kg");
  if (particleCount() >= kMaxParticles)
    return invalid(formatString("the body already has %zu particles", particleCount()), where,
                   "split the body, or coarsen it");
  const Eigen::Index n = Eigen::Index(particleCount());
  x_.conservativeResize(3 * n + 3);
  v_.conservativeResize(3 * n + 3);
  fext_.conservativeResize(3 * n + 3);
  x_.segment<3>(3 * n) = position;
  v_.segment<3>(3 * n).setZero();
  fext_.segment<3>(3 * n).setZero();
  mass_.push_back(mass);
  pinned_.push_back(pinned ? 1 : 0);
  prepared_ = false;
  return std::uint32_t(n);
}

Result<std::uint32_t> MassSpringBody::addElement(std::uint32_t i, std::uint32_t j,
                                                 const SpringMaterial& material, double restLength,
                                                 SpringLayout layout) {
  constexpr const char* where = "MassSpringBody::addElement";
  const std::size_t n = particleCount();
  if (i >= n || j >= n)
    return invalid(
        formatString("particle index %u is out of range (the body has %zu particles)", i >= n ? i : j, n),
        formatString("%s: %s", where, i >= n ? "i" : "j"));
  if (i == j) return invalid(formatString("both ends are particle %u", i), formatString("%s: j", where));
  if (Status s = validateSpringMaterial(material, "material"); !s) return std::move(s).error().within(where);
  if (std::isnan(restLength) || std::isinf(restLength))
    return invalid("rest length is not finite", formatString("%s: restLength", where),
                   "give L0 in m, or a negative value for the current distance");
  if (static_cast<std::size_t>(layout) >= kSpringLayoutCount)
    return invalid(formatString("unknown layout %d", int(layout)), formatString("%s: layout", where));
  if (restLength < 0) restLength = (position(j) - position(i)).norm();
  ei_.push_back(i);
  ej_.push_back(j);
  rest_.push_back(restLength);
  k_.push_back(material.stiffness);
  c_.push_back(material.damping);
  ed_.push_back(0.0);
  maxwell_.push_back(material.model == SpringModel::Maxwell ? 1 : 0);
  layout_.push_back(static_cast<std::uint8_t>(layout));
  ++layoutCount_[static_cast<std::size_t>(layout)];
  prepared_ = false;
  decayH_ = -1.0;
  return std::uint32_t(ei_.size() - 1);
}

Result<MassSpringBody> MassSpringBody::makeSheet(const SpringSheetOptions& o) {
  constexpr const char* where = "SpringSheetOptions";
  const auto field = [&](const char* name) { return formatString("%s.%s", where, name); };
  if (o.nx < 2 || o.nx > 4096)
    return invalid(formatString("nx is %d", o.nx), field("nx"), "give 2 to 4096 nodes along u");
  if (o.ny < 2 || o.ny > 4096)
    return invalid(formatString("ny is %d", o.ny), field("ny"), "give 2 to 4096 nodes along v");
  if (std::size_t(o.nx) * std::size_t(o.ny) > kMaxParticles)
    return invalid(
        formatString("nx*ny = %zu nodes exceeds %zu", std::size_t(o.nx) * std::size_t(o.ny), kMaxParticles),
        field("nx"), "coarsen the sheet");
  if (!std::isfinite(o.width) || o.width <= 0)
    return invalid(formatString("width is %g m", o.width), field("width"), "give a finite width > 0 m");
  if (!std::isfinite(o.height) || o.height <= 0)
    return invalid(formatString("height is %g m", o.height), field("height"), "give a finite height > 0 m");
  if (!std::isfinite(o.mass) || o.mass <= 0)
    return invalid(formatString("mass is %g kg", o.mass), field("mass"),
                   "give the total mass, finite and > 0 kg");
  if (!allFinite(o.origin)) return invalid("origin is not finite", field("origin"));
  if (!allFinite(o.uAxis) || o.uAxis.norm() == 0)
    return invalid("uAxis is zero or not finite", field("uAxis"), "give a direction, e.g. (1, 0, 0)");
  if (!allFinite(o.vAxis) || o.vAxis.norm() == 0)
    return invalid("vAxis is zero or not finite", field("vAxis"), "give a direction, e.g. (0, 1, 0)");
  const Vec3 u = o.uAxis.normalized(), v = o.vAxis.normalized();
  if (u.cross(v).norm() < 1e-9)
    return invalid("uAxis and vAxis are parallel", field("vAxis"), "give two independent directions");
  const SpringMaterial* materials[3] = {&o.structural, &o.shear, &o.bend};
  const char* names[3] = {"structural", "shear", "bend"};
  for (int l = 0; l < 3; ++l)
    if (materials[l]->enabled)
      if (Status s = validateSpringMaterial(*materials[l], field(names[l]).c_str()); !s)
        return std::move(s).error();

  const std::size_t nx = std::size_t(o.nx), ny = std::size_t(o.ny), n = nx * ny;
  MassSpringBody body;
  body.x_.resize(Eigen::Index(3 * n));
  body.v_ = VecX::Zero(Eigen::Index(3 * n));
  body.fext_ = VecX::Zero(Eigen::Index(3 * n));
  body.mass_.assign(n, o.mass / double(n));
  body.pinned_.assign(n, 0);
  for (std::size_t b = 0; b < ny; ++b)
    for (std::size_t a = 0; a < nx; ++a)
      body.x_.segment<3>(Eigen::Index(3 * (a + nx * b))) =
          o.origin + (double(a) / double(nx - 1) * o.width) * u + (double(b) / double(ny - 1) * o.height) * v;

  const std::size_t structural = (nx - 1) * ny + nx * (ny - 1), shear = 2 * (nx - 1) * (ny - 1),
                    bend = (nx - 2) * ny + nx * (ny - 2);
  const std::size_t total =
      (o.structural.enabled ? structural : 0) + (o.shear.enabled ? shear : 0) + (o.bend.enabled ? bend : 0);
  for (auto* vec : {&body.rest_, &body.k_, &body.c_, &body.ed_}) vec->reserve(total);
  for (auto* vec : {&body.ei_, &body.ej_}) vec->reserve(total);
  body.maxwell_.reserve(total);
  body.layout_.reserve(total);
  const auto id = [nx](std::size_t a, std::size_t b) { return std::uint32_t(a + nx * b); };
  // Indices and materials were checked above, so the elements are appended
  // directly rather than through addElement().
  const auto link = [&body](std::uint32_t i, std::uint32_t j, const SpringMaterial& m, SpringLayout layout) {
    body.ei_.push_back(i);
    body.ej_.push_back(j);
    body.rest_.push_back((body.position(j) - body.position(i)).norm());
    body.k_.push_back(m.stiffness);
    body.c_.push_back(m.damping);
    body.ed_.push_back(0.0);
    body.maxwell_.push_back(m.model == SpringModel::Maxwell ? 1 : 0);
    body.layout_.push_back(static_cast<std::uint8_t>(layout));
    ++body.layoutCount_[static_cast<std::size_t>(layout)];
  };
  for (std::size_t b = 0; b < ny; ++b)
    for (std::size_t a = 0; a < nx; ++a) {
      if (o.structural.enabled) {
        if (a + 1 < nx) link(id(a, b), id(a + 1, b), o.structural, SpringLayout::Structural);
        if (b + 1 < ny) link(id(a, b), id(a, b + 1), o.structural, SpringLayout::Structural);
      }
      if (o.shear.enabled && a + 1 < nx && b + 1 < ny) {
        link(id(a, b), id(a + 1, b + 1), o.shear, SpringLayout::Shear);
        link(id(a + 1, b), id(a, b + 1), o.shear, SpringLayout::Shear);
      }
      if (o.bend.enabled) {
        if (a + 2 < nx) link(id(a, b), id(a + 2, b), o.bend, SpringLayout::Bend);
        if (b + 2 < ny) link(id(a, b), id(a, b + 2), o.bend, SpringLayout::Bend);
      }
    }
  DM_ASSERT(body.elementCount() == total, "sheet element count");
  body.prepare();
  return body;
}

Result<MassSpringBody> MassSpringBody::fromMesh(const Mesh& mesh, const MassSpringMeshOptions& o) {
  constexpr const char* where = "MassSpringBody::fromMesh";
  if (Status s = mesh.validate(); !s) return std::move(s).error().within(where);
  if (!std::isfinite(o.mass) || o.mass <= 0)
    return invalid(formatString("mass is %g kg", o.mass), "MassSpringMeshOptions.mass",
                   "give the total mass, finite and > 0 kg");
  if (o.structural.enabled)
    if (Status s = validateSpringMaterial(o.structural, "MassSpringMeshOptions.structural"); !s)
      return std::move(s).error();
  if (o.bend.enabled)
    if (Status s = validateSpringMaterial(o.bend, "MassSpringMeshOptions.bend"); !s)
      return std::move(s).error();
  const std::size_t n = mesh.vertexCount();
  if (n > kMaxParticles)
    return invalid(formatString("the mesh has %zu vertices, more than %zu", n, kMaxParticles), where,
                   "simplify the mesh (dm/math/simplify.hpp)");

  // Lumped masses: a third of each triangle's area to each of its corners.
  std::vector<double> area(n, 0.0);
  std::vector<std::uint8_t> used(n, 0);
  struct HalfEdge {
    std::uint32_t a, b, opposite;  // a < b
  };
  std::vector<HalfEdge> edges;
  edges.reserve(3 * mesh.triangleCount());
  for (std::size_t t = 0; t < mesh.triangleCount(); ++t) {
    const Triangle& tri = mesh.triangles[t];
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) continue;
    const double third = mesh.faceArea(t) / 3.0;
    for (int c = 0; c < 3; ++c) {
      area[tri[c]] += third;
      used[tri[c]] = 1;
      const std::uint32_t a = tri[c], b = tri[(c + 1) % 3];
      edges.push_back({std::min(a, b), std::max(a, b), tri[(c + 2) % 3]});
    }
  }
  if (edges.empty())
    return invalid("the mesh has no non-degenerate triangle", where,
                   "pass a triangle mesh with distinct corners");
  double totalArea = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!used[i])
      return invalid(formatString("vertex %zu is used by no non-degenerate triangle", i),
                     formatString("%s: vertex %zu", where, i),
                     "remove unreferenced vertices, or weld the mesh (dm::weldVertices)");
    if (!(area[i] > 0))
      return invalid(formatString("vertex %zu has zero area around it (all its triangles are flat)", i),
                     formatString("%s: vertex %zu", where, i), "remove degenerate triangles");
    totalArea += area[i];
  }

  MassSpringBody body;
  body.x_.resize(Eigen::Index(3 * n));
  for (std::size_t i = 0; i < n; ++i) body.x_.segment<3>(Eigen::Index(3 * i)) = mesh.positions[i];
  body.v_ = VecX::Zero(Eigen::Index(3 * n));
  body.fext_ = VecX::Zero(Eigen::Index(3 * n));
  body.mass_.resize(n);
  for (std::size_t i = 0; i < n; ++i) body.mass_[i] = o.mass * area[i] / totalArea;
  body.pinned_.assign(n, 0);

  std::sort(edges.begin(), edges.end(), [](const HalfEdge& l, const HalfEdge& r) {
    return l.a != r.a ? l.a < r.a : (l.b != r.b ? l.b < r.b : l.opposite < r.opposite);
  });
  std::vector<std::pair<std::uint32_t, std::uint32_t>> unique, bends;
  for (std::size_t s = 0; s < edges.size();) {
    std::size_t e = s;
    while (e < edges.size() && edges[e].a == edges[s].a && edges[e].b == edges[s].b) ++e;
    unique.emplace_back(edges[s].a, edges[s].b);
    if (e - s == 2 && edges[s].opposite != edges[s + 1].opposite)
      bends.emplace_back(std::min(edges[s].opposite, edges[s + 1].opposite),
                         std::max(edges[s].opposite, edges[s + 1].opposite));
    s = e;
  }
  std::sort(bends.begin(), bends.end());
  bends.erase(std::unique(bends.begin(), bends.end()), bends.end());
  std::erase_if(bends, [&](const auto& p) { return std::binary_search(unique.begin(), unique.end(), p); });

  const auto add = [&body](const std::vector<std::pair<std::uint32_t, std::uint32_t>>& pairs,
                           const SpringMaterial& m, SpringLayout layout) -> Status {
    for (const auto& [i, j] : pairs)
      if (auto e = body.addElement(i, j, m, -1.0, layout); !e) return std::move(e).error();
    return ok();
  };
  if (o.structural.enabled)
    if (Status s = add(unique, o.structural, SpringLayout::Structural); !s) return std::move(s).error();
  if (o.bend.enabled)
    if (Status s = add(bends, o.bend, SpringLayout::Bend); !s) return std::move(s).error();
  body.prepare();
  return body;
}

// ---------------------------------------------------------------------------
// State access

double MassSpringBody::totalMass() const noexcept {
  double m = 0;
  for (double mi : mass_) m += mi;
  return m;
}

void MassSpringBody::setPosition(std::size_t i, const Vec3& x) {
  DM_ASSERT(i < particleCount(), "particle index out of range");
  x_.segment<3>(3 * Eigen::Index(i)) = x;
}

void MassSpringBody::setVelocity(std::size_t i, const Vec3& v) {
  DM_ASSERT(i < particleCount(), "particle index out of range");
  if (!pinned_[i]) v_.segment<3>(3 * Eigen::Index(i)) = v;
}

void MassSpringBody::setPinned(std::size_t i, bool pinned) {
  DM_ASSERT(i < particleCount(), "particle index out of range");
  pinned_[i] = pinned ? 1 : 0;
  if (pinned) v_.segment<3>(3 * Eigen::Index(i)).setZero();
}

void MassSpringBody::setExternalForce(std::size_t i, const Vec3& f) {
  DM_ASSERT(i < particleCount(), "particle index out of range");
  fext_.segment<3>(3 * Eigen::Index(i)) = f;
}

void MassSpringBody::clearExternalForces() { fext_.setZero(); }

Status MassSpringBody::setMass(std::size_t i, double mass) {
  DM_ASSERT(i < particleCount(), "particle index out of range");
  if (!std::isfinite(mass) || mass <= 0)
    return invalid(formatString("mass is %g kg", mass), "MassSpringBody::setMass: mass",
                   "give a finite mass > 0 kg");
  mass_[i] = mass;
  massRangeStale_ = true;
  return ok();
}

Status MassSpringBody::setDrag(double rate) {
  if (!std::isfinite(rate) || rate < 0)
    return invalid(formatString("drag rate is %g 1/s", rate), "MassSpringBody::setDrag: rate",
                   "give a finite rate >= 0 1/s (0: no drag)");
  drag_ = rate;
  return ok();
}

SpringElement MassSpringBody::element(std::size_t e) const {
  DM_ASSERT(e < elementCount(), "element index out of range");
  return SpringElement{ei_[e],
                       ej_[e],
                       rest_[e],
                       k_[e],
                       c_[e],
                       ed_[e],
                       maxwell_[e] ? SpringModel::Maxwell : SpringModel::KelvinVoigt,
                       static_cast<SpringLayout>(layout_[e])};
}

double MassSpringBody::elementTension(std::size_t e) const {
  DM_ASSERT(e < elementCount(), "element index out of range");
  const Vec3 d = position(ej_[e]) - position(ei_[e]);
  const double len = d.norm();
  const double ext = len - rest_[e];
  if (maxwell_[e]) return k_[e] * (ext - ed_[e]);
  const double rate = len > 0 ? d.dot(velocity(ej_[e]) - velocity(ei_[e])) / len : 0.0;
  return k_[e] * ext + c_[e] * rate;
}

Vec3 MassSpringBody::elementForceOn(std::size_t i) const {
  Vec3 f = Vec3::Zero();
  for (std::size_t e = 0; e < elementCount(); ++e) {
    if (ei_[e] != i && ej_[e] != i) continue;
    const Vec3 d = position(ej_[e]) - position(ei_[e]);
    const double len = d.norm();
    if (len == 0) continue;
    const Vec3 pull = elementTension(e) / len * d;  // on i, towards j
    f += ei_[e] == i ? pull : Vec3(-pull);
  }
  return f;
}

double MassSpringBody::kineticEnergy() const {
  double t = 0;
  for (std::size_t i = 0; i < particleCount(); ++i) t += 0.5 * mass_[i] * velocity(i).squaredNorm();
  return t;
}

double MassSpringBody::elasticEnergy() const {
  double u = 0;
  for (std::size_t e = 0; e < elementCount(); ++e) {
    const double s = (position(ej_[e]) - position(ei_[e])).norm() - rest_[e] - ed_[e];
    u += 0.5 * k_[e] * s * s;
  }
  return u;
}

double MassSpringBody::gravitationalEnergy() const {
  double u = 0;
  for (std::size_t i = 0; i < particleCount(); ++i) u -= mass_[i] * gravity_.dot(position(i));
  return u;
}

// ---------------------------------------------------------------------------
// Stepping

void MassSpringBody::prepare() {
  const std::size_t n = particleCount(), m = elementCount();
  // Incidence lists (CSR): the elements touching each particle, in element
  // order, so that the node loops gather forces in a fixed order.
  incStart_.assign(n + 1, 0);
  for (std::size_t e = 0; e < m; ++e) ++incStart_[ei_[e] + 1], ++incStart_[ej_[e] + 1];
  for (std::size_t i = 0; i < n; ++i) incStart_[i + 1] += incStart_[i];
  incElem_.resize(2 * m);
  std::vector<std::uint32_t> fill(incStart_.begin(), incStart_.end() - 1);
  for (std::size_t e = 0; e < m; ++e) {
    incElem_[fill[ei_[e]]++] = std::uint32_t(e);
    incElem_[fill[ej_[e]]++] = std::uint32_t(e);
  }
  // Implicit path: each element in a slot of its owner, its lower end, so
  // that a sweep in owner order finishes particle i once owner i is done.
  // Owners go in groups of two, particles 2g and 2g + 1, whose slots share
  // slot pairs lane by lane (lane 0: the first owner's k-th slot, lane 1 the
  // second's, in element order); the shorter run is padded with empty slots,
  // which point at their owner (an odd count's last group has only empty
  // ones in lane 1, pointing at the first owner).
  const std::size_t groups = (n + 1) / 2;
  std::vector<std::uint32_t> owned(2 * groups, 0);  // slots per owner
  for (std::size_t e = 0; e < m; ++e) ++owned[std::min(ei_[e], ej_[e])];
  ownStart_.assign(groups + 1, 0);
  for (std::size_t g = 0; g < groups; ++g)
    ownStart_[g + 1] = ownStart_[g] + std::max(owned[2 * g], owned[2 * g + 1]);
  const std::size_t slots = 2 * std::size_t(ownStart_[groups]);
  linkElem_.assign(slots, kNoElement);
  linkOther_.resize(slots);
  for (std::size_t g = 0; g < groups; ++g)
    for (std::size_t pr = ownStart_[g]; pr < ownStart_[g + 1]; ++pr) {
      linkOther_[2 * pr] = std::uint32_t(2 * g);
      linkOther_[2 * pr + 1] = std::uint32_t(std::min(2 * g + 1, n - 1));
    }
  fill.assign(n, 0);  // slots placed per owner
  for (std::size_t e = 0; e < m; ++e) {
    const std::uint32_t i = std::min(ei_[e], ej_[e]);
    const std::size_t s = 2 * (ownStart_[i / 2] + fill[i]++) + (i & 1u);
    linkElem_[s] = std::uint32_t(e);
    linkOther_[s] = std::max(ei_[e], ej_[e]);
  }
  leadUntil_.resize(groups);
  std::uint32_t reach = 0;
  for (std::size_t g = 0; g < groups; ++g) {
    reach = std::max(reach, std::uint32_t(std::min(2 * g + 2, n)));
    for (std::size_t s = 2 * ownStart_[g]; s < 2 * ownStart_[g + 1]; ++s)
      reach = std::max(reach, linkOther_[s] + 1);
    leadUntil_[g] = reach;
  }
  blocks_.assign(slots / 2, SlotPair{});
  for (std::size_t s = 0; s < slots; ++s) blocks_[s / 2].j3[s % 2] = 3 * linkOther_[s];
  slotRest_.assign(slots, 0.0);
  for (std::size_t s = 0; s < slots; ++s)
    if (linkElem_[s] != kNoElement) slotRest_[s] = rest_[linkElem_[s]];
  for (auto* vec : {&slotK_, &slotC_, &slotEd_}) vec->assign(slots, 0.0);
  slotH_ = -1.0;
  maxwellCount_ = std::size_t(std::count(maxwell_.begin(), maxwell_.end(), std::uint8_t(1)));
  const auto [lightest, heaviest] = std::minmax_element(mass_.begin(), mass_.end());
  massMin_ = n > 0 ? *lightest : 0.0;
  massMax_ = n > 0 ? *heaviest : 0.0;
  degreeMax_ = 0;
  for (std::size_t i = 0; i < n; ++i) degreeMax_ = std::max(degreeMax_, incStart_[i + 1] - incStart_[i]);
  ef_.assign(3 * std::max(m, slots), 0.0);
  decay_.assign(m, 1.0);
  decayH_ = -1.0;
  dsum_.assign(6 * n, 0.0);
  dinv_.assign(12 * groups, 0.0);
  freeMask_.assign(2 * groups, 0.0);
  for (VecX* vec : {&rhs_, &dv_, &cgR_, &cgZ_, &cgP_, &cgQ_}) *vec = VecX::Zero(Eigen::Index(3 * n));
  prepared_ = true;
}

template <class F>
void MassSpringBody::forEachRange(std::size_t count, F&& fn) const {
  if (count == 0) return;
  if (options_.parallel && particleCount() >= options_.parallelMinParticles && count > kGrain)
    parallelFor(0, count, kGrain, fn);
  else
    fn(std::size_t(0), count);
}

void MassSpringBody::updateMaxwellDecay(double h) {
  if (h == decayH_) return;
  for (std::size_t e = 0; e < elementCount(); ++e)
    decay_[e] = maxwell_[e] ? std::exp(-h * k_[e] / c_[e]) : 1.0;
  decayH_ = h;
}

Status MassSpringBody::stepSymplectic(double h) {
  if (!std::isfinite(h) || h <= 0)
    return invalid(formatString("time step is %g s", h), "MassSpringBody::stepSymplectic: h",
                   "give a finite h > 0 s");
  if (!prepared_) prepare();
  updateMaxwellDecay(h);

  // Element forces at the start of the step; Maxwell dampers relax over it.
  forEachRange(elementCount(), [this](std::size_t b, std::size_t end) {
    for (std::size_t e = b; e < end; ++e) {
      const Vec3 d = load3(x_, ej_[e]) - load3(x_, ei_[e]);
      const double len = d.norm();
      const Vec3 n = len > 0 ? Vec3(d / len) : Vec3::Zero();
      const double ext = len - rest_[e];
      double tension;
      if (maxwell_[e]) {
        const double spring = ext - ed_[e];
        tension = k_[e] * spring;
        // Exact solution of ė_d = k (e − e_d)/c with e held over the step.
        ed_[e] = ext - spring * decay_[e];
      } else {
        tension = k_[e] * ext + c_[e] * n.dot(load3(v_, ej_[e]) - load3(v_, ei_[e]));
      }
      store3(ef_, e, tension * n);
    }
  });

  const Vec3 g = gravity_;
  forEachRange(particleCount(), [this, h, &g](std::size_t b, std::size_t end) {
    for (std::size_t i = b; i < end; ++i) {
      if (pinned_[i]) continue;
      Vec3 f = mass_[i] * (g - drag_ * load3(v_, i)) + load3(fext_, i);
      for (std::uint32_t s = incStart_[i]; s < incStart_[i + 1]; ++s) {
        const std::uint32_t e = incElem_[s];
        const Vec3 fe = load3(ef_, e);
        f += ei_[e] == i ? fe : Vec3(-fe);
      }
      const Eigen::Index k = 3 * Eigen::Index(i);
      v_.segment<3>(k) += (h / mass_[i]) * f;
      x_.segment<3>(k) += h * v_.segment<3>(k);
    }
  });
  return ok();
}

namespace {

#if defined(__GNUC__)
// Two doubles in one SSE2 register (GCC/Clang vector extensions), lane by lane
// the scalar IEEE arithmetic.
using Lane2 = double __attribute__((vector_size(16)));
// The two floats of a SlotPair field in double. With SSE2 it loads 16 bytes
// from the field, which every field but the last (j3) has inside the
// SlotPair (static_assert in sweepLinks), and converts the low two: the
// AVX2 version folds that load into the conversion (one instruction per
// field instead of two, about 3 % of the 64 × 64 sheet step, measured).
inline Lane2 widen(const float (&f)[2]) noexcept {
#if defined(__SSE2__)
  return Lane2(_mm_cvtps_pd(_mm_loadu_ps(f)));
#else
  return Lane2{f[0], f[1]};
#endif
}
inline Lane2 load2(const double* p) noexcept {
  Lane2 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
inline void store2(double* p, Lane2 v) noexcept { std::memcpy(p, &v, sizeof v); }
inline Lane2 splat(double x) noexcept { return Lane2{x, x}; }
inline Lane2 sqrt2(Lane2 x) noexcept {
#if defined(__SSE2__)
  return Lane2(_mm_sqrt_pd(__m128d(x)));
#else
  return Lane2{std::sqrt(x[0]), std::sqrt(x[1])};
#endif
}
// Lane by lane: `x > 0 ? y : 0` (false for NaN).
inline Lane2 wherePositive(Lane2 x, Lane2 y) noexcept {
#if defined(__SSE2__)
  return Lane2(_mm_and_pd(_mm_cmpgt_pd(__m128d(x), _mm_setzero_pd()), __m128d(y)));
#else
  return Lane2{x[0] > 0 ? y[0] : 0.0, x[1] > 0 ? y[1] : 0.0};
#endif
}
// Lane by lane minimum and maximum (either operand for NaN) and |x|.
inline Lane2 lanesMin(Lane2 a, Lane2 b) noexcept {
#if defined(__SSE2__)
  return Lane2(_mm_min_pd(__m128d(a), __m128d(b)));
#else
  return Lane2{a[0] < b[0] ? a[0] : b[0], a[1] < b[1] ? a[1] : b[1]};
#endif
}
inline Lane2 lanesMax(Lane2 a, Lane2 b) noexcept {
#if defined(__SSE2__)
  return Lane2(_mm_max_pd(__m128d(a), __m128d(b)));
#else
  return Lane2{a[0] > b[0] ? a[0] : b[0], a[1] > b[1] ? a[1] : b[1]};
#endif
}
inline Lane2 lanesAbs(Lane2 x) noexcept {
#if defined(__SSE2__)
  return Lane2(_mm_andnot_pd(_mm_set1_pd(-0.0), __m128d(x)));
#else
  return Lane2{std::fabs(x[0]), std::fabs(x[1])};
#endif
}
// {a[0], b[0]} and {a[1], b[1]}, one unpack each (GCC builds some of them
// through memory otherwise).
inline Lane2 lows(Lane2 a, Lane2 b) noexcept {
#if defined(__SSE2__)
  return Lane2(_mm_unpacklo_pd(__m128d(a), __m128d(b)));
#else
  return Lane2{a[0], b[0]};
#endif
}
inline Lane2 highs(Lane2 a, Lane2 b) noexcept {
#if defined(__SSE2__)
  return Lane2(_mm_unpackhi_pd(__m128d(a), __m128d(b)));
#else
  return Lane2{a[1], b[1]};
#endif
}
// Rounds both lanes to float.
inline void narrow(float (&f)[2], Lane2 v) noexcept {
#if defined(__SSE2__)
  const double pair = _mm_cvtsd_f64(_mm_castps_pd(_mm_cvtpd_ps(__m128d(v))));
  std::memcpy(f, &pair, sizeof pair);
#else
  f[0] = float(v[0]), f[1] = float(v[1]);
#endif
}
#else
struct Lane2 {
  double h[2];
  double operator[](int i) const { return h[i]; }
};
inline Lane2 operator+(Lane2 a, Lane2 b) { return {{a.h[0] + b.h[0], a.h[1] + b.h[1]}}; }
inline Lane2 operator-(Lane2 a, Lane2 b) { return {{a.h[0] - b.h[0], a.h[1] - b.h[1]}}; }
inline Lane2 operator*(Lane2 a, Lane2 b) { return {{a.h[0] * b.h[0], a.h[1] * b.h[1]}}; }
inline Lane2& operator+=(Lane2& a, Lane2 b) { return a = a + b; }
inline Lane2& operator-=(Lane2& a, Lane2 b) { return a = a - b; }
inline Lane2 widen(const float (&f)[2]) noexcept { return {{f[0], f[1]}}; }
inline Lane2 load2(const double* p) noexcept { return {{p[0], p[1]}}; }
inline void store2(double* p, Lane2 v) noexcept { p[0] = v.h[0], p[1] = v.h[1]; }
inline Lane2 operator/(Lane2 a, Lane2 b) { return {{a.h[0] / b.h[0], a.h[1] / b.h[1]}}; }
inline Lane2 splat(double x) noexcept { return {{x, x}}; }
inline Lane2 sqrt2(Lane2 x) noexcept { return {{std::sqrt(x.h[0]), std::sqrt(x.h[1])}}; }
inline Lane2 wherePositive(Lane2 x, Lane2 y) noexcept {
  return {{x.h[0] > 0 ? y.h[0] : 0.0, x.h[1] > 0 ? y.h[1] : 0.0}};
}
inline void narrow(float (&f)[2], Lane2 v) noexcept { f[0] = float(v.h[0]), f[1] = float(v.h[1]); }
inline Lane2 lanesMin(Lane2 a, Lane2 b) noexcept {
  return {{a.h[0] < b.h[0] ? a.h[0] : b.h[0], a.h[1] < b.h[1] ? a.h[1] : b.h[1]}};
}
inline Lane2 lanesMax(Lane2 a, Lane2 b) noexcept {
  return {{a.h[0] > b.h[0] ? a.h[0] : b.h[0], a.h[1] > b.h[1] ? a.h[1] : b.h[1]}};
}
inline Lane2 lanesAbs(Lane2 x) noexcept { return {{std::fabs(x.h[0]), std::fabs(x.h[1])}}; }
inline Lane2 lows(Lane2 a, Lane2 b) noexcept { return {{a.h[0], b.h[0]}}; }
inline Lane2 highs(Lane2 a, Lane2 b) noexcept { return {{a.h[1], b.h[1]}}; }
#endif

// The first write of a row y_k of the sweep, in the widths of the scatter
// that follows it (a pair, then a scalar): a 16-byte load of y_k right after
// two 8-byte stores cannot be forwarded from them and waits for them to reach
// the cache (about 4 % of the 64 × 64 sheet step, measured).
inline void leadRow(double* y, double y0, double y1, double y2) noexcept {
  store2(y, Lane2{y0, y1});
  y[2] = y2;
}

// Applies the blocks B of one slot pair (one per lane) to v_j − v_i, with
// the lanes' owners' v_i in v0, v1, v2 and v_j read from v at the pair's
// offsets: adds g = B (v_j − v_i), minus the force on the owner, to y_j and
// subtracts it from the owners' accumulators a0, a1, a2. Adding g to y_j is a
// load-add-store (the add takes y_j from memory: one instruction fewer
// than subtracting the force). v_j − v_i = −(v_i − v_j) and IEEE rounding is
// symmetric, so g is exactly the negated force: the same bits as applying
// the force.
template <class Pair>
inline void applyPair(const Pair& B, const double* v, Lane2 v0, Lane2 v1, Lane2 v2, double* y, Lane2& a0,
                      Lane2& a1, Lane2& a2) noexcept {
  const std::size_t jA = B.j3[0], jB = B.j3[1];
  const Lane2 w0 = Lane2{v[jA], v[jB]} - v0, w1 = Lane2{v[jA + 1], v[jB + 1]} - v1,
              w2 = Lane2{v[jA + 2], v[jB + 2]} - v2;
  const Lane2 n0 = widen(B.n0), n1 = widen(B.n1), n2 = widen(B.n2), ba = widen(B.a);
  const Lane2 t = widen(B.b) * (n0 * w0 + n1 * w1 + n2 * w2);
  const Lane2 g0 = ba * w0 + t * n0, g1 = ba * w1 + t * n1, g2 = ba * w2 + t * n2;
  a0 -= g0, a1 -= g1, a2 -= g2;
  store2(y + jA, load2(y + jA) + lows(g0, g1));
  y[jA + 2] += g2[0];
  store2(y + jB, load2(y + jB) + highs(g0, g1));
  y[jB + 2] += g2[1];
}

}  // namespace

// One sweep over the slots in owner order, accumulating y = (M + h C + h² K) v
// restricted to the free particles, with v taken as 0 on pinned particles
// (the callers keep it so). Each slot's block is applied once: it adds
// B (v_i − v_j) to the owner i and subtracts it from the other end j, in y.
// The owners go two at a time, a lane each (group g: particles 2g, 2g + 1),
// their own sums held in registers. Before group g, lead(k) runs for every
// particle k not yet led up to leadUntil_[g]: it must set v_k and
// y_k = (1 + h·drag) m_k v_k, which is the first write to y_k. After group
// g, no slot touches its particles again: trail(i, second, y0, y1, y2, v0,
// v1, v2) receives their finished rows (the stored row plus the owner's
// sum; not stored) and their v, lane 0 particle i = 2g, lane 1 particle
// i + 1 if `second` (else a meaningless lane). Pinned particles get a
// meaningless row that trail must ignore.
template <class Lead, class Trail>
void MassSpringBody::sweepLinks(const double* v, double* y, Lead&& lead, Trail&& trail) const {
  static_assert(offsetof(SlotPair, n2) + 4 * sizeof(float) <= sizeof(SlotPair), "widen() reads 16 bytes");
  const std::size_t n = particleCount(), groups = (n + 1) / 2;
  const std::uint32_t *own = ownStart_.data(), *leadUntil = leadUntil_.data();
  const SlotPair* pair = blocks_.data();  // the groups' runs follow each other
  std::size_t front = 0;
  for (std::size_t g = 0; g < groups; ++g) {
    for (const std::size_t until = leadUntil[g]; front < until; ++front) lead(front);
    const std::size_t i = 2 * g, k = std::min(i + 1, n - 1);  // k: lane 1's particle (i if none)
    const Lane2 v0 = {v[3 * i], v[3 * k]}, v1 = {v[3 * i + 1], v[3 * k + 1]},
                v2 = {v[3 * i + 2], v[3 * k + 2]};
    Lane2 a0 = splat(0.0), a1 = splat(0.0), a2 = splat(0.0);
    for (const SlotPair* end = blocks_.data() + own[g + 1]; pair != end; ++pair)
      applyPair(*pair, v, v0, v1, v2, y, a0, a1, a2);
    trail(i, i + 1 < n, Lane2{y[3 * i], y[3 * k]} + a0, Lane2{y[3 * i + 1], y[3 * k + 1]} + a1,
          Lane2{y[3 * i + 2], y[3 * k + 2]} + a2, v0, v1, v2);
  }
}

// Preconditioned CG on (M + h C + h² K) Δv = rhs_ from Δv = dv_, with the
// block-Jacobi preconditioner dinv_; the same iteration and stopping rule as
// dm::PcgSolver (relative residual ≤ tolerance, confirmed on the true
// residual, restarting from it otherwise; here the confirming sweep is
// skipped when a rounding-error bound already confirms it), in two passes over memory per
// iteration: sweepLinks() forms the new direction p just ahead of itself and
// returns A p and pᵀAp; one particle loop then updates Δv and r, applies the
// preconditioner and sums rᵀr and rᵀz. Serial: the sweep scatters.
MassSpringBody::CgStop MassSpringBody::solveImplicit(double bnorm, double rr0, double rz,
                                                     const SystemBounds& bounds, ImplicitStepReport& report) {
  const std::size_t n = particleCount();
  const double tol = options_.cgTolerance, ms = massScale_;
  double* x = dv_.data();
  const double* b = rhs_.data();
  double *r = cgR_.data(), *z = cgZ_.data(), *p = cgP_.data(), *q = cgQ_.data();
  const double* mass = mass_.data();
  const std::uint8_t* pinned = pinned_.data();
  const double *dinv = dinv_.data(), *freeMask = freeMask_.data();
  // z_i = D_i⁻¹ r_i; returns r_i·z_i.
  const auto precondition = [&](std::size_t i) {
    const double* d = dinv + 12 * (i / 2) + (i & 1);  // entry c at d[2 c]
    const double r0 = r[3 * i], r1 = r[3 * i + 1], r2 = r[3 * i + 2];
    const double z0 = d[0] * r0 + d[2] * r1 + d[4] * r2;
    const double z1 = d[2] * r0 + d[6] * r1 + d[8] * r2;
    const double z2 = d[4] * r0 + d[8] * r1 + d[10] * r2;
    z[3 * i] = z0, z[3 * i + 1] = z1, z[3 * i + 2] = z2;
    return r0 * z0 + r1 * z1 + r2 * z2;
  };
  // r = b − A x, z = M⁻¹ r; returns rᵀr and sets rz = rᵀz.
  const auto trueResidual = [&](double& rzOut) {
    double rr = 0.0, rzSum = 0.0;
    sweepLinks(
        x, q,
        [&](std::size_t k) {
          const double m = ms * mass[k];
          leadRow(q + 3 * k, m * x[3 * k], m * x[3 * k + 1], m * x[3 * k + 2]);
        },
        [&](std::size_t i, bool second, Lane2 y0, Lane2 y1, Lane2 y2, Lane2, Lane2, Lane2) {
          const auto row = [&](std::size_t k, double q0, double q1, double q2) {
            if (pinned[k]) q0 = q1 = q2 = 0.0;  // b_k = 0 and D_k⁻¹ = 0 there too
            const double r0 = b[3 * k] - q0, r1 = b[3 * k + 1] - q1, r2 = b[3 * k + 2] - q2;
            r[3 * k] = r0, r[3 * k + 1] = r1, r[3 * k + 2] = r2;
            rr += r0 * r0 + r1 * r1 + r2 * r2;
            rzSum += precondition(k);
          };
          row(i, y0[0], y1[0], y2[0]);
          if (second) row(i + 1, y0[1], y1[1], y2[1]);
        });
    rzOut = rzSum;
    return rr;
  };

  double rnorm = std::sqrt(rr0);
  report.relativeResidual = rnorm / bnorm;
  if (!std::isfinite(rnorm)) return CgStop::NotFinite;
  if (report.relativeResidual <= tol) return CgStop::Converged;
  if (!(rz > 0.0) || !std::isfinite(rz)) return CgStop::NotPositive;
  // The recurrence r ← r − α A p drifts from the true residual b − A x by
  // rounding. The drift is at most u·gap (Greenbaum 1997; van der Vorst and
  // Ye 2000), gap summing per iteration j (K + 2) ‖A‖ (‖x_j‖ + ‖x_j+1‖) +
  // 2 (‖r_j‖ + ‖r_j+1‖), from the rounding of x ← x + α p, of r ← r − α q
  // and of the sweep q = A p, whose every entry is within K u of the exact
  // one relative to the row's sum of magnitudes (K: twice its operation
  // count per entry, degreeMax_ + 8). ‖x_j‖ is bounded without a sum over
  // the particles: ‖α p‖ ≤ α (pᵀAp / λ_min)^½. When the recurrence is below
  // the tolerance by more than four times that drift, the true residual is
  // below it too and the confirming sweep is skipped; otherwise it runs.
  constexpr double u = 0x1p-53;
  const double kSweep = 2.0 * (double(degreeMax_) + 8.0), anorm = bounds.anorm;
  double xBound = bounds.x0;                     // ≥ ‖x_j‖ of every iterate so far
  double gap = kSweep * anorm * xBound + rnorm;  // the warm start's residual
  bool restart = true;  // p = z, else p = z + beta p
  double beta = 0.0;
  for (int it = 1; it <= options_.cgMaxIterations; ++it) {
    // q = A p, zero on pinned particles (their free mask), and pᵀAp, a lane
    // per particle of the group.
    Lane2 pAp2 = splat(0.0);
    const auto trail = [&](std::size_t i, bool second, Lane2 y0, Lane2 y1, Lane2 y2, Lane2 p0, Lane2 p1,
                           Lane2 p2) {
      const Lane2 f = load2(freeMask + i);
      y0 = y0 * f, y1 = y1 * f, y2 = y2 * f;
      pAp2 += p0 * y0 + p1 * y1 + p2 * y2;
      double* qi = q + 3 * i;
      store2(qi, lows(y0, y1));
      qi[2] = y2[0];
      if (second) {
        store2(qi + 3, highs(y0, y1));
        qi[5] = y2[1];
      }
    };
    const auto massRow = [&](std::size_t k) {
      const double m = ms * mass[k];
      leadRow(q + 3 * k, m * p[3 * k], m * p[3 * k + 1], m * p[3 * k + 2]);
    };
    if (restart)
      sweepLinks(
          p, q,
          [&](std::size_t k) {
            p[3 * k] = z[3 * k], p[3 * k + 1] = z[3 * k + 1], p[3 * k + 2] = z[3 * k + 2];
            massRow(k);
          },
          trail);
    else
      sweepLinks(
          p, q,
          [&](std::size_t k) {
            const double p0 = z[3 * k] + beta * p[3 * k], p1 = z[3 * k + 1] + beta * p[3 * k + 1],
                         p2 = z[3 * k + 2] + beta * p[3 * k + 2];
            const double m = ms * mass[k];
            p[3 * k] = p0, p[3 * k + 1] = p1, p[3 * k + 2] = p2;
            leadRow(q + 3 * k, m * p0, m * p1, m * p2);
          },
          trail);
    const double pAp = pAp2[0] + pAp2[1];
    if (!std::isfinite(pAp)) return CgStop::NotFinite;
    if (pAp <= 0.0) return CgStop::NotPositive;
    const double alpha = rz / pAp;
    // Two particles at a time: their six coordinates as three lane pairs
    // (x y)(z x')(y' z') for the flat updates, and transposed to one
    // particle per lane, (x x')(y y')(z z'), for the preconditioner, whose
    // blocks dinv_ keeps interleaved in that form.
    const Lane2 al = splat(alpha);
    Lane2 rr2 = splat(0.0), rz2 = splat(0.0);
    std::size_t i = 0;
    for (; i + 2 <= n; i += 2) {
      double *xi = x + 3 * i, *ri = r + 3 * i, *zi = z + 3 * i;
      const double *pi = p + 3 * i, *qi = q + 3 * i;
      store2(xi, load2(xi) + al * load2(pi)), store2(xi + 2, load2(xi + 2) + al * load2(pi + 2));
      store2(xi + 4, load2(xi + 4) + al * load2(pi + 4));
      const Lane2 R0 = load2(ri) - al * load2(qi), R1 = load2(ri + 2) - al * load2(qi + 2),
                  R2 = load2(ri + 4) - al * load2(qi + 4);
      store2(ri, R0), store2(ri + 2, R1), store2(ri + 4, R2);
      rr2 += R0 * R0 + R1 * R1 + R2 * R2;
      const Lane2 rx = Lane2{R0[0], R1[1]}, ry = Lane2{R0[1], R2[0]}, rzc = Lane2{R1[0], R2[1]};
      const double* d = dinv + 6 * i;
      const Lane2 d0 = load2(d), d1 = load2(d + 2), d2 = load2(d + 4), d3 = load2(d + 6), d4 = load2(d + 8),
                  d5 = load2(d + 10);
      const Lane2 zx = d0 * rx + d1 * ry + d2 * rzc, zy = d1 * rx + d3 * ry + d4 * rzc,
                  zz = d2 * rx + d4 * ry + d5 * rzc;
      store2(zi, lows(zx, zy)), store2(zi + 2, Lane2{zz[0], zx[1]}), store2(zi + 4, highs(zy, zz));
      rz2 += rx * zx + ry * zy + rzc * zz;
    }
    double rr = rr2[0] + rr2[1], rzNew = rz2[0] + rz2[1];
    if (i < n) {
      const double r0 = r[3 * i] - alpha * q[3 * i], r1 = r[3 * i + 1] - alpha * q[3 * i + 1],
                   r2 = r[3 * i + 2] - alpha * q[3 * i + 2];
      x[3 * i] += alpha * p[3 * i], x[3 * i + 1] += alpha * p[3 * i + 1], x[3 * i + 2] += alpha * p[3 * i + 2];
      r[3 * i] = r0, r[3 * i + 1] = r1, r[3 * i + 2] = r2;
      rr += r0 * r0 + r1 * r1 + r2 * r2;
      rzNew += precondition(i);
    }
    report.cgIterations = it;
    const double rnormBefore = rnorm;
    rnorm = std::sqrt(rr);
    report.relativeResidual = rnorm / bnorm;
    const double stepBound = bounds.lambda > 0.0 ? alpha * std::sqrt(pAp / bounds.lambda) : HUGE_VAL;
    gap += (kSweep + 2.0) * anorm * (2.0 * xBound + stepBound) + 2.0 * (rnormBefore + rnorm);
    xBound += stepBound;
    if (report.relativeResidual <= tol) {
      if (rnorm + 4.0 * u * gap <= tol * bnorm) return CgStop::Converged;
      // Confirm on the true residual, and restart from it if it is not
      // small enough yet.
      rnorm = std::sqrt(trueResidual(rz));
      report.relativeResidual = rnorm / bnorm;
      if (report.relativeResidual <= tol) return CgStop::Converged;
      if (!(rz > 0.0) || !std::isfinite(rz)) return CgStop::NotPositive;
      gap = kSweep * anorm * xBound + rnorm;
      restart = true;
      continue;
    }
    if (!(rzNew > 0.0) || !std::isfinite(rzNew)) return CgStop::NotPositive;
    beta = rzNew / rz;
    rz = rzNew;
    restart = false;
  }
  return CgStop::MaxIterations;
}

// The implicit step after the checks: assembly, solve and update; returns
// why the solve stopped (Converged also when there was nothing to solve),
// RhsNotFinite before the solve. Compiled once per instruction set (Kernels).
MassSpringBody::CgStop MassSpringBody::stepImplicitCore(double h, ImplicitStepReport& report) {
  const double h2 = h * h;
  massScale_ = 1.0 + h * drag_;  // M + h·drag·M: the drag's velocity Jacobian

  // Per slot: the effective axial stiffness and damping at this h (a Maxwell
  // element acts over the step as a spring of stiffness k/(1 + h k/c), by
  // backward Euler on its damper) and the damper extension.
  if (h != slotH_) {
    for (std::size_t s = 0; s < linkElem_.size(); ++s) {
      const std::uint32_t e = linkElem_[s];
      if (e == kNoElement) continue;
      slotK_[s] = maxwell_[e] ? k_[e] / (1.0 + h * k_[e] / c_[e]) : k_[e];
      slotC_[s] = maxwell_[e] ? 0.0 : c_[e];
    }
    slotH_ = h;
  }
  if (maxwellCount_ > 0)
    for (std::size_t s = 0; s < linkElem_.size(); ++s)
      if (const std::uint32_t e = linkElem_[s]; e != kNoElement && maxwell_[e]) slotEd_[s] = ed_[e];

  // Per slot, two at a time: the block B = a·I + b·n nᵀ of h C + h² K, and
  // the right-hand-side term h f₀ − h² K (v_i − v_j) on the owner i (n points
  // from the owner to the other end; padding slots have zero stiffness and
  // length and give zero blocks and terms). A group's two owners a lane each.
  const std::size_t groups = (particleCount() + 1) / 2;
  forEachRange(groups, [this, h, h2](std::size_t begin, std::size_t end) {
    // The arrays in locals: the stores through B and ef below could alias the
    // members as far as the compiler knows, which would reload every
    // member's data pointer after each store.
    const double *X = x_.data(), *V = v_.data();
    const double *K = slotK_.data(), *C = slotC_.data(), *rest = slotRest_.data(), *ed = slotEd_.data();
    const std::uint32_t* own = ownStart_.data();
    SlotPair* blocks = blocks_.data();
    double* ef = ef_.data();
    const Lane2 hh = splat(h), hh2 = splat(h2), one = splat(1.0);
    const std::size_t n = particleCount();
    for (std::size_t g = begin; g < end; ++g) {
      const std::size_t i = 2 * g, k = std::min(i + 1, n - 1);  // the owners of lanes 0 and 1
      const Lane2 xi0 = {X[3 * i], X[3 * k]}, xi1 = {X[3 * i + 1], X[3 * k + 1]},
                  xi2 = {X[3 * i + 2], X[3 * k + 2]};
      const Lane2 vi0 = {V[3 * i], V[3 * k]}, vi1 = {V[3 * i + 1], V[3 * k + 1]},
                  vi2 = {V[3 * i + 2], V[3 * k + 2]};
      for (std::size_t pr = own[g], last = own[g + 1]; pr < last; ++pr) {
        SlotPair& B = blocks[pr];
        const std::size_t jA = B.j3[0], jB = B.j3[1];
        const Lane2 d0 = Lane2{X[jA], X[jB]} - xi0, d1 = Lane2{X[jA + 1], X[jB + 1]} - xi1,
                    d2 = Lane2{X[jA + 2], X[jB + 2]} - xi2;
        const Lane2 len = sqrt2(d0 * d0 + d1 * d1 + d2 * d2);
        const Lane2 invLen = wherePositive(len, one / len);  // one division serves n and T/L
        const Lane2 n0 = invLen * d0, n1 = invLen * d1, n2 = invLen * d2;
        const Lane2 w0 = Lane2{V[jA], V[jB]} - vi0, w1 = Lane2{V[jA + 1], V[jB + 1]} - vi1,
                    w2 = Lane2{V[jA + 2], V[jB + 2]} - vi2;
        const Lane2 rate = n0 * w0 + n1 * w1 + n2 * w2;
        const Lane2 kAxial = load2(K + 2 * pr), damping = load2(C + 2 * pr);
        const Lane2 spring = kAxial * (len - load2(rest + 2 * pr) - load2(ed + 2 * pr));
        const Lane2 tension = spring + damping * rate;
        // Transverse (geometric) stiffness T/L, kept only while stretched.
        const Lane2 geo = wherePositive(spring, spring * invLen);
        const Lane2 iso = hh2 * geo, axial = hh2 * (kAxial - geo);
        narrow(B.a, iso);
        narrow(B.b, hh * damping + axial);
        narrow(B.n0, n0), narrow(B.n1, n1), narrow(B.n2, n2);
        const Lane2 along = hh * tension + axial * rate;
        double* t = ef + 6 * pr;
        store2(t, along * n0 + iso * w0), store2(t + 2, along * n1 + iso * w1);
        store2(t + 4, along * n2 + iso * w2);
      }
    }
  });

  // One sweep in owner order, a group of two owners at a time (rhs_, dsum_
  // and cgQ_ hold the running sums of the particles ahead of it), assembles
  // the right-hand side b and the diagonal blocks D_i = (1 + h·drag) m_i I +
  // Σ B, inverts D_i as soon as owner i is done, and forms the residual
  // r = b − A Δv of the warm start and z = D⁻¹ r for the solver.
  const Vec3 g = gravity_;
  const std::size_t n = particleCount();
  const double ms = massScale_;
  double *dsum = dsum_.data(), *dinv = dinv_.data(), *rhs = rhs_.data(), *x = dv_.data(), *q = cgQ_.data();
  double *r = cgR_.data(), *z = cgZ_.data(), *freeMask = freeMask_.data();
  const double* ef = ef_.data();
  // Members in locals, as in the block formation above.
  const double *mass = mass_.data(), *V = v_.data(), *fext = fext_.data();
  const std::uint8_t* pinned = pinned_.data();
  const std::uint32_t *own = ownStart_.data(), *leadUntil = leadUntil_.data();
  const SlotPair* blocks = blocks_.data();
  const double drag = drag_;
  std::size_t front = 0;
  double bb = 0.0, rr = 0.0, rz = 0.0, xx = 0.0;
  // For the solve's rounding-error bound, over the blocks B = a I + b n nᵀ:
  // min(a, a + b |n|²), which is ≥ 0 when all are positive semidefinite
  // (|n|² ≤ 1 + 1e-6 for the single-precision n), and max |a| + √3 |b|, a
  // bound on each row sum of |B| (Σ_c |n_r n_c| ≤ √3).
  Lane2 blockMin = splat(HUGE_VAL), blockRowSum = splat(0.0);
  const Lane2 unitSq = splat(1.0 + 1e-6), sqrt3 = splat(1.7320508075688772);
  for (std::size_t gr = 0; gr < groups; ++gr) {
    for (const std::size_t until = leadUntil[gr]; front < until; ++front) {
      const std::size_t k = front;
      for (int c = 0; c < 3; ++c) rhs[3 * k + c] = h * (mass[k] * (g[c] - drag * V[3 * k + c]) + fext[3 * k + c]);
      double* d = dsum + 6 * k;
      const double m = ms * mass[k];
      d[0] = d[3] = d[5] = m;
      d[1] = d[2] = d[4] = 0.0;
      if (pinned[k]) x[3 * k] = x[3 * k + 1] = x[3 * k + 2] = 0.0;
      freeMask[k] = pinned[k] ? 0.0 : 1.0;
      leadRow(q + 3 * k, m * x[3 * k], m * x[3 * k + 1], m * x[3 * k + 2]);
    }
    // The group's owners a lane each; their sums start at zero and are added
    // to the stored rows (which other owners, the first one included, scatter
    // into) once the group is done.
    const std::size_t i0 = 2 * gr, i1 = std::min(i0 + 1, n - 1);
    Lane2 b0 = splat(0.0), b1 = b0, b2 = b0, D0 = b0, D1 = b0, D2 = b0, D3 = b0, D4 = b0, D5 = b0, a0 = b0,
          a1 = b0, a2 = b0;
    const Lane2 x0 = {x[3 * i0], x[3 * i1]}, x1 = {x[3 * i0 + 1], x[3 * i1 + 1]},
                x2 = {x[3 * i0 + 2], x[3 * i1 + 2]};
    for (std::size_t pr = own[gr], last = own[gr + 1]; pr < last; ++pr) {
      const SlotPair& B = blocks[pr];
      const std::size_t jA = B.j3[0], jB = B.j3[1];
      const Lane2 t0 = load2(ef + 6 * pr), t1 = load2(ef + 6 * pr + 2), t2 = load2(ef + 6 * pr + 4);
      b0 += t0, b1 += t1, b2 += t2;
      store2(rhs + jA, load2(rhs + jA) - lows(t0, t1));
      rhs[jA + 2] -= t2[0];
      store2(rhs + jB, load2(rhs + jB) - highs(t0, t1));
      rhs[jB + 2] -= t2[1];
      const Lane2 ba = widen(B.a), bn = widen(B.b), n0 = widen(B.n0), n1 = widen(B.n1), n2 = widen(B.n2);
      blockMin = lanesMin(blockMin, lanesMin(ba, ba + unitSq * bn));
      blockRowSum = lanesMax(blockRowSum, lanesAbs(ba) + sqrt3 * lanesAbs(bn));
      const Lane2 e0 = ba + bn * n0 * n0, e1 = bn * n0 * n1, e2 = bn * n0 * n2, e3 = ba + bn * n1 * n1,
                  e4 = bn * n1 * n2, e5 = ba + bn * n2 * n2;
      D0 += e0, D1 += e1, D2 += e2, D3 += e3, D4 += e4, D5 += e5;
      double *dA = dsum + 2 * jA, *dB = dsum + 2 * jB;  // 6 per particle, j3 = 3 j
      store2(dA, load2(dA) + lows(e0, e1)), store2(dB, load2(dB) + highs(e0, e1));
      store2(dA + 2, load2(dA + 2) + lows(e2, e3)), store2(dB + 2, load2(dB + 2) + highs(e2, e3));
      store2(dA + 4, load2(dA + 4) + lows(e4, e5)), store2(dB + 4, load2(dB + 4) + highs(e4, e5));
      applyPair(B, x, x0, x1, x2, q, a0, a1, a2);
    }
    // Particle i, lane L of the group: b_i, D_i (inverted), the warm start's
    // A Δv, r and z.
    const auto finish = [&](std::size_t i, auto lane) {
      constexpr int L = decltype(lane)::value;
      double* di = dsum + 6 * i;
      Vec3 bi(rhs[3 * i] + b0[L], rhs[3 * i + 1] + b1[L], rhs[3 * i + 2] + b2[L]);
      di[0] += D0[L], di[1] += D1[L], di[2] += D2[L], di[3] += D3[L], di[4] += D4[L], di[5] += D5[L];
      double y0 = q[3 * i] + a0[L], y1 = q[3 * i + 1] + a1[L], y2 = q[3 * i + 2] + a2[L];
      xx += x[3 * i] * x[3 * i] + x[3 * i + 1] * x[3 * i + 1] + x[3 * i + 2] * x[3 * i + 2];
      double inv[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};  // D_i⁻¹; 0 for a pinned particle
      if (pinned[i]) {
        bi.setZero();
        y0 = y1 = y2 = 0.0;
      } else {
        // Inverse of the symmetric block by cofactors.
        const double c00 = di[3] * di[5] - di[4] * di[4], c01 = di[2] * di[4] - di[1] * di[5],
                     c02 = di[1] * di[4] - di[2] * di[3];
        const double det = 1.0 / (di[0] * c00 + di[1] * c01 + di[2] * c02);
        const double c11 = di[0] * di[5] - di[2] * di[2], c12 = di[1] * di[2] - di[0] * di[4],
                     c22 = di[0] * di[3] - di[1] * di[1];
        inv[0] = c00 * det, inv[1] = c01 * det, inv[2] = c02 * det;
        inv[3] = c11 * det, inv[4] = c12 * det, inv[5] = c22 * det;
      }
      double* dout = dinv + 12 * (i / 2) + (i & 1);
      for (int c = 0; c < 6; ++c) dout[2 * c] = inv[c];
      rhs[3 * i] = bi.x(), rhs[3 * i + 1] = bi.y(), rhs[3 * i + 2] = bi.z();
      bb += bi.squaredNorm();
      const double r0 = bi.x() - y0, r1 = bi.y() - y1, r2 = bi.z() - y2;
      r[3 * i] = r0, r[3 * i + 1] = r1, r[3 * i + 2] = r2;
      rr += r0 * r0 + r1 * r1 + r2 * r2;
      const double z0 = inv[0] * r0 + inv[1] * r1 + inv[2] * r2;
      const double z1 = inv[1] * r0 + inv[3] * r1 + inv[4] * r2;
      const double z2 = inv[2] * r0 + inv[4] * r1 + inv[5] * r2;
      z[3 * i] = z0, z[3 * i + 1] = z1, z[3 * i + 2] = z2;
      rz += r0 * z0 + r1 * z1 + r2 * z2;
    };
    finish(i0, std::integral_constant<int, 0>{});
    if (i0 + 1 < n) finish(i0 + 1, std::integral_constant<int, 1>{});
  }

  const double bnorm = std::sqrt(bb);
  if (!std::isfinite(bnorm) || !dv_.allFinite()) {
    dv_.setZero();
    return CgStop::RhsNotFinite;
  }
  CgStop stop = CgStop::Converged;
  if (bnorm == 0.0) {
    dv_.setZero();
  } else {
    // ‖A‖₂ ≤ the largest row sum of its entries' magnitudes (A is
    // symmetric); A ⪰ (1 + h·drag) M when every block is semidefinite.
    SystemBounds bounds;
    bounds.anorm = ms * massMax_ + 2.0 * double(degreeMax_) * std::max(blockRowSum[0], blockRowSum[1]);
    bounds.lambda = std::min(blockMin[0], blockMin[1]) >= 0.0 ? ms * massMin_ : 0.0;
    bounds.x0 = std::sqrt(xx);
    stop = solveImplicit(bnorm, rr, rz, bounds, report);
    if (stop == CgStop::MaxIterations && !dv_.allFinite()) stop = CgStop::NotFinite;
    if (stop == CgStop::NotFinite || stop == CgStop::NotPositive) {
      dv_.setZero();
      return stop;
    }
  }

  forEachRange(particleCount(), [this, h](std::size_t b, std::size_t end) {
    for (std::size_t i = b; i < end; ++i) {
      if (pinned_[i]) continue;
      const Eigen::Index k = 3 * Eigen::Index(i);
      v_.segment<3>(k) += dv_.segment<3>(k);
      x_.segment<3>(k) += h * v_.segment<3>(k);
    }
  });
  // Maxwell dampers: backward Euler at the new stretch,
  // e_d' = (e_d + β e')/(1 + β), β = h k/c — consistent with kAxial above.
  if (maxwellCount_ > 0)
    forEachRange(elementCount(), [this, h](std::size_t b, std::size_t end) {
      for (std::size_t e = b; e < end; ++e) {
        if (!maxwell_[e]) continue;
        const double ext = (load3(x_, ej_[e]) - load3(x_, ei_[e])).norm() - rest_[e];
        const double beta = h * k_[e] / c_[e];
        ed_[e] = (ed_[e] + beta * ext) / (1.0 + beta);
      }
    });
  return stop;
}

// The implicit step's entry points per instruction set. The AVX2 version is
// the same source with everything inlined into it (flatten) and compiled for
// AVX2 without FMA: operation for operation the same IEEE arithmetic as the
// SSE2 version, so both give the same bits; VEX encoding (three operands)
// spares the register copies of the two-operand forms (5-7 % of the 64 x 64
// sheet step, measured). Flattening inlines stepImplicitCore, an exported
// member, only because the modules are built with -fno-semantic-interposition
// (cmake/DMHelpers.cmake); without it stepAvx2 is a jump to the SSE2 code.
// Chosen once with __builtin_cpu_supports (not an ifunc, as in
// constraint_solver.cpp); GCC and clang on x86-64, not under ThreadSanitizer.
#if defined(__GNUC__) && defined(__x86_64__) && !defined(__AVX2__) && !defined(__SANITIZE_THREAD__)
#define DM_MASS_SPRING_AVX2 1
#endif

struct MassSpringBody::Kernels {
  using StepFn = CgStop (*)(MassSpringBody&, double, ImplicitStepReport&);
  static CgStop step(MassSpringBody& body, double h, ImplicitStepReport& report) {
    return body.stepImplicitCore(h, report);
  }
#if defined(DM_MASS_SPRING_AVX2)
  [[gnu::target("avx2"), gnu::noinline, gnu::flatten]] static CgStop stepAvx2(MassSpringBody& body, double h,
                                                                            ImplicitStepReport& report) {
    return body.stepImplicitCore(h, report);
  }
  [[gnu::target("arch=x86-64-v4"), gnu::noinline, gnu::flatten]] static CgStop stepAvx512(
      MassSpringBody& body, double h, ImplicitStepReport& report) {
    return body.stepImplicitCore(h, report);
  }
#endif
  static StepFn pick() noexcept {
#if defined(DM_MASS_SPRING_AVX2)
    if (simdLevel() == SimdLevel::Avx512) return &stepAvx512;
    if (simdLevel() == SimdLevel::Avx2) return &stepAvx2;
#endif
    return &step;
  }
};

Result<ImplicitStepReport> MassSpringBody::stepImplicit(double h) {
  constexpr const char* where = "MassSpringBody::stepImplicit";
  if (!std::isfinite(h) || h <= 0)
    return invalid(formatString("time step is %g s", h), formatString("%s: h", where),
                   "give a finite h > 0 s");
  if (!prepared_) prepare();
  if (massRangeStale_) {  // the CG's bounds (stepImplicitCore) use the lightest and heaviest
    const auto [lightest, heaviest] = std::minmax_element(mass_.begin(), mass_.end());
    massMin_ = mass_.empty() ? 0.0 : *lightest;
    massMax_ = mass_.empty() ? 0.0 : *heaviest;
    massRangeStale_ = false;
  }
  // Picked on first use (a function-local static: safe from other static
  // initialisers that step a body).
  static const Kernels::StepFn stepFn = Kernels::pick();
  ImplicitStepReport report;
  switch (stepFn(*this, h, report)) {
    case CgStop::Converged:
      return report;
    case CgStop::MaxIterations:
      report.converged = false;
      return report;
    case CgStop::RhsNotFinite:
      return invalid("the right-hand side is not finite", where,
                     "check the state (positions, velocities, forces) for NaN or Inf");
    case CgStop::NotFinite:
      return invalid(formatString("CG produced a non-finite value at iteration %d", report.cgIterations), where,
                     "check the state and the materials for NaN, Inf or extreme values");
    case CgStop::NotPositive:
      return invalid(
          formatString("the system lost positive definiteness at CG iteration %d", report.cgIterations), where,
          "check for Maxwell elements compressed past their rest length, or reduce h");
  }
  return report;
}

}  // namespace dm
