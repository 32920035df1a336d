/* dm/core/plugin_abi.h — the C boundary between DMPlatform and its plugins.
 *
 * A plugin is a shared library (device driver, importer, collider, ...) with
 * exactly one exported C entry point, `dm_plugin_entry`, that returns a
 * pointer to a static, versioned table (DmPluginInfo). The host (DMCore's
 * dm::PluginLinker) reads `abi_version` BEFORE anything else and refuses the
 * plugin if it differs from DM_PLUGIN_ABI_VERSION. It then calls `init` with
 * a host API (DmHostApi): a C struct of function pointers through which the
 * plugin registers factories and logs. `shutdown` is called before unload.
 *
 * Only plain C types, opaque handles and status codes cross this boundary:
 * no C++ types, no exceptions, no ownership transfer of host memory. Strings
 * passed to the host are copied before the call returns; vtables passed to
 * register_factory must stay valid until `shutdown` returns (use statics).
 *
 * A factory is identified by (kind, name). `kind` names an extension point
 * owned by a module ("haptic-device", "importer", "collider", ...); that
 * module defines the kind's vtable (a C struct of function pointers) and its
 * own kind ABI version, which the plugin passes along with the vtable.
 *
 * This header is pure C (C99) so plugins can be written in C or any language
 * with a C FFI; it is also valid C++.
 *
 * @code
 *   static int myInit(const DmHostApi* host) {
 *     return host->register_factory(host->ctx, "test-adder", "adder", 1u, &kAdderVTable);
 *   }
 *   static const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "my-plugin", "1.0.0", myInit, NULL};
 *   DM_PLUGIN_ENTRY { return &kInfo; }
 * @endcode
 */
#ifndef DM_CORE_PLUGIN_ABI_H
#define DM_CORE_PLUGIN_ABI_H

#include <stddef.h> /* NULL, for plugin tables */
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Version of the DmPluginInfo / DmHostApi layout. Bumped on any change to
 * either struct or to the meaning of a status code. A plugin built against a
 * different version is refused; rebuild it against the installed SDK. */
#define DM_PLUGIN_ABI_VERSION 1u

/* Name of the one symbol every plugin exports. */
#define DM_PLUGIN_ENTRY_SYMBOL "dm_plugin_entry"

/* Status codes returned by host API functions (and usable by plugins as
 * their own init error codes; any nonzero value means failure). */
#define DM_PLUGIN_OK 0
#define DM_PLUGIN_ERROR_INVALID_ARGUMENT 1 /* null/empty string, null vtable */
#define DM_PLUGIN_ERROR_DUPLICATE 2        /* (kind, name) already registered */
#define DM_PLUGIN_ERROR_WRONG_STATE 3      /* e.g. register_factory after init */
#define DM_PLUGIN_ERROR_OUT_OF_MEMORY 4
#define DM_PLUGIN_ERROR_INTERNAL 5    /* a host bug; please report */
#define DM_PLUGIN_ERROR_INIT_FAILED 6 /* generic init failure for plugins */

/* Log levels accepted by DmHostApi::log. */
#define DM_PLUGIN_LOG_TRACE 0
#define DM_PLUGIN_LOG_DEBUG 1
#define DM_PLUGIN_LOG_INFO 2
#define DM_PLUGIN_LOG_WARN 3
#define DM_PLUGIN_LOG_ERROR 4

/* Opaque host state for one loaded plugin; pass it back unchanged. */
typedef struct DmHostContext DmHostContext;

/* Functions the host offers to a plugin. Valid from the start of `init` until
 * `shutdown` returns. All functions are safe to call from the thread running
 * init; `log` is safe from any thread. */
typedef struct DmHostApi {
  /* Equals DM_PLUGIN_ABI_VERSION of the host; always the first member. */
  uint32_t abi_version;
  /* Opaque context to pass as the first argument of every call below. */
  DmHostContext* ctx;
  /* Registers a factory of `kind` named `name` whose kind-specific vtable
   * (layout version `kind_abi_version`) is `vtable`. Only valid during init.
   * Returns DM_PLUGIN_OK, DM_PLUGIN_ERROR_DUPLICATE (the (kind, name) pair
   * is taken; the load will be refused), DM_PLUGIN_ERROR_INVALID_ARGUMENT,
   * DM_PLUGIN_ERROR_WRONG_STATE or DM_PLUGIN_ERROR_OUT_OF_MEMORY. */
  int (*register_factory)(DmHostContext* ctx, const char* kind, const char* name, uint32_t kind_abi_version,
                          const void* vtable);
  /* Writes one message (NUL-terminated, copied) to the host log. */
  void (*log)(DmHostContext* ctx, int level, const char* message);
  /* Sets the message reported to the user when init returns nonzero, e.g.
   * "device /dev/ttyUSB0 not found; plug it in". The last call wins. */
  void (*set_error)(DmHostContext* ctx, const char* message);
} DmHostApi;

/* The table a plugin's entry point returns; must stay valid until unload. */
typedef struct DmPluginInfo {
  /* Must be DM_PLUGIN_ABI_VERSION; always the first member. */
  uint32_t abi_version;
  /* Unique plugin name, e.g. "sim-haptic"; non-empty. */
  const char* name;
  /* Free-form version string, e.g. "1.2.0"; may be NULL. */
  const char* version;
  /* Registers factories; returns 0 on success, nonzero on failure (after
   * host->set_error). Never NULL. Must not throw or longjmp out. */
  int (*init)(const DmHostApi* host);
  /* Releases what init acquired; called once before unload. May be NULL. */
  void (*shutdown)(void);
} DmPluginInfo;

/* Type of the entry point. */
typedef const DmPluginInfo* (*DmPluginEntryFn)(void);

#if defined(_WIN32)
#define DM_PLUGIN_EXPORT __declspec(dllexport)
#elif defined(__GNUC__) || defined(__clang__)
#define DM_PLUGIN_EXPORT __attribute__((visibility("default")))
#else
#define DM_PLUGIN_EXPORT
#endif

#ifdef __cplusplus
#define DM_PLUGIN_EXTERN_C extern "C"
#else
#define DM_PLUGIN_EXTERN_C
#endif

/* Declares/defines the entry point: `DM_PLUGIN_ENTRY { return &kInfo; }`. */
#define DM_PLUGIN_ENTRY DM_PLUGIN_EXTERN_C DM_PLUGIN_EXPORT const DmPluginInfo* dm_plugin_entry(void)

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* DM_CORE_PLUGIN_ABI_H */
