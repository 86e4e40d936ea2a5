#!/bin/bash
# Tracking accuracy on simulated sequences (docs/accuracy.md, "Tracking accuracy").
#
# Usage: scripts/accuracy/tracking_accuracy.sh BUILD_DIR OUT_DIR [SEQUENCE...] [-- TRACK_FLAGS...]
#   BUILD_DIR   a build with evloc-sim, evloc-track and evloc-eval
#   OUT_DIR     where the datasets and results go (under /tmp: datasets are gigabytes)
#   SEQUENCE    slow | mid | fast | aggressive (10 s of --motion) or fr1_xyz (the TUM fr1_xyz
#               ground truth replayed for FR1_XYZ_DURATION seconds, default 30; the dataset folder
#               is fr1_xyz-<duration>s); default: mid fr1_xyz
#   TRACK_FLAGS extra evloc-track flags for every run (e.g. --variant EVT-- --rate 150)
# Env: VARIANTS="EVT EVT-PR EVT-OH EVT--" and RATES="300 150 100" (defaults: EVT and 300) run
# every combination. A dataset already in OUT_DIR is reused (rendering is slow: 10 s of mid at
# 640x480 took 12 min wall here). Prints one table row per run.
set -euo pipefail
if [ $# -lt 2 ]; then sed -n 2,16p "$0"; exit 2; fi
BUILD=$(realpath "$1"); OUT=$2; shift 2
SEQUENCES=(); EXTRA=()
while [ $# -gt 0 ]; do
  if [ "$1" = "--" ]; then shift; EXTRA=("$@"); break; fi
  SEQUENCES+=("$1"); shift
done
[ ${#SEQUENCES[@]} -gt 0 ] || SEQUENCES=(mid fr1_xyz)
VARIANTS=${VARIANTS:-EVT}
RATES=${RATES:-300}
SIM=$BUILD/tools/sim/evloc-sim; TRACK=$BUILD/localizer/offline/evloc-track
EVAL=$BUILD/tools/eval/evloc-eval
TUM=${TUM_TRAJECTORY:-/work/shared/data/tum-trajectories/fr1_xyz_groundtruth.txt}
mkdir -p "$OUT"

FR1_XYZ_DURATION=${FR1_XYZ_DURATION:-30}

generate() {  # sequence name -> dataset folder
  local name=$1 dir=$OUT/$1
  [ "$name" = fr1_xyz ] && dir=$OUT/fr1_xyz-${FR1_XYZ_DURATION}s
  if [ ! -f "$dir/groundtruth.txt" ]; then
    case $name in
      fr1_xyz) "$SIM" render --out "$dir" --trajectory "$TUM" --duration "$FR1_XYZ_DURATION" \
                 --force >&2 ;;
      slow|mid|fast|aggressive) "$SIM" render --out "$dir" --motion "$name" --duration 10 --force >&2 ;;
      *) echo "unknown sequence $name" >&2; exit 2 ;;
    esac
  fi
  echo "$dir"
}

printf '%-10s %-7s %5s %9s %9s %9s %9s %8s %6s %9s %8s %8s\n' sequence variant Hz ate_t_cm \
  ate_r_deg rpe_t_cms rpe_r_degs coverage lost wall_s step_ms_med events_M
for sequence in "${SEQUENCES[@]}"; do
  dataset=$(generate "$sequence")
  for variant in $VARIANTS; do
    for rate in $RATES; do
      run=$OUT/results/$sequence-$variant-$rate
      mkdir -p "$run"
      "$TRACK" --map "$dataset/gt_map" --dataset "$dataset" --out "$run/est.txt" \
        --stats "$run/stats.json" --variant "$variant" --rate "$rate" --quiet \
        ${EXTRA[@]+"${EXTRA[@]}"} > "$run/track.log" 2>&1 || { echo "$sequence $variant $rate: evloc-track failed, see $run/track.log"; continue; }
      "$EVAL" --gt "$dataset/groundtruth.txt" --est "$run/est.txt" --align none \
        --json "$run/eval.json" > "$run/eval.log" 2>&1 || { echo "$sequence $variant $rate: evloc-eval failed, see $run/eval.log"; continue; }
      python3 - "$run" "$sequence" "$variant" "$rate" <<'PY'
import json, sys
run, sequence, variant, rate = sys.argv[1:]
e = json.load(open(f"{run}/eval.json")); s = json.load(open(f"{run}/stats.json"))
def f(key, fmt="%.3f"):
    v = e.get(key)
    return "-" if v is None else fmt % v
print("%-10s %-7s %5s %9s %9s %9s %9s %8s %6d %9.2f %8.3f %8.1f" % (
    sequence, variant, rate, f("ate_t_rmse_cm"), f("ate_r_rmse_deg"), f("rpe_t_rmse_cm_s"),
    f("rpe_r_rmse_deg_s"), f("coverage"), s["lost_steps"], s["wall_s"], s["median_step_ms"],
    s["measurements"] / 1e6))
PY
    done
  done
done
