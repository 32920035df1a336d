#!/usr/bin/env bash
# Regenerates the golden reference images of the render tests ON PURPOSE:
# runs DMRenderer_tests with DM_UPDATE_GOLDEN=1, which rewrites every
# Tests/DMRenderer/golden/*.png the tests compare against. Look at the changed
# images (git diff --stat; an image viewer) before committing them.
# Usage: scripts/update_golden.sh [BUILD_DIR] [GTEST_FILTER]
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
filter=${2:-*}
if [ ! -x "$build/Tests/DMRenderer_tests" ]; then
  echo "update_golden: $build/Tests/DMRenderer_tests not built; run: cmake --build $build --target DMRenderer_tests" >&2
  exit 1
fi
DM_UPDATE_GOLDEN=1 DM_SOURCE_DIR="$PWD" "$build/Tests/DMRenderer_tests" --gtest_filter="$filter"
git status --short Tests/DMRenderer/golden
