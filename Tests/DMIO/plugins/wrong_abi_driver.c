/* A haptic driver built against a future plugin ABI: must be refused. */
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

static int init(const DmHostApi* host) {
  (void)host;
  return 0;
}
static const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION + 7u, "future-haptic", "9.0", init, NULL};
DM_PLUGIN_ENTRY { return &kInfo; }
