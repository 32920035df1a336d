/* A shared library that is not a DMPlatform plugin: no dm_plugin_entry. */
#include <dm/core/plugin_abi.h>

DM_PLUGIN_EXPORT int dm_test_not_an_entry(void) { return 42; }
