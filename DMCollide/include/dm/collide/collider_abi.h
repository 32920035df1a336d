/* dm/collide/collider_abi.h — the C boundary for collider plugins.
 *
 * A plugin (see dm/core/plugin_abi.h) adds a narrow-phase collider for one
 * pair of shape types by registering a factory of kind DM_COLLIDER_KIND whose
 * vtable is a DmColliderVTable. The host (dm::registerPluginColliders in
 * dm/collide/collider_plugin.hpp) puts it into the collider table; from then
 * on dm::intersect / collide / distance and the collision world use it for
 * that pair, in either order.
 *
 * Shapes cross the boundary as DmShapeView: the type name and, for the
 * built-in kinds, their parameters in the local frame (metres):
 *   point        params = {x, y, z}
 *   segment      params = {ax, ay, az, bx, by, bz}
 *   plane        params = {nx, ny, nz, offset}        (half-space n·x ≤ offset)
 *   triangle     params = {ax, ay, az, bx, by, bz, cx, cy, cz}
 *   sphere       params = {radius}
 *   box          params = {hx, hy, hz}                (half extents)
 *   capsule      params = {radius, halfLength}        (axis z)
 *   cylinder     params = {radius, halfLength}        (axis z)
 *   ellipsoid    params = {rx, ry, rz}
 *   convex-hull, triangle-mesh: vertices/triangles set (no params)
 * Other kinds (and user kinds) have no params; `shape` is then the host's
 * dm::Shape object, usable by a C++ plugin that knows the class.
 * Poses are rigid transforms local → world: x_world = R·x + t, R row-major.
 *
 * Functions must be thread-safe (queries run in parallel), must not throw,
 * and should not allocate. Everything is in world coordinates; normals point
 * from shape A to shape B (A is the vtable's shape_a).
 *
 * @code
 *   static const DmColliderVTable kPlaneMesh = {"plane", "triangle-mesh", hit, contacts, dist};
 *   host->register_factory(host->ctx, DM_COLLIDER_KIND, "plane-mesh", DM_COLLIDER_KIND_ABI_VERSION,
 *                          &kPlaneMesh);
 * @endcode
 */
#ifndef DM_COLLIDE_COLLIDER_ABI_H
#define DM_COLLIDE_COLLIDER_ABI_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Factory kind and the layout version of DmColliderVTable / DmShapeView. */
#define DM_COLLIDER_KIND "collider"
#define DM_COLLIDER_KIND_ABI_VERSION 1u

/* Largest number of contacts the host accepts from one contacts() call. */
#define DM_COLLIDER_MAX_CONTACTS 64

/* A shape as a plugin sees it (see the table above). */
typedef struct DmShapeView {
  const char* type_name;       /* "sphere", "triangle-mesh", or a user kind */
  uint32_t param_count;        /* number of valid entries in params */
  double params[12];           /* kind parameters, metres */
  const double* vertices;      /* xyz per vertex (hulls and meshes), else NULL */
  uint32_t vertex_count;
  const uint32_t* triangles;   /* three vertex indices per triangle, CCW from outside */
  uint32_t triangle_count;
  const void* shape;           /* the host's dm::Shape (C++ plugins only) */
} DmShapeView;

/* Rigid pose: x_world = rotation · x_local + translation. */
typedef struct DmPose {
  double rotation[9]; /* row-major */
  double translation[3];
} DmPose;

/* One contact, world frame: position (m), unit normal from A to B, depth ≥ 0 (m). */
typedef struct DmContact {
  double position[3];
  double normal[3];
  double depth;
} DmContact;

/* The collider of one shape pair (shape_a, shape_b), by type name. */
typedef struct DmColliderVTable {
  const char* shape_a;
  const char* shape_b;
  /* 1 if the shapes overlap or touch, else 0. */
  int (*intersect)(const DmShapeView* a, const DmPose* pose_a, const DmShapeView* b, const DmPose* pose_b);
  /* Writes up to max_contacts contacts into out and returns how many (0 when
   * apart). max_contacts ≤ DM_COLLIDER_MAX_CONTACTS. */
  int (*contacts)(const DmShapeView* a, const DmPose* pose_a, const DmShapeView* b, const DmPose* pose_b,
                  DmContact* out, int max_contacts);
  /* Signed distance (m, negative = penetration depth) and the closest (or
   * deepest) points on A and B, world frame. Returns 0 on success, nonzero if
   * the distance is unavailable for these shapes. */
  int (*distance)(const DmShapeView* a, const DmPose* pose_a, const DmShapeView* b, const DmPose* pose_b,
                  double* distance, double point_a[3], double point_b[3]);
} DmColliderVTable;

#ifdef __cplusplus
}
#endif

#endif /* DM_COLLIDE_COLLIDER_ABI_H */
