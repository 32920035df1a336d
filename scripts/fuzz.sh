#!/usr/bin/env bash
# Builds every libFuzzer target with clang and runs each for a bounded time.
#   scripts/fuzz.sh [SECONDS_PER_TARGET]   (default 30)
#   scripts/fuzz.sh --budget SECONDS       every target runs, and the
#       fuzzing takes about SECONDS of wall time in all: each target gets
#       SECONDS x cores / targets (at least 5 s). CI uses this, so the stage
#       keeps its time as targets are added.
# Seeds: Tests/fuzz/corpus/<target>/ plus real files named in seeds_for().
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
builddir=build-fuzz
CC=clang CXX=clang++ cmake -S . -B "$builddir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDM_FUZZ=ON \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" \
  -DDM_BUILD_TESTS=OFF -DDM_BUILD_BENCH=OFF -DDM_BUILD_EXAMPLES=OFF >/dev/null
mapfile -t targets < <(cmake --build "$builddir" --target help | sed -n 's/^\([a-z0-9_]*_fuzz\):.*/\1/p')
if [ ${#targets[@]} -eq 0 ]; then echo "fuzz: no targets"; exit 0; fi
cmake --build "$builddir" -j "$(nproc)" --target "${targets[@]}"
if [ -n "$budget" ]; then
  seconds=$((budget * $(nproc) / ${#targets[@]}))
  [ "$seconds" -ge 5 ] || seconds=5
  echo "fuzz: ${#targets[@]} targets, ${seconds}s each, $(nproc) at a time (budget ${budget}s)"
fi

seeds_for() {
  case "$1" in
    nifti_fuzz) ls /usr/share/mricron/templates/*.nii.gz 2>/dev/null | head -2 ;;
  esac
}
mkdir -p "$builddir/artifacts"

# Prepares the corpus of target $1 and fuzzes it for $seconds; its output
# goes to a log of its own, so targets can run side by side.
fuzz_one() {
  local t="$1" corpus="$builddir/corpus/$1" log="$builddir/artifacts/$1.log"
  mkdir -p "$corpus"
  [ -d "Tests/fuzz/corpus/$t" ] && cp -n Tests/fuzz/corpus/"$t"/* "$corpus"/ 2>/dev/null || true
  for f in $(seeds_for "$t"); do cp -n "$f" "$corpus"/ 2>/dev/null || true; done
  if [ "$t" = mesh_fuzz ]; then
    # mesh_fuzz reads a format byte first (0 stl, 1 ply, 2 obj, 3 off, ...).
    local m=/usr/share/assimp/models i=0 pair
    for pair in "0 $m/STL/Spider_ascii.stl" "1 $m/PLY/cube.ply" "2 $m/OBJ/box.obj" "3 $m/OFF/Cube.off"; do
      set -- $pair
      [ -f "$2" ] && { printf "\\$(printf '%03o' "$1")"; head -c 65536 "$2"; } > "$corpus/seed$i" || true
      i=$((i + 1))
    done
  fi
  # The parsers that fork an isolated child (Assimp, OpenVDB) give it its own
  # memory budget, enforced by allocator hooks under the sanitizers; those run
  # after libFuzzer's, so its per-malloc limit (by default the RSS limit)
  # must not end the child first. The RSS limit still guards our process.
  ASAN_OPTIONS=detect_leaks=1 "$builddir/Tests/fuzz/$t" -max_total_time="$seconds" -rss_limit_mb=4096 \
      -malloc_limit_mb=65536 \
      -max_len=1048576 -artifact_prefix="$builddir/artifacts/$t-" -print_final_stats=1 "$corpus" >"$log" 2>&1
}

# One target per core at a time; each keeps its full time budget.
slots=$(nproc)
failed=()
declare -A running=()
finish_one() {
  local pid
  wait -n -p pid "${!running[@]}" && rc=0 || rc=$?
  local t="${running[$pid]}"
  unset "running[$pid]"
  if [ "$rc" -ne 0 ]; then
    tail -40 "$builddir/artifacts/$t.log"
    echo "fuzz: $t failed; the input is in $builddir/artifacts/" >&2
    failed+=("$t")
  else
    echo "fuzz: $t ran ${seconds}s: $(grep -E "^(stat::number_of_executed_units|Done [0-9]+ runs)" "$builddir/artifacts/$t.log" | tail -1)"
  fi
}
for t in "${targets[@]}"; do
  [ ${#running[@]} -ge "$slots" ] && finish_one
  fuzz_one "$t" &
  running[$!]="$t"
done
while [ ${#running[@]} -gt 0 ]; do finish_one; done
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz: ${#failed[@]} of ${#targets[@]} targets failed: ${failed[*]}" >&2
  exit 1
fi
echo "fuzz: all ${#targets[@]} targets ran ${seconds}s each without a failure"
