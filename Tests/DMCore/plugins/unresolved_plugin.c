/* References a function no library defines: dlopen(RTLD_NOW) must fail with
 * "undefined symbol" before any plugin code runs. */
#include <dm/core/plugin_abi.h>

extern int dm_test_function_that_does_not_exist(int x);

static int init(const DmHostApi* host) {
  (void)host;
  return dm_test_function_that_does_not_exist(1);
}

static const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "test-unresolved", "0.1", init, NULL};

DM_PLUGIN_ENTRY { return &kInfo; }
