#!/usr/bin/env bash
# Sets up, builds and runs the main job: `dmplatform run` on the bundled
# default scene (examples/scenes/head_probe.json: the Colin27 MRI head probed
# through the god-object by a simulated haptic device, rendered headless).
#   scripts/run.sh [dmplatform run options...]   (outputs in out/head_probe/)
# e.g. scripts/run.sh --realtime --duration 60
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
# The Python package too (import dmplatform: docs/python.md), when pybind11 is there.
targets=(dmplatform)
help="$(cmake --build build --target help)"
[[ "$help" == *$'\n'dmplatform_core:* ]] && targets+=(dmplatform_core)
cmake --build build -j "$(nproc)" --target "${targets[@]}"
bash scripts/link_python.sh build
exec build/Editors/dmplatform run "$@"
