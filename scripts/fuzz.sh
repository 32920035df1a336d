#!/usr/bin/env bash
# Builds every libFuzzer target with clang and runs each for a bounded time.
#   scripts/fuzz.sh [SECONDS_PER_TARGET]   (default 30)
#   scripts/fuzz.sh --budget SECONDS       every target runs, and the
#       fuzzing takes about SECONDS of wall time in all: each target gets
#       SECONDS x cores / targets (at least 5 s). CI uses this, so the stage
#       keeps its time as targets are added.
# Seeds: Tests/fuzz/corpus/<target>/ plus real files (scripts/fuzz_common.sh).
# The long run outside CI (≥ 10⁷ executions a target, coverage): scripts/fuzz-deep.sh.
# A crash leaves the input in build-fuzz/artifacts/ and fails the script.
set -euo pipefail
cd "$(dirname "$0")/.."
budget=""
seconds=30
if [ "${1:-}" = "--budget" ]; then
  budget="${2:?fuzz.sh: --budget needs a number of seconds}"
elif [ -n "${1:-}" ]; then
  seconds="$1"
fi
bash scripts/setup.sh
source scripts/fuzz_common.sh
builddir=build-fuzz
fuzz_configure "$builddir"
mapfile -t targets < <(fuzz_targets "$builddir")
if [ ${#targets[@]} -eq 0 ]; then echo "fuzz: no targets"; exit 0; fi
cmake --build "$builddir" -j "$(nproc)" --target "${targets[@]}"
if [ -n "$budget" ]; then
  seconds=$((budget * $(nproc) / ${#targets[@]}))
  [ "$seconds" -ge 5 ] || seconds=5
  echo "fuzz: ${#targets[@]} targets, ${seconds}s each, $(nproc) at a time (budget ${budget}s)"
fi
mkdir -p "$builddir/artifacts"

# Prepares the corpus of target $1 and fuzzes it for $seconds; its output
# goes to a log of its own, so targets can run side by side.
fuzz_one() {
  local t="$1" corpus="$builddir/corpus/$1"
  fuzz_prepare_corpus "$t" "$corpus"
  fuzz_run "$builddir" "$t" "$corpus" "$builddir/artifacts/$t.log" -max_total_time="$seconds"
}

fuzz_each "$builddir" fuzz_one "${targets[@]}"
failed=("${fuzz_failed[@]}")
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz: ${#failed[@]} of ${#targets[@]} targets failed: ${failed[*]}" >&2
  exit 1
fi
echo "fuzz: all ${#targets[@]} targets ran ${seconds}s each without a failure"
