#!/usr/bin/env bash
# Builds every libFuzzer target with clang and runs each for a bounded time.
#   scripts/fuzz.sh [SECONDS_PER_TARGET]   (default 30)
# Seeds: Tests/fuzz/corpus/<target>/ plus real files named in seeds_for().
# A crash leaves the input in build-fuzz/artifacts/ and fails the script.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-30}"
bash scripts/setup.sh
builddir=build-fuzz
CC=clang CXX=clang++ cmake -S . -B "$builddir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDM_FUZZ=ON \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG" "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG" \
  -DDM_BUILD_TESTS=OFF -DDM_BUILD_BENCH=OFF -DDM_BUILD_EXAMPLES=OFF >/dev/null
mapfile -t targets < <(cmake --build "$builddir" --target help | sed -n 's/^\([a-z0-9_]*_fuzz\):.*/\1/p')
if [ ${#targets[@]} -eq 0 ]; then echo "fuzz: no targets"; exit 0; fi
cmake --build "$builddir" -j "$(nproc)" --target "${targets[@]}"

seeds_for() {
  case "$1" in
    nifti_fuzz) ls /usr/share/mricron/templates/*.nii.gz 2>/dev/null | head -2 ;;
  esac
}
mkdir -p "$builddir/artifacts"
for t in "${targets[@]}"; do
  corpus="$builddir/corpus/$t"
  mkdir -p "$corpus"
  [ -d "Tests/fuzz/corpus/$t" ] && cp -n Tests/fuzz/corpus/"$t"/* "$corpus"/ 2>/dev/null || true
  for f in $(seeds_for "$t"); do cp -n "$f" "$corpus"/ 2>/dev/null || true; done
  if [ "$t" = mesh_fuzz ]; then
    # mesh_fuzz reads a format byte first (0 stl, 1 ply, 2 obj, 3 off, ...).
    m=/usr/share/assimp/models
    i=0
    for pair in "0 $m/STL/Spider_ascii.stl" "1 $m/PLY/cube.ply" "2 $m/OBJ/box.obj" "3 $m/OFF/Cube.off"; do
      set -- $pair
      [ -f "$2" ] && { printf "\\$(printf '%03o' "$1")"; head -c 65536 "$2"; } > "$corpus/seed$i" || true
      i=$((i + 1))
    done
  fi
  echo "fuzz: $t for ${seconds}s"
  log="$builddir/artifacts/$t.log"
  # The parsers that fork an isolated child (Assimp, OpenVDB) give it its own
  # memory budget, enforced by allocator hooks under the sanitizers; those run
  # after libFuzzer's, so its per-malloc limit (by default the RSS limit)
  # must not end the child first. The RSS limit still guards our process.
  if ! ASAN_OPTIONS=detect_leaks=1 "$builddir/Tests/fuzz/$t" -max_total_time="$seconds" -rss_limit_mb=4096 \
      -malloc_limit_mb=65536 \
      -max_len=1048576 -artifact_prefix="$builddir/artifacts/$t-" -print_final_stats=1 "$corpus" >"$log" 2>&1; then
    tail -40 "$log"
    echo "fuzz: $t failed; the input is in $builddir/artifacts/" >&2
    exit 1
  fi
  grep -E "^(#[0-9]+ *DONE|stat::number_of_executed_units|Done [0-9]+ runs)" "$log" | tail -2
done
echo "fuzz: all ${#targets[@]} targets ran ${seconds}s each without a failure"
