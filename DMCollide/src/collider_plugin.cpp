// Plugin colliders: C vtables (dm/collide/collider_abi.h) adapted to the
// collider table's function pointers. The table stores plain function
// pointers without a context, so each of kMaxPluginColliders slots gets its
// own adapter functions (templates over the slot index) that read the slot's
// vtable.
#include <dm/collide/bvh.hpp>
#include <dm/collide/collider_plugin.hpp>

#include <array>
#include <memory>
#include <string>
#include <utility>

namespace dm {

namespace {

struct Slot {
  const DmColliderVTable* vtable = nullptr;
  std::shared_ptr<const void> keepAlive;  // keeps the plugin library mapped
};
std::array<Slot, kMaxPluginColliders> gSlots;
int gSlotsUsed = 0;

DmPose toC(const Isometry3& pose) noexcept {
  DmPose p;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) p.rotation[3 * r + c] = pose.linear()(r, c);
    p.translation[r] = pose.translation()[r];
  }
  return p;
}

Vec3 fromC(const double* v) noexcept { return {v[0], v[1], v[2]}; }

template <int I>
bool slotIntersect(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb, PairCache*) {
  const DmShapeView va = shapeView(a), vb = shapeView(b);
  const DmPose ca = toC(pa), cb = toC(pb);
  return gSlots[I].vtable->intersect(&va, &ca, &vb, &cb) != 0;
}

template <int I>
void slotContacts(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                  const CollisionRequest& request, CollisionResult& out, PairCache*) {
  const DmShapeView va = shapeView(a), vb = shapeView(b);
  const DmPose ca = toC(pa), cb = toC(pb);
  DmContact buffer[DM_COLLIDER_MAX_CONTACTS];
  const int wanted = request.maxContacts < 1                          ? 1
                     : request.maxContacts > DM_COLLIDER_MAX_CONTACTS ? DM_COLLIDER_MAX_CONTACTS
                                                                      : request.maxContacts;
  int n = gSlots[I].vtable->contacts(&va, &ca, &vb, &cb, buffer, wanted);
  if (n > wanted) n = wanted;  // a plugin that overran its bound is not trusted further
  for (int i = 0; i < n; ++i) {
    const Vec3 normal = fromC(buffer[i].normal);
    const double len = normal.norm();
    if (!(len > 0.0) || !std::isfinite(buffer[i].depth)) continue;  // drop malformed contacts
    out.contacts.push_back({fromC(buffer[i].position), normal / len, std::max(0.0, buffer[i].depth)});
  }
  out.colliding = out.colliding || n > 0;
}

template <int I>
DistanceResult slotDistance(const Shape& a, const Isometry3& pa, const Shape& b, const Isometry3& pb,
                            PairCache*) {
  const DmShapeView va = shapeView(a), vb = shapeView(b);
  const DmPose ca = toC(pa), cb = toC(pb);
  DistanceResult r;
  double d = 0.0, pA[3] = {0, 0, 0}, pB[3] = {0, 0, 0};
  if (gSlots[I].vtable->distance(&va, &ca, &vb, &cb, &d, pA, pB) != 0) {
    r.supported = false;
    return r;
  }
  r.distance = d;
  r.pointA = fromC(pA);
  r.pointB = fromC(pB);
  return r;
}

template <std::size_t... I>
constexpr std::array<Collider, sizeof...(I)> makeAdapters(std::index_sequence<I...>) {
  return {Collider{&slotIntersect<I>, &slotContacts<I>, &slotDistance<I>}...};
}
const std::array<Collider, kMaxPluginColliders> kAdapters =
    makeAdapters(std::make_index_sequence<kMaxPluginColliders>{});

// Built-in kind by name, else a user kind (registered on first use).
Result<ShapeType> resolveType(std::string_view name) {
  for (int i = 0; i < static_cast<int>(ShapeType::FirstUser); ++i)
    if (shapeTypeName(static_cast<ShapeType>(i)) == name) return static_cast<ShapeType>(i);
  return registerShapeType(name);
}

}  // namespace

DmShapeView shapeView(const Shape& shape) noexcept {
  DmShapeView v{};
  v.type_name = shapeTypeName(shape.type()).data();  // names are static, NUL-terminated storage
  v.shape = &shape;
  auto put = [&v](std::initializer_list<double> values) {
    for (double x : values) v.params[v.param_count++] = x;
  };
  auto putVec = [&put](const Vec3& p) { put({p.x(), p.y(), p.z()}); };
  auto putMesh = [&v](const Mesh& m) {
    v.vertices = m.positions.empty() ? nullptr : m.positions.front().data();
    v.vertex_count = static_cast<std::uint32_t>(m.positions.size());
    v.triangles = m.triangles.empty() ? nullptr : m.triangles.front().data();
    v.triangle_count = static_cast<std::uint32_t>(m.triangles.size());
  };
  switch (shape.type()) {
    case ShapeType::Point:
      putVec(static_cast<const Point&>(shape).position());
      break;
    case ShapeType::Segment:
      putVec(static_cast<const Segment&>(shape).a());
      putVec(static_cast<const Segment&>(shape).b());
      break;
    case ShapeType::Plane: {
      const auto& p = static_cast<const Plane&>(shape);
      putVec(p.normal());
      put({p.offset()});
      break;
    }
    case ShapeType::TriangleShape:
      for (int i = 0; i < 3; ++i) putVec(static_cast<const TriangleShape&>(shape).vertex(i));
      break;
    case ShapeType::Sphere:
      put({static_cast<const Sphere&>(shape).radius()});
      break;
    case ShapeType::Box:
      putVec(static_cast<const Box&>(shape).halfExtents());
      break;
    case ShapeType::Capsule:
      put({static_cast<const Capsule&>(shape).radius(), static_cast<const Capsule&>(shape).halfLength()});
      break;
    case ShapeType::Cylinder:
      put({static_cast<const Cylinder&>(shape).radius(), static_cast<const Cylinder&>(shape).halfLength()});
      break;
    case ShapeType::Ellipsoid:
      putVec(static_cast<const Ellipsoid&>(shape).radii());
      break;
    case ShapeType::ConvexHull:
      putMesh(static_cast<const ConvexHull&>(shape).mesh());
      break;
    case ShapeType::TriangleMesh:
      putMesh(*static_cast<const TriangleMesh&>(shape).mesh());
      break;
    default:
      break;
  }
  return v;
}

Result<int> registerPluginColliders(const FactoryRegistry& registry, ColliderTable& table) {
  int added = 0;
  for (const Factory& f : registry.list(DM_COLLIDER_KIND)) {
    const std::string where = "collider '" + f.key.name + "' from " + f.provider;
    if (f.kindAbiVersion != DM_COLLIDER_KIND_ABI_VERSION)
      return fail(ErrorCode::Version,
                  "collider ABI " + std::to_string(f.kindAbiVersion) + ", host expects " +
                      std::to_string(DM_COLLIDER_KIND_ABI_VERSION),
                  where, "rebuild the plugin against this SDK's dm/collide/collider_abi.h");
    const auto* vt = f.as<DmColliderVTable>();
    if (!vt || !vt->intersect || !vt->contacts || !vt->distance)
      return fail(ErrorCode::InvalidArgument, "null collider function", where,
                  "set intersect, contacts and distance in the DmColliderVTable");
    if (!vt->shape_a || !*vt->shape_a || !vt->shape_b || !*vt->shape_b)
      return fail(ErrorCode::InvalidArgument, "empty shape type name", where,
                  "name both shape kinds, e.g. \"plane\" and \"triangle-mesh\"");
    int slot = -1;
    for (int i = 0; i < gSlotsUsed; ++i)
      if (gSlots[i].vtable == vt) slot = i;
    if (slot < 0) {
      if (gSlotsUsed == kMaxPluginColliders)
        return fail(ErrorCode::Busy,
                    "all " + std::to_string(kMaxPluginColliders) + " plugin collider slots are used", where,
                    "load fewer collider plugins");
      slot = gSlotsUsed++;
      gSlots[slot] = {vt, f.keepAlive};
    }
    auto a = resolveType(vt->shape_a);
    if (!a) return a.error().within(where);
    auto b = resolveType(vt->shape_b);
    if (!b) return b.error().within(where);
    if (Status s = table.registerCollider(*a, *b, kAdapters[slot]); !s) return s.error().within(where);
    ++added;
  }
  return added;
}

}  // namespace dm
