#!/usr/bin/env bash
# Sets up, builds and runs the main job: the head probe demo on the Colin27
# MRI head (until the master engine's `dmplatform run` exists).
#   scripts/run.sh [head_probe options...]   (outputs in out/head_probe/)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build build -j "$(nproc)" --target head_probe
exec build/examples/head_probe "$@"
