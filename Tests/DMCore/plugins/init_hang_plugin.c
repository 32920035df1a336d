/* init never returns. Only ever loaded in probe mode with a short timeout:
 * the host kills the probe process and refuses the plugin. */
#define _POSIX_C_SOURCE 200809L
#include <dm/core/plugin_abi.h>

#include <unistd.h>

static int init(const DmHostApi* host) {
  (void)host;
  for (;;) pause();
  return 0;
}

static const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "test-init-hang", "0.1", init, NULL};

DM_PLUGIN_ENTRY { return &kInfo; }
