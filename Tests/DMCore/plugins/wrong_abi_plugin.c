/* Built against a future plugin ABI: the host must refuse it after reading
 * abi_version, before calling anything in the table (init would register a
 * factory, which the test checks never appears). */
#include <dm/core/plugin_abi.h>

#include "test_adder.h"

static int add(int a, int b) { return a * b; }
static const DmTestAdderVTable kVTable = {add, NULL, NULL, NULL};

static int init(const DmHostApi* host) {
  return host->register_factory(host->ctx, DM_TEST_ADDER_KIND, "from-wrong-abi",
                                DM_TEST_ADDER_KIND_ABI_VERSION, &kVTable);
}

static const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION + 41u, "test-wrong-abi", "2.0", init, NULL};

DM_PLUGIN_ENTRY { return &kInfo; }
