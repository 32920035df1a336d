#!/usr/bin/env bash
# Deep fuzzing, outside CI (issue 37): every libFuzzer target runs until it
# has executed RUNS inputs (default 10,000,000) or for SECONDS (default
# 3600), one target per core; the inputs that reached new code are merged
# into the committed corpus (Tests/fuzz/corpus/<target>/: libFuzzer's
# -merge=1 adds only those, so it stays small and regression inputs stay);
# then a coverage build runs each target over its corpus once and reports
# the line coverage of the parser it fuzzes, with the lines no input
# reaches. The table goes to build-fuzz/deep/report.md (docs/security.md
# keeps the last one).
#   scripts/fuzz-deep.sh [--runs N] [--seconds S] [--no-merge] [--report-only] [TARGET...]
# (--report-only: the coverage and the table again from the last run's logs
# and corpora, without fuzzing.)
# A crash leaves the input in build-fuzz/artifacts/ and fails the script
# (after the other targets ran): fix it and add the input to the corpus.
# Coverage misses what a forked import child runs (Assimp, OpenVDB: the
# child ends with _exit, which writes no profile).
set -euo pipefail
cd "$(dirname "$0")/.."
runs=10000000
seconds=3600
merge=1
fuzz=1
only=()
while [ $# -gt 0 ]; do
  case "$1" in
    --runs) runs="$2"; shift 2 ;;
    --seconds) seconds="$2"; shift 2 ;;
    --no-merge) merge=0; shift ;;
    --report-only) fuzz=0; merge=0; shift ;;
    -*) echo "fuzz-deep: unknown option $1" >&2; exit 2 ;;
    *) only+=("$1"); shift ;;
  esac
done
source scripts/fuzz_common.sh
builddir=build-fuzz
covdir=build-fuzz-cov
deep="$builddir/deep"
mkdir -p "$deep" "$builddir/artifacts"

fuzz_configure "$builddir"
if [ ${#only[@]} -gt 0 ]; then targets=("${only[@]}"); else mapfile -t targets < <(fuzz_targets "$builddir"); fi
cmake --build "$builddir" -j "$(nproc)" --target "${targets[@]}"

# The sources each target's parser lives in (coverage is reported on these).
sources_of() {
  case "$1" in
    device_path_fuzz) echo DMIO/src/device_path.cpp ;;
    dicom_fuzz) echo DMIO/src/dicom.cpp ;;
    haply_answer_fuzz) echo DMIO/drivers/haply_protocol.hpp ;;
    isolate_result_fuzz) echo "DMIO/src/isolate.cpp" ;;
    mesh_fuzz) echo "DMIO/src/mesh_guards.cpp DMIO/src/mesh_io.cpp" ;;
    metaimage_fuzz) echo DMIO/src/metaimage.cpp ;;
    net_auth_fuzz) echo DMNetwork/src/auth.cpp ;;
    net_igtl_fuzz) echo "DMNetwork/src/igtl.cpp DMNetwork/src/igtl_image.cpp DMNetwork/src/igtl_polydata.cpp" ;;
    net_igtl_stream_fuzz) echo DMNetwork/src/igtl_session.cpp ;;
    net_message_fuzz) echo DMNetwork/src/message.cpp ;;
    net_slip_fuzz) echo DMNetwork/src/slip.cpp ;;
    net_teleop_fuzz) echo DMNetwork/src/teleop.cpp ;;
    nifti_fuzz) echo DMIO/src/nifti.cpp ;;
    nrrd_fuzz) echo DMIO/src/nrrd.cpp ;;
    png_fuzz) echo DMIO/src/image_io.cpp ;;
    proc_stat_fuzz) echo DMCore/src/host_cpu.cpp ;;
    recording_fuzz) echo DMIO/src/recorder.cpp ;;
    scene_file_fuzz) echo "DMIO/src/scene_file.cpp DMIO/src/scene_parse.hpp" ;;
    scene_replay_fuzz) echo DMIO/src/scene_replay.cpp ;;
    sim_haptic_csv_fuzz) echo DMIO/drivers/sim_haptic.cpp ;;
    vdb_fuzz) echo DMIO/src/vdb.cpp ;;
    vision_graph_fuzz) echo DMVision/src/filter_graph.cpp ;;
    vision_letter_fuzz) echo DMVision/src/classify.cpp ;;
    volume_files_fuzz) echo "DMIO/src/metaimage.cpp DMIO/src/nrrd.cpp DMIO/src/nifti.cpp DMCore/src/filesystem.cpp" ;;
  esac
}

deep_one() {
  local t="$1" corpus="$builddir/corpus/$1"
  fuzz_prepare_corpus "$t" "$corpus"
  fuzz_run "$builddir" "$t" "$corpus" "$builddir/artifacts/$t.log" -runs="$runs" -max_total_time="$seconds"
}
fuzz_failed=()
if [ "$fuzz" = 1 ]; then
  echo "fuzz-deep: ${#targets[@]} targets, each to $runs executions or ${seconds}s, $(nproc) at a time"
  fuzz_each "$builddir" deep_one "${targets[@]}"
fi

# New coverage into the committed corpora.
if [ "$merge" = 1 ]; then
  for t in "${targets[@]}"; do
    mkdir -p "Tests/fuzz/corpus/$t"
    "$builddir/Tests/fuzz/$t" -merge=1 -rss_limit_mb=4096 -malloc_limit_mb=65536 -max_len=1048576 \
        "Tests/fuzz/corpus/$t" "$builddir/corpus/$t" >"$deep/$t.merge.log" 2>&1 ||
      echo "fuzz-deep: merging $t's corpus failed (see $deep/$t.merge.log)" >&2
  done
fi

# Coverage: the same targets built with clang's source-based coverage, each
# run once over its corpus.
fuzz_configure "$covdir" "-DCMAKE_C_FLAGS=-fprofile-instr-generate -fcoverage-mapping" \
  "-DCMAKE_CXX_FLAGS=-fprofile-instr-generate -fcoverage-mapping" \
  "-DCMAKE_EXE_LINKER_FLAGS=-fprofile-instr-generate" "-DCMAKE_SHARED_LINKER_FLAGS=-fprofile-instr-generate"
cmake --build "$covdir" -j "$(nproc)" --target "${targets[@]}"
mapfile -t libs < <(find "$covdir" -name 'libdm*.so' -o -name 'libDM*.so' | sort)
objects=()
for l in "${libs[@]}"; do objects+=(-object "$l"); done
# The coverage build records sources as build-fuzz-cov/../<path>; the
# sources are named here by their absolute paths.
cov() { llvm-cov "$1" "$covdir/Tests/fuzz/$t" "${objects[@]}" -instr-profile="$deep/$t.profdata" \
          "-path-equivalence=$covdir/..,$PWD" "${@:2}"; }

report="$deep/report.md"
{
  echo "| target | executions | crashes | lines covered (parser) | lines no input reaches |"
  echo "|---|---|---|---|---|"
} >"$report"
for t in "${targets[@]}"; do
  log="$builddir/artifacts/$t.log"
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  crashes=0
  if printf '%s\n' "${fuzz_failed[@]}" | grep -qx "$t"; then crashes=1; fi
  rm -f "$deep/$t".*.profraw
  LLVM_PROFILE_FILE="$deep/$t.%p.profraw" ASAN_OPTIONS=detect_leaks=0 "$covdir/Tests/fuzz/$t" -runs=0 \
      -rss_limit_mb=4096 -malloc_limit_mb=65536 -max_len=1048576 "Tests/fuzz/corpus/$t" "$builddir/corpus/$t" \
      >"$deep/$t.cov.log" 2>&1 || true
  llvm-profdata merge -sparse "$deep/$t".*.profraw -o "$deep/$t.profdata"
  srcs=()
  for f in $(sources_of "$t"); do srcs+=("$PWD/$f"); done
  covered="-"
  unreached="-"
  if [ ${#srcs[@]} -gt 0 ]; then
    # The sources' line coverage, from the export's totals.
    covered=$(cov export -summary-only "${srcs[@]}" |
              /usr/bin/python3 -c 'import json,sys; l=json.load(sys.stdin)["data"][0]["totals"]["lines"]; print("%.1f %% (%d of %d)" % (l["percent"], l["covered"], l["count"]))')
    # The lines with a zero count, as ranges, per file (llvm-cov names each
    # file of several on a line of its own, "DMIO/src/x.cpp:").
    cov show "${srcs[@]}" >"$deep/$t.show.txt" 2>/dev/null || true
    unreached=$(awk -F'|' -v file="$(basename "${srcs[0]}")" '
        /^[^ |].*:$/ { file = $0; sub(/:$/, "", file); n = split(file, parts, "/"); file = parts[n]; next }
        NF >= 3 { count = $2; gsub(/ /, "", count); line = $1; gsub(/ /, "", line)
                  if (count == "0") { if (start == "" || line != last + 1 || file != lastfile) { if (start != "") { out = out sep lastfile ":" start (last > start ? "-" last : ""); sep = ", " } start = line } last = line; lastfile = file } }
        END { if (start != "") out = out sep lastfile ":" start (last > start ? "-" last : ""); print out }' \
        "$deep/$t.show.txt")
    [ -n "$unreached" ] || unreached="none"
    echo "$unreached" >"$deep/$t.unreached.txt"
    [ ${#unreached} -le 200 ] || unreached="${unreached:0:200}… ($deep/$t.unreached.txt)"
  fi
  echo "| \`$t\` | ${execs:-?} | $crashes | $covered | $unreached |" >>"$report"
done
cat "$report"
if [ ${#fuzz_failed[@]} -gt 0 ]; then
  echo "fuzz-deep: ${#fuzz_failed[@]} of ${#targets[@]} targets failed: ${fuzz_failed[*]}" >&2
  exit 1
fi
