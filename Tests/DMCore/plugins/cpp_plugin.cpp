// A plugin written in C++: C++ inside, only C across the boundary (the
// entry point is extern "C", the vtable is a C struct, no exceptions leak).
#include <dm/core/plugin_abi.h>

#include <new>

#include "test_adder.h"

struct DmTestAccumulator {
  int total = 0;
};

namespace {

int saturatingAdd(int a, int b) {
  const long long s = static_cast<long long>(a) + b;
  return s > 100 ? 100 : s < -100 ? -100 : static_cast<int>(s);
}

DmTestAccumulator* create(int start) { return new (std::nothrow) DmTestAccumulator{saturatingAdd(start, 0)}; }
int accumulate(DmTestAccumulator* acc, int x) { return acc->total = saturatingAdd(acc->total, x); }
void destroy(DmTestAccumulator* acc) { delete acc; }

const DmTestAdderVTable kSaturating = {saturatingAdd, create, accumulate, destroy};

int init(const DmHostApi* host) noexcept {
  return host->register_factory(host->ctx, DM_TEST_ADDER_KIND, "saturating-adder",
                                DM_TEST_ADDER_KIND_ABI_VERSION, &kSaturating);
}

const DmPluginInfo kInfo = {DM_PLUGIN_ABI_VERSION, "test-cpp", "0.9", init, nullptr};

}  // namespace

DM_PLUGIN_ENTRY { return &kInfo; }
