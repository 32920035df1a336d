/* init crashes with SIGSEGV. Only ever loaded in probe mode: the forked
 * probe process dies, the host refuses the plugin and survives. */
#include <dm/core/plugin_abi.h>

#include <signal.h>

static int init(const DmHostApi* host) {
  (void)host;
  raise(SIGSEGV);
  return 0;
}

static const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "test-init-crash", "0.1", init, NULL};

DM_PLUGIN_ENTRY { return &kInfo; }
