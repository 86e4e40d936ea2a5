#!/usr/bin/env bash
# The real-frame run of issue 5 item 5 (docs/mapper.md, "slider_depth"; docs/accuracy.md): a map
# of ECD slider_depth from its 87 real DAVIS240C frames at the slider poses, its edge distance on
# the frames, events from the frames (evloc-sim events-from-frames), tracking against the map
# (evloc-track) and the trajectory error against the slider ground truth (evloc-eval, no
# alignment).
#
# Usage: scripts/accuracy/slider_depth.sh [OUT_DIR] [BUILD_DIR]
#   OUT_DIR    results (default /tmp/evloc-slider): slider_map/ (its COLMAP workspace beside it is
#              reused when the inputs match), slider_events/, slider_run/ (est.txt, stats.json,
#              eval.json, eval.png, debug/: tracking pictures)
#   BUILD_DIR  build tree with evloc-mapper, evloc-mapper-accuracy, evloc-sim, evloc-track and
#              evloc-eval (default build)
# Env: EVLOC_DATA_DIR (default ../shared/data from the project root), CONTRAST (ESIM threshold of
# events-from-frames, default 0.5: docs/simulator.md section 5), TRACK_FLAGS (extra evloc-track
# flags). Exits non-zero when a step fails.
set -euo pipefail

root=$(cd "$(dirname "$0")/../.." && pwd)
out=${1:-/tmp/evloc-slider}
build=$(realpath "${2:-$root/build}")
data=${EVLOC_DATA_DIR:-$root/../shared/data}/ecd/slider_depth
if [[ ! -f "$data/images.txt" ]]; then
  echo "slider_depth not found in $data (set EVLOC_DATA_DIR)" >&2
  exit 1
fi
mkdir -p "$out/slider_run"
run=$out/slider_run

echo "== map from the frames at the slider poses"
rm -rf "$out/slider_map"
/usr/bin/time -f "evloc-mapper build: %e s wall, %U s user, %S s system" \
  "$build/mapper/evloc-mapper" build --images "$data" --images-list "$data/images.txt" \
  --calib "$data/calib.txt" --known-poses "$data/groundtruth.txt" --out "$out/slider_map" --quiet
"$build/mapper/evloc-mapper" info "$out/slider_map" | sed -n '/^points:/p;/^keyframes:/p;/bounding box/p'
sed -n '/"timings"/,/]/p' "$out/slider_map/report.json" | tr -d '\n ' | sed 's/},{/}\n{/g'
echo
echo "== edge distance of the map on its keyframe frames (pixels)"
"$build/tools/map_accuracy/evloc-mapper-accuracy" --map "$out/slider_map" --images "$data"

echo "== events from the frames (contrast ${CONTRAST:-0.5})"
"$build/tools/sim/evloc-sim" events-from-frames --in "$data" --out "$out/slider_events" \
  --contrast "${CONTRAST:-0.5}" --force

echo "== tracking"
rm -rf "$run/debug"
# shellcheck disable=SC2086
/usr/bin/time -f "evloc-track: %e s wall, %U s user, %S s system" \
  "$build/localizer/offline/evloc-track" --map "$out/slider_map" --dataset "$out/slider_events" \
  --out "$run/est.txt" --stats "$run/stats.json" --debug-dir "$run/debug" --quiet \
  ${TRACK_FLAGS:-}
/usr/bin/python3 - "$run/stats.json" <<'EOF'
import json, sys
stats = json.load(open(sys.argv[1]))
lost = [step["t_s"] for step in stats["per_step"] if step["status"] != "TRACKING"]
print(f"steps {stats['steps']}, LOST {len(lost)}" +
      (f" (first at {lost[0]:.3f} s, last at {lost[-1]:.3f} s)" if lost else ""))
EOF

echo "== trajectory error against the slider ground truth (no alignment)"
"$build/tools/eval/evloc-eval" --gt "$data/groundtruth.txt" --est "$run/est.txt" --align none \
  --json "$run/eval.json" --plot "$run/eval.png"
