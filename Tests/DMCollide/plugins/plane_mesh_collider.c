/* A collider plugin in plain C: the pair (plane, triangle-mesh), which the
 * built-in table does not serve. Exact for any mesh: a half-space's distance
 * to (and penetration of) a polyhedral surface is attained at a vertex. */
#include <dm/collide/collider_abi.h>
#include <dm/core/plugin_abi.h>

#include <math.h>

/* The plane in world coordinates: n·x ≤ offset, n unit. */
static void worldPlane(const DmShapeView* plane, const DmPose* pose, double n[3], double* offset) {
  int r;
  for (r = 0; r < 3; ++r)
    n[r] = pose->rotation[3 * r] * plane->params[0] + pose->rotation[3 * r + 1] * plane->params[1] +
           pose->rotation[3 * r + 2] * plane->params[2];
  *offset = plane->params[3] + n[0] * pose->translation[0] + n[1] * pose->translation[1] + n[2] * pose->translation[2];
}

static void worldVertex(const DmShapeView* mesh, const DmPose* pose, uint32_t i, double x[3]) {
  const double* v = mesh->vertices + 3 * (size_t)i;
  int r;
  for (r = 0; r < 3; ++r)
    x[r] = pose->rotation[3 * r] * v[0] + pose->rotation[3 * r + 1] * v[1] + pose->rotation[3 * r + 2] * v[2] +
           pose->translation[r];
}

/* Signed distance of vertex i above the plane (negative: below, inside). */
static double height(const DmShapeView* mesh, const DmPose* pm, uint32_t i, const double n[3], double offset,
                     double x[3]) {
  worldVertex(mesh, pm, i, x);
  return n[0] * x[0] + n[1] * x[1] + n[2] * x[2] - offset;
}

static int intersect(const DmShapeView* plane, const DmPose* pp, const DmShapeView* mesh, const DmPose* pm) {
  double n[3], offset, x[3];
  uint32_t i;
  worldPlane(plane, pp, n, &offset);
  for (i = 0; i < mesh->vertex_count; ++i)
    if (height(mesh, pm, i, n, offset, x) <= 0.0) return 1;
  return 0;
}

/* The max_contacts deepest vertices below the plane, deepest first. */
static int contacts(const DmShapeView* plane, const DmPose* pp, const DmShapeView* mesh, const DmPose* pm,
                    DmContact* out, int max_contacts) {
  double n[3], offset, x[3];
  uint32_t i;
  int count = 0, k, j;
  worldPlane(plane, pp, n, &offset);
  for (i = 0; i < mesh->vertex_count; ++i) {
    const double h = height(mesh, pm, i, n, offset, x);
    if (h > 0.0) continue;
    /* insertion into the sorted (by depth, descending) list of at most max_contacts */
    for (k = count; k > 0 && out[k - 1].depth < -h; --k)
      if (k < max_contacts) out[k] = out[k - 1];
    if (k >= max_contacts) continue;
    if (count < max_contacts) ++count;
    for (j = 0; j < 3; ++j) {
      out[k].position[j] = x[j] - 0.5 * h * n[j]; /* midway between vertex and plane */
      out[k].normal[j] = n[j];                    /* the mesh leaves along +n */
    }
    out[k].depth = -h;
  }
  return count;
}

static int distance(const DmShapeView* plane, const DmPose* pp, const DmShapeView* mesh, const DmPose* pm,
                    double* dist, double point_a[3], double point_b[3]) {
  double n[3], offset, x[3], best = INFINITY;
  uint32_t i;
  int j;
  if (mesh->vertex_count == 0) return 1;
  worldPlane(plane, pp, n, &offset);
  for (i = 0; i < mesh->vertex_count; ++i) {
    const double h = height(mesh, pm, i, n, offset, x);
    if (h < best) {
      best = h;
      for (j = 0; j < 3; ++j) {
        point_b[j] = x[j];
        point_a[j] = x[j] - h * n[j];
      }
    }
  }
  *dist = best;
  return 0;
}

static const DmColliderVTable kPlaneMesh = {"plane", "triangle-mesh", intersect, contacts, distance};

static int init(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_COLLIDER_KIND, "plane-mesh", DM_COLLIDER_KIND_ABI_VERSION,
                                &kPlaneMesh);
}

static const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "test-plane-mesh-collider", "1.0", init, NULL};

DM_PLUGIN_ENTRY { return &kInfo; }
