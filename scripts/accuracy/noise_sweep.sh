#!/bin/bash
# Tracking under sensor noise (docs/accuracy.md, "Sensor noise"): the issue-15 sweep of shot-noise
# rate x hot-pixel fraction x lighting, rendered with the realistic pixel (docs/simulator.md) and
# tracked with evloc-track against each dataset's ground-truth map.
#
# Usage: scripts/accuracy/noise_sweep.sh BUILD_DIR OUT_DIR
#   BUILD_DIR   a build with evloc-sim, evloc-track and evloc-eval
#   OUT_DIR     where the datasets and results go (outside the repository); a dataset already
#               there is reused, so a second run with other TRACK_FLAGS only tracks
# Env (defaults in brackets):
#   TRACK_FLAGS  extra evloc-track flags for every run, e.g. the noise filters [none]
#   TAG          name of this set of tracking runs, for the results folder [default]
#   NOISE_RATES  evloc-sim --noise-rate values, Hz per pixel at the darkest level [0.1 1 3 10]
#   HOT_PIXELS   evloc-sim --hot-pixels fractions [0 0.001 0.01]
#   LIGHTINGS    evloc-sim --lighting values [bright dark]
#   SENSOR       evloc-sim --sensor [davis240]; CAMERA evloc-sim --camera [davis240]
#   DURATION     seconds of the path [10]
#   TRAJECTORY   TUM file replayed as the path [the TUM fr1_xyz hand-held ground truth]
#   CPU          the core evloc-track is pinned to (taskset) for the step cost [1]
# Prints one row per run: the event counts (all, and of them noise and hot-pixel events, from
# info.json), ATE (evloc-eval, no alignment, tolerance 0.02 s), coverage, LOST steps / steps, and
# the step cost (median and mean of the per-step tracking time, ms; evloc-track wall time, s).
set -euo pipefail
if [ $# -ne 2 ]; then sed -n 2,22p "$0"; exit 2; fi
BUILD=$(realpath "$1"); OUT=$2
TRACK_FLAGS=${TRACK_FLAGS:-}
TAG=${TAG:-default}
NOISE_RATES=${NOISE_RATES:-0.1 1 3 10}
HOT_PIXELS=${HOT_PIXELS:-0 0.001 0.01}
LIGHTINGS=${LIGHTINGS:-bright dark}
SENSOR=${SENSOR:-davis240}
CAMERA=${CAMERA:-davis240}
DURATION=${DURATION:-10}
TRAJECTORY=${TRAJECTORY:-/work/shared/data/tum-trajectories/fr1_xyz_groundtruth.txt}
CPU=${CPU:-1}
SIM=$BUILD/tools/sim/evloc-sim; TRACK=$BUILD/localizer/offline/evloc-track
EVAL=$BUILD/tools/eval/evloc-eval
for tool in "$SIM" "$TRACK" "$EVAL"; do
  [ -x "$tool" ] || { echo "noise_sweep: $tool is missing; build it first" >&2; exit 1; }
done
[ -f "$TRAJECTORY" ] || { echo "noise_sweep: no trajectory file $TRAJECTORY (set TRAJECTORY)" >&2; exit 1; }
mkdir -p "$OUT"
read -r -a track_flags <<< "$TRACK_FLAGS"

printf '%-7s %6s %6s %10s %9s %9s %9s %9s %11s %8s %8s %7s\n' lighting noise hot events \
  noise_ev hot_ev ate_t_cm coverage lost median_ms mean_ms wall_s
for lighting in $LIGHTINGS; do
  for noise in $NOISE_RATES; do
    for hot in $HOT_PIXELS; do
      name=$SENSOR-$CAMERA-$lighting-n$noise-h$hot-${DURATION}s
      dataset=$OUT/$name
      if [ ! -f "$dataset/info.json" ]; then
        "$SIM" render --out "$dataset" --camera "$CAMERA" --trajectory "$TRAJECTORY" \
          --duration "$DURATION" --sensor "$SENSOR" --noise-rate "$noise" --hot-pixels "$hot" \
          --lighting "$lighting" --force > "$OUT/$name.render.log" 2>&1 ||
          { echo "$name: evloc-sim failed, see $OUT/$name.render.log"; continue; }
      fi
      run=$OUT/results/$TAG/$name
      mkdir -p "$run"
      taskset -c "$CPU" "$TRACK" --map "$dataset/gt_map" --dataset "$dataset" --out "$run/est.txt" \
        --stats "$run/stats.json" --quiet ${track_flags[@]+"${track_flags[@]}"} \
        > "$run/track.log" 2>&1 ||
        { echo "$name: evloc-track failed, see $run/track.log"; continue; }
      "$EVAL" --gt "$dataset/groundtruth.txt" --est "$run/est.txt" --align none \
        --json "$run/eval.json" > "$run/eval.log" 2>&1 ||
        { echo "$name: evloc-eval failed, see $run/eval.log"; continue; }
      /usr/bin/python3 - "$dataset" "$run" "$lighting" "$noise" "$hot" <<'PY'
import json, statistics, sys
dataset, run, lighting, noise, hot = sys.argv[1:]
info = json.load(open(f"{dataset}/info.json"))["counts"]
e = json.load(open(f"{run}/eval.json")); s = json.load(open(f"{run}/stats.json"))
ate = e.get("ate_t_rmse_cm")
costs = [x["total_ms"] for x in s["per_step"] if "total_ms" in x]
print("%-7s %6s %6s %10d %9d %9d %9s %9.3f %11s %8.3f %8.3f %7.1f" % (
    lighting, noise, hot, info["events"], info["noise_events"], info["hot_pixel_events"],
    "-" if ate is None else "%.3f" % ate, e.get("coverage", 0.0),
    "%d/%d" % (s["lost_steps"], s["steps"]), statistics.median(costs) if costs else 0.0,
    statistics.mean(costs) if costs else 0.0, s["wall_s"]))
PY
    done
  done
done
