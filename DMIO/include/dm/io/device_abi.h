/* dm/io/device_abi.h — the C boundary for device driver plugins.
 *
 * A driver is a factory (dm/core/plugin_abi.h) of a device kind; this header
 * defines what all kinds share (parameters, status codes, identity) and the
 * vtables of the kinds "haptic-device", "controller", "daq", "sensor" and
 * "serial". A driver instance is an opaque DmDevice
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

/* ---- controller (joysticks, pedals, 3-D mice) ---------------------------- */

#define DM_CONTROLLER_KIND "controller"
#define DM_CONTROLLER_KIND_ABI_VERSION 1u
#define DM_CONTROLLER_AXES 6          /* analog axes per state */
#define DM_CONTROLLER_MAX_BUTTONS 128 /* buttons per state */

/* Capability bits of DmControllerInfo::capabilities. */
#define DM_CONTROLLER_CAP_AXES 0x1u
#define DM_CONTROLLER_CAP_BUTTONS 0x2u
#define DM_CONTROLLER_CAP_RECONNECT 0x4u /* reconnect can bring a lost device back */

/* What a controller has. */
typedef struct DmControllerInfo {
  DmDeviceIdentity identity;
  uint32_t capabilities; /* DM_CONTROLLER_CAP_* bits */
  uint32_t axis_count;   /* axes that move, ≤ DM_CONTROLLER_AXES; the others stay 0 */
  uint32_t button_count; /* ≤ DM_CONTROLLER_MAX_BUTTONS */
  double poll_rate_hz;   /* rate at which read_state should run */
} DmControllerInfo;

/* One sample of a controller. */
typedef struct DmControllerState {
  int64_t time_ns;                    /* sample time on the host's loop clock */
  double axes[DM_CONTROLLER_AXES];    /* normalised to [-1, 1]; centre 0 */
  uint64_t buttons[2];                /* button i pressed: bit (i % 64) of buttons[i / 64] */
} DmControllerState;

typedef struct DmControllerVTable {
  /* As DmHapticDeviceVTable::open. */
  DmDevice* (*open)(const DmDeviceParam* params, size_t param_count, char* error, size_t error_size);
  void (*close)(DmDevice* device);
  int (*get_info)(DmDevice* device, DmControllerInfo* info);
  /* Samples the controller at host time now_ns; never blocks. */
  int (*read_state)(DmDevice* device, int64_t now_ns, DmControllerState* state);
  /* Tries to reconnect a lost controller; DM_DEVICE_OK when it is back. May be NULL. */
  int (*reconnect)(DmDevice* device, int64_t now_ns);
} DmControllerVTable;

/* ---- data acquisition (DAQ) ---------------------------------------------- */

#define DM_DAQ_KIND "daq"
#define DM_DAQ_KIND_ABI_VERSION 1u
#define DM_DAQ_MAX_CHANNELS 16

/* Capability bits of DmDaqInfo::capabilities. */
#define DM_DAQ_CAP_ANALOG_IN 0x1u
#define DM_DAQ_CAP_RECONNECT 0x2u

/* What a DAQ acquires: channel_count channels sampled together at
 * sample_rate_hz (one "frame" = one sample of every channel). */
typedef struct DmDaqInfo {
  DmDeviceIdentity identity;
  uint32_t capabilities;   /* DM_DAQ_CAP_* bits */
  uint32_t channel_count;  /* 1..DM_DAQ_MAX_CHANNELS */
  double sample_rate_hz;   /* frames per second */
  double range_min;        /* V, smallest value a sample takes */
  double range_max;        /* V */
  uint64_t fifo_frames;    /* frames the device buffers between reads */
} DmDaqInfo;

/* What one read_frames call returned. */
typedef struct DmDaqBlock {
  size_t frames;           /* frames written, ≤ max_frames */
  uint64_t first_index;    /* acquisition index of the first frame written */
  uint64_t overrun_frames; /* frames the device dropped (FIFO overflow) since the previous call */
} DmDaqBlock;

typedef struct DmDaqVTable {
  /* As DmHapticDeviceVTable::open. */
  DmDevice* (*open)(const DmDeviceParam* params, size_t param_count, char* error, size_t error_size);
  void (*close)(DmDevice* device);
  int (*get_info)(DmDevice* device, DmDaqInfo* info);
  /* Hands over up to max_frames of the frames acquired up to host time
   * now_ns, oldest first: samples[f * channel_count + c] (V) and times[f]
   * (ns, host loop clock). Frames left over stay queued for the next call.
   * Never blocks. */
  int (*read_frames)(DmDevice* device, int64_t now_ns, double* samples, int64_t* times, size_t max_frames,
                     DmDaqBlock* block);
  /* Tries to reconnect a lost DAQ; DM_DEVICE_OK when it is back. May be NULL. */
  int (*reconnect)(DmDevice* device, int64_t now_ns);
} DmDaqVTable;

/* ---- sensor (force sensors, trackers, IMUs, thermometers) ---------------- */

#define DM_SENSOR_KIND "sensor"
#define DM_SENSOR_KIND_ABI_VERSION 1u

/* DmSensorReading::type and DmSensorInfo::reading_type: what values[] holds. */
#define DM_SENSOR_SCALAR 0u     /* values[0] */
#define DM_SENSOR_VEC3 1u       /* values[0..2] */
#define DM_SENSOR_QUATERNION 2u /* values[0..3] = w, x, y, z (unit) */
#define DM_SENSOR_POSE 3u       /* values[0..2] = position (m), values[3..6] = w, x, y, z */

/* Capability bits of DmSensorInfo::capabilities. */
#define DM_SENSOR_CAP_RECONNECT 0x1u

/* What a sensor measures. */
typedef struct DmSensorInfo {
  DmDeviceIdentity identity;
  uint32_t capabilities; /* DM_SENSOR_CAP_* bits */
  uint32_t reading_type; /* DM_SENSOR_* */
  double rate_hz;        /* rate at which read should run */
  char unit[16];         /* SI unit of the values, e.g. "N", "m", "K" */
} DmSensorInfo;

/* One typed, timestamped reading. */
typedef struct DmSensorReading {
  int64_t time_ns; /* measurement time on the host's loop clock */
  uint32_t type;   /* DM_SENSOR_*; equals DmSensorInfo::reading_type */
  uint32_t reserved;
  double values[7];
} DmSensorReading;

typedef struct DmSensorVTable {
  /* As DmHapticDeviceVTable::open. */
  DmDevice* (*open)(const DmDeviceParam* params, size_t param_count, char* error, size_t error_size);
  void (*close)(DmDevice* device);
  int (*get_info)(DmDevice* device, DmSensorInfo* info);
  /* Samples the sensor at host time now_ns; never blocks. */
  int (*read)(DmDevice* device, int64_t now_ns, DmSensorReading* reading);
  /* Tries to reconnect a lost sensor; DM_DEVICE_OK when it is back. May be NULL. */
  int (*reconnect)(DmDevice* device, int64_t now_ns);
} DmSensorVTable;

/* ---- serial line ---------------------------------------------------------- */

#define DM_SERIAL_KIND "serial"
#define DM_SERIAL_KIND_ABI_VERSION 1u

#define DM_SERIAL_PARITY_NONE 0u
#define DM_SERIAL_PARITY_EVEN 1u
#define DM_SERIAL_PARITY_ODD 2u
#define DM_SERIAL_FLOW_NONE 0u
#define DM_SERIAL_FLOW_RTSCTS 1u
#define DM_SERIAL_FLOW_XONXOFF 2u

/* Line settings. */
typedef struct DmSerialConfig {
  uint32_t baud;         /* bits per second */
  uint32_t data_bits;    /* 5..8 */
  uint32_t parity;       /* DM_SERIAL_PARITY_* */
  uint32_t stop_bits;    /* 1 or 2 */
  uint32_t flow_control; /* DM_SERIAL_FLOW_* */
} DmSerialConfig;

/* Capability bits of DmSerialInfo::capabilities. */
#define DM_SERIAL_CAP_RECONNECT 0x1u /* reconnect can reopen a lost line */
#define DM_SERIAL_CAP_CONFIGURE 0x2u /* configure changes the settings of an open line */

/* What a serial line is. */
typedef struct DmSerialInfo {
  DmDeviceIdentity identity;
  uint32_t capabilities; /* DM_SERIAL_CAP_* bits */
  char path[256];        /* device path, e.g. "/dev/ttyUSB0" */
  DmSerialConfig config; /* settings in force */
} DmSerialInfo;

typedef struct DmSerialVTable {
  /* As DmHapticDeviceVTable::open; the parameters name the path and the
   * line settings. */
  DmDevice* (*open)(const DmDeviceParam* params, size_t param_count, char* error, size_t error_size);
  void (*close)(DmDevice* device);
  int (*get_info)(DmDevice* device, DmSerialInfo* info);
  /* Applies new line settings; DM_DEVICE_ERROR_INVALID_ARGUMENT with a
   * message naming the setting when one is not supported. */
  int (*configure)(DmDevice* device, const DmSerialConfig* config, char* error, size_t error_size);
  /* Reads what is available, at most size bytes, waiting at most timeout_ms
   * (0: do not wait) for the first byte; *transferred = 0 after a timeout. */
  int (*read)(DmDevice* device, void* data, size_t size, int timeout_ms, size_t* transferred);
  /* Writes up to size bytes, waiting at most timeout_ms in all for room;
   * *transferred < size after a timeout. */
  int (*write)(DmDevice* device, const void* data, size_t size, int timeout_ms, size_t* transferred);
  /* Tries to reopen a lost line with the same settings; DM_DEVICE_OK when it is back. May be NULL. */
  int (*reconnect)(DmDevice* device);
} DmSerialVTable;

#ifdef __cplusplus
}
#endif

#endif /* DM_IO_DEVICE_ABI_H */
