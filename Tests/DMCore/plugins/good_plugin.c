/* A well-behaved plugin: two "test-adder" factories, "adder" (a + b) and
 * "offset-adder" (a + b + 1000), with opaque accumulators. Also exports
 * dm_test_good_live_accumulators() so the test can check create/destroy. */
#include <dm/core/plugin_abi.h>

#include <stdlib.h>

#include "test_adder.h"

struct DmTestAccumulator {
  int total;
  int (*add)(int, int);
};

static int g_live = 0;
static const DmHostApi* g_host = NULL;

static int plainAdd(int a, int b) { return a + b; }
static int offsetAdd(int a, int b) { return a + b + 1000; }

static DmTestAccumulator* makeAccumulator(int start, int (*add)(int, int)) {
  DmTestAccumulator* acc = (DmTestAccumulator*)malloc(sizeof(DmTestAccumulator));
  if (!acc) return NULL;
  acc->total = start;
  acc->add = add;
  ++g_live;
  return acc;
}
static DmTestAccumulator* createPlain(int start) { return makeAccumulator(start, plainAdd); }
static DmTestAccumulator* createOffset(int start) { return makeAccumulator(start, offsetAdd); }
static int accumulate(DmTestAccumulator* acc, int x) {
  acc->total = acc->add(acc->total, x);
  return acc->total;
}
static void destroy(DmTestAccumulator* acc) {
  if (!acc) return;
  --g_live;
  free(acc);
}

static const DmTestAdderVTable kPlain = {plainAdd, createPlain, accumulate, destroy};
static const DmTestAdderVTable kOffset = {offsetAdd, createOffset, accumulate, destroy};

static int init(const DmHostApi* host) {
  int rc;
  if (host->abi_version != DM_PLUGIN_ABI_VERSION) return DM_PLUGIN_ERROR_INIT_FAILED;
  g_host = host;
  rc =
      host->register_factory(host->ctx, DM_TEST_ADDER_KIND, "adder", DM_TEST_ADDER_KIND_ABI_VERSION, &kPlain);
  if (rc != DM_PLUGIN_OK) return rc;
  rc = host->register_factory(host->ctx, DM_TEST_ADDER_KIND, "offset-adder", DM_TEST_ADDER_KIND_ABI_VERSION,
                              &kOffset);
  if (rc != DM_PLUGIN_OK) return rc;
  host->log(host->ctx, DM_PLUGIN_LOG_INFO, "init done");
  return DM_PLUGIN_OK;
}

static void shutdown(void) {
  if (g_host) g_host->log(g_host->ctx, DM_PLUGIN_LOG_INFO, "shutdown");
  g_host = NULL;
}

static const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "test-good", "1.2.3", init, shutdown};

DM_PLUGIN_ENTRY { return &kInfo; }

DM_PLUGIN_EXPORT int dm_test_good_live_accumulators(void) { return g_live; }
