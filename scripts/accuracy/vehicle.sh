#!/bin/bash
# Tracking at vehicle speed on the simulated car park (docs/accuracy.md, "Vehicle speed").
#
# Usage: scripts/accuracy/vehicle.sh BUILD_DIR OUT_DIR [RUN...] [-- TRACK_FLAGS...]
#   BUILD_DIR   a build with evloc-sim, evloc-track and evloc-eval
#   OUT_DIR     where the datasets and results go (outside the repository)
#   RUN         day5 | day10 | night5 | night10 | night5-davis346 | walk (default: day5 day10
#               night5 walk): the vehicle route (`evloc-sim render --scene carpark --path vehicle`)
#               at 5 or 10 m/s, by day or at night (street lamps; `-davis346`: the realistic
#               DAVIS346 pixel instead of the ideal one), over the end of the first lane and into
#               the half turn at its end (30 m at 5 m/s from 150 m along the route, 50 m at 10 m/s
#               from 140 m); walk: the pedestrian path (1.4 m/s, 8 s)
#   TRACK_FLAGS evloc-track flags replacing the vehicle defaults below
# Vehicle defaults: poses stamped at their step time and the motion prior (docs/tracking.md,
# "Vehicle speed", "Motion prior"): --stamp-at-step-time on --motion-prior 2,0.
# Camera: the DAVIS240 preset (240x180). Ground-truth map: the whole site at 5 cm spacing.
# A dataset already in OUT_DIR is reused (2-10 min each to render on this VM).
# Prints one table row per run: ATE and RPE (evloc-eval, no alignment, delta 1 s), the largest
# error, coverage, LOST steps, and the median step time (evloc-track --stats; pin the script
# with taskset -c 1 for comparable times).
set -euo pipefail
if [ $# -lt 2 ]; then sed -n 2,21p "$0"; exit 2; fi
BUILD=$(realpath "$1"); OUT=$2; shift 2
RUNS=(); TRACK_FLAGS=(--stamp-at-step-time on --motion-prior 2,0)
while [ $# -gt 0 ]; do
  if [ "$1" = "--" ]; then shift; TRACK_FLAGS=("$@"); break; fi
  RUNS+=("$1"); shift
done
[ ${#RUNS[@]} -gt 0 ] || RUNS=(day5 day10 night5 walk)
SIM=$BUILD/tools/sim/evloc-sim; TRACK=$BUILD/localizer/offline/evloc-track
EVAL=$BUILD/tools/eval/evloc-eval
for tool in "$SIM" "$TRACK" "$EVAL"; do
  [ -x "$tool" ] || { echo "vehicle: $tool is missing; build it first" >&2; exit 1; }
done
mkdir -p "$OUT/results"

generate() {  # RUN -> dataset folder (rendered when missing)
  local run=$1 dir=$OUT/$1 flags
  case $run in
    day5) flags=(--path vehicle --speed 5 --path-start 150 --duration 6) ;;
    day10) flags=(--path vehicle --speed 10 --path-start 140 --duration 5) ;;
    night5) flags=(--path vehicle --speed 5 --path-start 150 --duration 6 --time-of-day night) ;;
    night10) flags=(--path vehicle --speed 10 --path-start 140 --duration 5 --time-of-day night) ;;
    night5-davis346)
      flags=(--path vehicle --speed 5 --path-start 150 --duration 6 --time-of-day night
             --sensor davis346) ;;
    walk) flags=(--path pedestrian --path-start 60 --duration 8) ;;
    *) echo "vehicle: unknown run '$run'" >&2; exit 2 ;;
  esac
  if [ ! -f "$dir/groundtruth.txt" ]; then
    "$SIM" render --out "$dir" --scene carpark --camera davis240 --map-spacing 0.05 \
      "${flags[@]}" --force >&2
  fi
  echo "$dir"
}

echo "| run | ATE cm | ATE ° | max cm | RPE cm/s | coverage | LOST / steps | step ms (median) |"
echo "|---|---|---|---|---|---|---|---|"
for run in "${RUNS[@]}"; do
  dataset=$(generate "$run")
  result=$OUT/results/$run
  mkdir -p "$result"
  "$TRACK" --map "$dataset/gt_map" --dataset "$dataset" --out "$result/estimate.txt" \
    --stats "$result/stats.json" --quiet "${TRACK_FLAGS[@]}"
  "$EVAL" --gt "$dataset/groundtruth.txt" --est "$result/estimate.txt" \
    --json "$result/eval.json" --plot "$result/plot.png" > /dev/null
  /usr/bin/python3 - "$run" "$result" <<'EOF'
import json, sys
run, result = sys.argv[1], sys.argv[2]
e = json.load(open(result + "/eval.json"))
s = json.load(open(result + "/stats.json"))
print("| %s | %.2f | %.3f | %.1f | %.2f | %.3f | %d / %d | %.2f |" % (
    run, e["ate_t_rmse_cm"], e["ate_r_rmse_deg"], e["ate_t_max_cm"], e["rpe_t_rmse_cm_s"],
    e["coverage"], s["lost_steps"], s["steps"], s["median_step_ms"]))
EOF
done
