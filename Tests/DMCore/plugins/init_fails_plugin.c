/* init registers one factory, then fails with a message: the host must
 * refuse the plugin, pass the message on, drop the staged factory, and not
 * call shutdown (a failed init cleans up after itself). */
#include <dm/core/plugin_abi.h>

#include "test_adder.h"

static int add(int a, int b) { return a - b; }
static const DmTestAdderVTable kVTable = {add, NULL, NULL, NULL};

static const DmHostApi* g_host = NULL;

static int init(const DmHostApi* host) {
  g_host = host;
  host->register_factory(host->ctx, DM_TEST_ADDER_KIND, "half-registered", DM_TEST_ADDER_KIND_ABI_VERSION,
                         &kVTable);
  host->set_error(host->ctx, "calibration file /etc/dm/test.cal not found; run dm-calibrate first");
  return 7;
}
static void shutdown(void) {
  if (g_host) g_host->log(g_host->ctx, DM_PLUGIN_LOG_INFO, "shutdown");
}

static const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "test-init-fails", "0.1", init, shutdown};

DM_PLUGIN_ENTRY { return &kInfo; }
