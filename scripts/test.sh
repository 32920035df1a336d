#!/usr/bin/env bash
# Sets up, builds and runs DMPlatform's tests. The README's test command.
#   scripts/test.sh                              full suite, RelWithDebInfo, build/
#   scripts/test.sh --sanitize address,undefined full suite under ASan+UBSan, build-asan/
#   scripts/test.sh --sanitize thread --label concurrency   concurrency tests under TSan
# With CI=true in the environment, warnings are errors.
set -euo pipefail
cd "$(dirname "$0")/.."

sanitize=""
label=""
while [ $# -gt 0 ]; do
  case "$1" in
    --sanitize) sanitize="$2"; shift 2 ;;
    --label) label="$2"; shift 2 ;;
    *) echo "test.sh: unknown option $1" >&2; exit 2 ;;
  esac
done

bash scripts/setup.sh

builddir=build
args=(-DCMAKE_BUILD_TYPE=RelWithDebInfo)
targets=()
if [ -n "$sanitize" ]; then
  builddir="build-$(echo "$sanitize" | tr ',' '-')"
  # Benchmarks, examples and the install test add nothing under a sanitizer.
  # Line tables (-g1) are all a sanitizer report needs and compile much
  # faster than full debug info. -O1, as the sanitizers' own docs advise:
  # with UBSan's checks GCC 12 takes up to twice as long at -O2 (measured on
  # DMMath's isosurface.cpp: 125 s at -O2, 63 s at -O1), for no extra finding.
  args+=(-DDM_SANITIZE="$sanitize" -DDM_BUILD_BENCH=OFF -DDM_BUILD_EXAMPLES=OFF
         "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG")
fi
if [ "${CI:-}" = "true" ]; then
  args+=(-DDM_WERROR=ON)
fi
jobs=$(nproc)

cmake -S . -B "$builddir" -G Ninja "${args[@]}" >/dev/null
if [ "$label" = "concurrency" ]; then
  mapfile -t targets < <(cmake --build "$builddir" --target help | sed -n 's/^\([A-Za-z]*_concurrency_tests\):.*/\1/p')
  cmake --build "$builddir" -j "$jobs" --target "${targets[@]}"
else
  cmake --build "$builddir" -j "$jobs"
fi
if [ -z "$sanitize" ]; then
  bash scripts/link_python.sh "$builddir"  # /usr/bin/python3 imports dmplatform (docs/python.md)
fi

ctest_args=(--test-dir "$builddir" --output-on-failure -j "$jobs" --timeout 600)
[ -n "$label" ] && ctest_args+=(-L "$label")
if [ -n "$sanitize" ]; then
  # intercept_tls_get_addr=0: GCC 12's runtime mistakes some dynamic TLS
  # blocks (Mesa's driver, dlopen'd) for pre-2.25 glibc ones, and the leak
  # checker's tracer then dies at exit ("Tracer caught signal 11").
  export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:strict_string_checks=1:intercept_tls_get_addr=0
  export LSAN_OPTIONS="suppressions=$PWD/scripts/lsan.supp"
  export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
  export TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1
fi
ctest "${ctest_args[@]}"
