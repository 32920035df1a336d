/* test_adder.h — the "test-adder" factory kind used by the plugin tests.
 *
 * A kind is owned by the module that consumes it; this one is owned by
 * Tests/DMCore/plugin_test.cpp. Its vtable is a C struct of function
 * pointers; instances are opaque handles created and destroyed by the plugin.
 */
#ifndef DM_TEST_ADDER_H
#define DM_TEST_ADDER_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define DM_TEST_ADDER_KIND "test-adder"
#define DM_TEST_ADDER_KIND_ABI_VERSION 3u

/* Opaque accumulator owned by the plugin. */
typedef struct DmTestAccumulator DmTestAccumulator;

typedef struct DmTestAdderVTable {
  /* Stateless sum of a and b as this factory defines it. */
  int (*add)(int a, int b);
  /* New accumulator starting at `start`; NULL on allocation failure. */
  DmTestAccumulator* (*create)(int start);
  /* Adds `x` to the accumulator with add() and returns the new total. */
  int (*accumulate)(DmTestAccumulator* acc, int x);
  /* Frees an accumulator from create(); NULL is ignored. */
  void (*destroy)(DmTestAccumulator* acc);
} DmTestAdderVTable;

#ifdef __cplusplus
}
#endif

#endif /* DM_TEST_ADDER_H */
