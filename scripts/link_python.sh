#!/usr/bin/env bash
# Makes Debian's /usr/bin/python3 import the dmplatform package built in
# BUILD_DIR/Python (default build/): a dmplatform.pth naming that folder in
# the interpreter's first site-packages folder (/usr/local/lib/python3.X/
# dist-packages) — a development install: rebuilding updates it. Quiet when
# the package was not built; says what to do when the folder is not
# writable. Called by scripts/run.sh and scripts/test.sh after building.
#   scripts/link_python.sh [BUILD_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
build="${1:-build}"
package="$(cd "$build" 2>/dev/null && pwd)/Python"
[ -f "$package/dmplatform/__init__.py" ] || exit 0
[ -x /usr/bin/python3 ] || exit 0
site="$(/usr/bin/python3 -c 'import site; print(site.getsitepackages()[0])')"
if mkdir -p "$site" 2>/dev/null && [ -w "$site" ]; then
  printf '%s\n' "$package" > "$site/dmplatform.pth"
else
  echo "link_python: cannot write $site: use PYTHONPATH=$package /usr/bin/python3" >&2
fi
