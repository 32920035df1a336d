/* A haptic driver whose init crashes (as a buggy vendor SDK might): a probing
 * linker must refuse it without going down. */
#include <dm/core/plugin_abi.h>
#include <dm/io/device_abi.h>

#include <stdlib.h>

static int init(const DmHostApi* host) {
  (void)host;
  abort();
}
static const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "crashing-haptic", "1.0", init, NULL};
DM_PLUGIN_ENTRY { return &kInfo; }
