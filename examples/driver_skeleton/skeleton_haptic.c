/* skeleton-haptic — the smallest complete haptic-device driver, to copy when
 * writing a driver for real hardware (see docs/writing-a-driver.md).
 *
 * It models a stylus resting at a configurable point on a spring mount: the
 * position it reports moves by force / mount_stiffness along the force the
 * host last sent, so a host can see its output arrive. Where a real driver
 * talks to the vendor SDK, the comments marked "HARDWARE" say what goes
 * there. Plain C99; needs only the two ABI headers, no DMPlatform library.
 *
 * Parameters: position "x,y,z" (m, default 0,0,0), mount_stiffness (N/m,
 * default 500), max_force (N, default 3). */
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct Skeleton {
  double rest[3];
  double stiffness;
  double max_force;
  double force[3]; /* last output */
} Skeleton;

static const char* find_param(const DmDeviceParam* params, size_t count, const char* key) {
  size_t i;
  for (i = 0; i < count; ++i)
    if (params[i].key && strcmp(params[i].key, key) == 0) return params[i].value;
  return NULL;
}

/* Parses a positive number; writes an error naming the key on failure. */
static int parse_positive(const char* value, const char* key, double* out, char* error, size_t error_size) {
  char* end = NULL;
  const double x = strtod(value, &end);
  if (end == value || *end != '\0' || !(x > 0.0) || x > 1e9) {
    snprintf(error, error_size, "parameter '%s': '%s' is not a positive number", key, value);
    return 0;
  }
  *out = x;
  return 1;
}

static DmDevice* skeleton_open(const DmDeviceParam* params, size_t count, char* error, size_t error_size) {
  Skeleton* s;
  const char* v;
  size_t i;
  for (i = 0; i < count; ++i) {
    const char* k = params[i].key ? params[i].key : "";
    if (strcmp(k, "position") != 0 && strcmp(k, "mount_stiffness") != 0 && strcmp(k, "max_force") != 0) {
      snprintf(error, error_size, "unknown parameter '%s' (known: position, mount_stiffness, max_force)", k);
      return NULL;
    }
  }
  s = (Skeleton*)calloc(1, sizeof *s);
  if (!s) {
    snprintf(error, error_size, "out of memory");
    return NULL;
  }
  s->stiffness = 500.0;
  s->max_force = 3.0;
  if ((v = find_param(params, count, "position")) != NULL &&
      sscanf(v, "%lf,%lf,%lf", &s->rest[0], &s->rest[1], &s->rest[2]) != 3) {
    snprintf(error, error_size, "parameter 'position': '%s' is not \"x,y,z\"", v);
    free(s);
    return NULL;
  }
  if (((v = find_param(params, count, "mount_stiffness")) != NULL &&
       !parse_positive(v, "mount_stiffness", &s->stiffness, error, error_size)) ||
      ((v = find_param(params, count, "max_force")) != NULL &&
       !parse_positive(v, "max_force", &s->max_force, error, error_size))) {
    free(s);
    return NULL;
  }
  /* HARDWARE: open the device here (vendor SDK init, USB/serial handle). */
  return (DmDevice*)s;
}

static void skeleton_close(DmDevice* device) {
  /* HARDWARE: send zero force, then release the device. */
  free(device);
}

static int skeleton_info(DmDevice* device, DmHapticInfo* info) {
  const Skeleton* s = (const Skeleton*)device;
  int i;
  memset(info, 0, sizeof *info);
  snprintf(info->identity.driver, sizeof info->identity.driver, "skeleton-haptic");
  snprintf(info->identity.vendor, sizeof info->identity.vendor, "example");
  snprintf(info->identity.model, sizeof info->identity.model, "stylus on a spring mount");
  snprintf(info->identity.serial, sizeof info->identity.serial, "0001");
  info->capabilities = DM_HAPTIC_CAP_POSITION | DM_HAPTIC_CAP_FORCE;
  for (i = 0; i < 3; ++i) {
    info->workspace_min[i] = s->rest[i] - 0.1;
    info->workspace_max[i] = s->rest[i] + 0.1;
  }
  info->max_force = s->max_force; /* HARDWARE: the device's rated continuous force */
  info->max_stiffness = 1000.0;
  info->max_damping = 5.0;
  info->servo_rate_hz = 1000.0;
  return DM_DEVICE_OK;
}

static int skeleton_read(DmDevice* device, int64_t now_ns, DmHapticState* state) {
  const Skeleton* s = (const Skeleton*)device;
  int i;
  /* HARDWARE: read encoders / the SDK's latest sample; return
   * DM_DEVICE_ERROR_LOST if the device disappeared. Never block here. */
  memset(state, 0, sizeof *state);
  state->time_ns = now_ns;
  for (i = 0; i < 3; ++i) state->position[i] = s->rest[i] + s->force[i] / s->stiffness;
  state->orientation[0] = 1.0;
  return DM_DEVICE_OK;
}

static int skeleton_write(DmDevice* device, int64_t now_ns, const double force[3], const double torque[3]) {
  Skeleton* s = (Skeleton*)device;
  (void)now_ns;
  (void)torque;
  /* HARDWARE: send the force to the motors. The host has already clamped it
   * to max_force and removed NaN/Inf. Never block here. */
  memcpy(s->force, force, sizeof s->force);
  return DM_DEVICE_OK;
}

static const DmHapticDeviceVTable kSkeleton = {skeleton_open,  skeleton_close, skeleton_info,
                                               skeleton_read,  skeleton_write, NULL};

static int skeleton_init(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_HAPTIC_DEVICE_KIND, "skeleton-haptic",
                                DM_HAPTIC_DEVICE_KIND_ABI_VERSION, &kSkeleton);
}

static const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "skeleton-haptic", "1.0.0", skeleton_init, NULL};

DM_PLUGIN_ENTRY { return &kInfo; }
