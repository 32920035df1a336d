/* Registers "test-adder"/"subtractor" and then "test-adder"/"adder", which
 * test-good also provides: loaded after test-good it must be refused as a
 * whole ("subtractor" must not stay registered) and, since its init
 * succeeded, shut down. Alone it loads. */
#include <dm/core/plugin_abi.h>

#include "test_adder.h"

static int sub(int a, int b) { return a - b; }
static const DmTestAdderVTable kSub = {sub, NULL, NULL, NULL};

static const DmHostApi* g_host = NULL;

static int init(const DmHostApi* host) {
  g_host = host;
  /* Ignores the status codes on purpose: the host refuses the load anyway. */
  host->register_factory(host->ctx, DM_TEST_ADDER_KIND, "subtractor", DM_TEST_ADDER_KIND_ABI_VERSION, &kSub);
  host->register_factory(host->ctx, DM_TEST_ADDER_KIND, "adder", DM_TEST_ADDER_KIND_ABI_VERSION, &kSub);
  return DM_PLUGIN_OK;
}
static void shutdown(void) {
  if (g_host) g_host->log(g_host->ctx, DM_PLUGIN_LOG_INFO, "shutdown");
  g_host = NULL;
}

static const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "test-duplicate", "0.1", init, shutdown};

DM_PLUGIN_ENTRY { return &kInfo; }
