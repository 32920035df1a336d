# Shared by scripts/fuzz.sh (CI's bounded run) and scripts/fuzz-deep.sh
# (the long run outside CI): the clang fuzz tree and each target's corpus.
# Source it from the repository root.

# fuzz_configure BUILDDIR [CMAKE ARGS...]: configures a tree of libFuzzer
# targets (clang, ASan+UBSan+fuzzer coverage in every library of ours).
fuzz_configure() {
  local dir="$1"
  shift
  CC=clang CXX=clang++ cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDM_FUZZ=ON \
    "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" \
    -DDM_BUILD_TESTS=OFF -DDM_BUILD_BENCH=OFF -DDM_BUILD_EXAMPLES=OFF "$@" >/dev/null
}

# fuzz_targets BUILDDIR: the targets' names, one a line.
fuzz_targets() {
  cmake --build "$1" --target help | sed -n 's/^\([a-z0-9_]*_fuzz\):.*/\1/p'
}

# Real files that seed a target besides its committed corpus.
fuzz_seeds_for() {
  case "$1" in
    nifti_fuzz) ls /usr/share/mricron/templates/*.nii.gz 2>/dev/null | head -2 ;;
  esac
}

# fuzz_prepare_corpus TARGET DIR: DIR gets the committed corpus of TARGET
# and its seeds (files already there are kept).
fuzz_prepare_corpus() {
  local t="$1" corpus="$2"
  mkdir -p "$corpus"
  [ -d "Tests/fuzz/corpus/$t" ] && cp -n Tests/fuzz/corpus/"$t"/* "$corpus"/ 2>/dev/null || true
  for f in $(fuzz_seeds_for "$t"); do cp -n "$f" "$corpus"/ 2>/dev/null || true; done
  if [ "$t" = mesh_fuzz ]; then
    # mesh_fuzz reads a format byte first (0 stl, 1 ply, 2 obj, 3 off, ...).
    local m=/usr/share/assimp/models i=0 pair
    for pair in "0 $m/STL/Spider_ascii.stl" "1 $m/PLY/cube.ply" "2 $m/OBJ/box.obj" "3 $m/OFF/Cube.off"; do
      set -- $pair
      [ -f "$2" ] && { printf "\\$(printf '%03o' "$1")"; head -c 65536 "$2"; } > "$corpus/seed$i" || true
      i=$((i + 1))
    done
  fi
}

# fuzz_run BUILDDIR TARGET CORPUS LOG [LIBFUZZER FLAGS...]: one fuzzing run.
# The parsers that fork an isolated child (Assimp, OpenVDB) give it its own
# memory budget, enforced by allocator hooks under the sanitizers; those run
# after libFuzzer's, so its per-malloc limit (by default the RSS limit) must
# not end the child first. The RSS limit still guards our process.
fuzz_run() {
  local dir="$1" t="$2" corpus="$3" log="$4"
  shift 4
  ASAN_OPTIONS=detect_leaks=1 "$dir/Tests/fuzz/$t" -rss_limit_mb=4096 -malloc_limit_mb=65536 \
      -max_len=1048576 -artifact_prefix="$dir/artifacts/$t-" -print_final_stats=1 "$@" "$corpus" >"$log" 2>&1
}

# fuzz_each BUILDDIR FUNC TARGET...: runs `FUNC TARGET` for each target in
# the background, one per core at a time (each keeps its whole time). A
# target whose FUNC fails has its log's tail shown and lands in the array
# fuzz_failed; one that passes prints its executions.
fuzz_each() {
  local dir="$1" func="$2"
  shift 2
  local slots pid t ended rc
  slots=$(nproc)
  fuzz_failed=()
  declare -A running=()
  _fuzz_finish_one() {  # `ended`, not `t`: the caller's loop is still using t
    wait -n -p pid "${!running[@]}" && rc=0 || rc=$?
    ended="${running[$pid]}"
    unset "running[$pid]"
    if [ "$rc" -ne 0 ]; then
      tail -40 "$dir/artifacts/$ended.log"
      echo "fuzz: $ended failed; the input is in $dir/artifacts/" >&2
      fuzz_failed+=("$ended")
    else
      echo "fuzz: $ended: $(grep -E "^(stat::number_of_executed_units|Done [0-9]+ runs)" "$dir/artifacts/$ended.log" | tail -1)"
    fi
  }
  for t in "$@"; do
    [ ${#running[@]} -ge "$slots" ] && _fuzz_finish_one
    "$func" "$t" &
    running[$!]="$t"
  done
  while [ ${#running[@]} -gt 0 ]; do _fuzz_finish_one; done
}
