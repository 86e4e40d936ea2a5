#!/usr/bin/env bash
# A shortened `make demo` (scripts/demo.sh, docs/demo.md): 1.5 s of the circling camera at 320x240,
# the map from 15 frames by COLMAP without poses, the events through the gRPC service, the checks
# and the table. Fails when the demo fails or an output it promises is missing.
#
# Usage: tests/demo_test.sh BUILD_DIR   (ctest: evloc_demo_short_test)
# Exit codes: 0 pass, 1 fail, 77 skipped (COLMAP not installed).
set -euo pipefail

build_dir=$(cd "${1:?usage: demo_test.sh BUILD_DIR}" && pwd)
source_dir=$(cd "$(dirname "$0")/.." && pwd)
if ! command -v colmap >/dev/null 2>&1; then
  echo "SKIPPED: colmap is not installed (scripts/install-deps.sh installs it)"
  exit 77
fi

out=$(mktemp -d "${TMPDIR:-/tmp}/evloc-demo-test.XXXXXX")
# A small pinhole camera keeps the render and COLMAP short.
cat >"$out/camera.yaml" <<'EOF'
model: pinhole
width: 320
height: 240
intrinsics: [250, 250, 159.5, 119.5]
distortion: []
EOF

status=0
(cd "$source_dir" && BUILD_DIR="$build_dir" EVLOC_DEMO_OUT="$out/demo-out" \
  EVLOC_DEMO_DURATION=1.5 EVLOC_DEMO_CAMERA="$out/camera.yaml" EVLOC_DEMO_MAX_FEATURES=1024 \
  scripts/demo.sh) || status=$?
if ((status != 0)); then
  echo "FAIL: scripts/demo.sh exited with status $status; outputs kept in $out"
  exit 1
fi

missing=()
for file in maps/room/map.evmap maps/room/map.ply maps/room/preview.png maps/room/report.json \
  trajectory_room.txt trajectory_room-exact.txt eval_room.png eval_room.json replay_room.json \
  logs/server.log summary.txt; do
  [[ -s "$out/demo-out/$file" ]] || missing+=("$file")
done
if ((${#missing[@]} > 0)); then
  echo "FAIL: missing or empty in demo-out/: ${missing[*]}; outputs kept in $out"
  exit 1
fi
if ! grep -q '^evloc-localizer: stopped' "$out/demo-out/logs/server.log"; then
  echo "FAIL: the service log does not end with 'stopped'; outputs kept in $out"
  exit 1
fi
if ! grep -q '^evloc, map built from the frames' "$out/demo-out/summary.txt"; then
  echo "FAIL: summary.txt has no result table; outputs kept in $out"
  exit 1
fi
rm -rf "$out"
echo "PASS"
