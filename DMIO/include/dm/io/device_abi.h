/* dm/io/device_abi.h — the C boundary for device driver plugins.
 *
 * A driver is a factory (dm/core/plugin_abi.h) of a device kind; this header
 * defines what all kinds share (parameters, status codes, identity) and the
 * vtable of the haptic-device kind. A driver instance is an opaque DmDevice
 * created by `open` from flat key/value parameters (the scene's device
 * object, e.g. {"path": "circle", "radius": "0.03"}) and destroyed by
 * `close`.
 *
 * Time: the host passes its loop time (nanoseconds on the loop's clock:
 * CLOCK_MONOTONIC in real time, a virtual clock in lockstep) to every call
 * that samples or commands the device, so a simulated driver is
 * reproducible bit for bit in lockstep.
 *
 * Real-time rules: read_state and write_output run on the servo thread at the
 * device rate; they must not block, allocate or throw. open/close/get_info may.
 * Units: metres, seconds, newtons, newton-metres, radians; quaternions w,x,y,z.
 *
 * @code
 *   static const DmHapticDeviceVTable kSim = {open, close, get_info, read_state, write_output, reconnect};
 *   host->register_factory(host->ctx, DM_HAPTIC_DEVICE_KIND, "sim-haptic",
 *                          DM_HAPTIC_DEVICE_KIND_ABI_VERSION, &kSim);
 * @endcode
 */
#ifndef DM_IO_DEVICE_ABI_H
#define DM_IO_DEVICE_ABI_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---- common to every device kind ---------------------------------------- */

/* Status codes of device calls. */
#define DM_DEVICE_OK 0
#define DM_DEVICE_ERROR_LOST 1         /* the device disconnected; reconnect may bring it back */
#define DM_DEVICE_ERROR_INVALID_ARGUMENT 2
#define DM_DEVICE_ERROR_IO 3           /* a read or write failed this time; the device is still there */
#define DM_DEVICE_ERROR_UNSUPPORTED 4

/* One configuration entry; both strings NUL-terminated, valid during open. */
typedef struct DmDeviceParam {
  const char* key;
  const char* value;
} DmDeviceParam;

/* Opaque driver instance. */
typedef struct DmDevice DmDevice;

/* Who a device is. Strings are NUL-terminated and truncated to fit. */
typedef struct DmDeviceIdentity {
  char driver[64]; /* factory name, e.g. "sim-haptic" */
  char vendor[64];
  char model[64];
  char serial[64];
} DmDeviceIdentity;

/* ---- haptic device ------------------------------------------------------- */

#define DM_HAPTIC_DEVICE_KIND "haptic-device"
#define DM_HAPTIC_DEVICE_KIND_ABI_VERSION 1u

/* Capability bits of DmHapticInfo::capabilities. */
#define DM_HAPTIC_CAP_POSITION 0x1u
#define DM_HAPTIC_CAP_ORIENTATION 0x2u
#define DM_HAPTIC_CAP_VELOCITY 0x4u
#define DM_HAPTIC_CAP_FORCE 0x8u
#define DM_HAPTIC_CAP_TORQUE 0x10u

/* What a haptic device can do. */
typedef struct DmHapticInfo {
  DmDeviceIdentity identity;
  uint32_t capabilities;    /* DM_HAPTIC_CAP_* bits */
  uint32_t button_count;    /* ≤ 32 */
  double workspace_min[3];  /* m, device frame */
  double workspace_max[3];
  double max_force;         /* N, continuous */
  double max_torque;        /* N·m; 0 without torque output */
  double max_stiffness;     /* N/m the device renders stably */
  double max_damping;       /* N·s/m */
  double servo_rate_hz;     /* rate at which read_state/write_output should run */
} DmHapticInfo;

/* One sample of the device, device frame. */
typedef struct DmHapticState {
  int64_t time_ns;             /* sample time on the host's loop clock */
  double position[3];          /* m */
  double orientation[4];       /* unit quaternion w, x, y, z */
  double linear_velocity[3];   /* m/s */
  double angular_velocity[3];  /* rad/s */
  uint32_t buttons;            /* bit i = button i pressed */
} DmHapticState;

typedef struct DmHapticDeviceVTable {
  /* Creates an instance from `params`. On failure returns NULL and writes a
   * message naming the offending key into error[error_size]. */
  DmDevice* (*open)(const DmDeviceParam* params, size_t param_count, char* error, size_t error_size);
  void (*close)(DmDevice* device);
  int (*get_info)(DmDevice* device, DmHapticInfo* info);
  /* Samples the device at host time now_ns. */
  int (*read_state)(DmDevice* device, int64_t now_ns, DmHapticState* state);
  /* Sends force (N) and torque (N·m) to the device at host time now_ns. The
   * host has already clamped them to the limits and removed NaN/Inf. */
  int (*write_output)(DmDevice* device, int64_t now_ns, const double force[3], const double torque[3]);
  /* Tries to reconnect a lost device; DM_DEVICE_OK when it is back. May be NULL. */
  int (*reconnect)(DmDevice* device, int64_t now_ns);
} DmHapticDeviceVTable;

#ifdef __cplusplus
}
#endif

#endif /* DM_IO_DEVICE_ABI_H */
