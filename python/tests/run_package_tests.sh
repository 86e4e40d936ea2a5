#!/usr/bin/env bash
# ctest evloc_python_package_test: installs the evloc package as a user does (docs/python.md: a
# venv with Debian's packages, pip without build isolation, offline) from this build, then runs
# its pytest tests against the installed package, from outside the source tree.
# Usage: run_package_tests.sh BUILD_DIR [pytest arguments...]
set -euo pipefail
BUILD_DIR=$(cd "$1" && pwd)
shift
SOURCE_DIR=$(cd "$(dirname "$0")/.." && pwd)
VENV="$BUILD_DIR/python/venv"
PYTHON=${EVLOC_PYTHON:-/usr/bin/python3}

for module in numpy grpc google.protobuf pytest; do
  if ! "$PYTHON" -c "import $module" 2>/dev/null; then
    echo "run_package_tests: $PYTHON cannot import $module: run scripts/install-deps.sh" >&2
    exit 1
  fi
done
if [[ ! -x "$VENV/bin/python" ]]; then
  "$PYTHON" -m venv --system-site-packages "$VENV"
fi
start=$(date +%s%N)
EVLOC_BUILD_DIR="$BUILD_DIR" "$VENV/bin/pip" install --quiet --no-build-isolation --no-index \
  --force-reinstall --no-deps "$SOURCE_DIR"
elapsed_ms=$((($(date +%s%N) - start) / 1000000))
echo "run_package_tests: pip install ./python took ${elapsed_ms} ms"
cd "$BUILD_DIR/python"
EVLOC_BUILD_DIR="$BUILD_DIR" exec "$VENV/bin/python" -m pytest -p no:cacheprovider -rs -q \
  "$SOURCE_DIR/tests" "$@"
