#!/bin/bash
# Tracking accuracy on simulated sequences (docs/accuracy.md, "Tracking accuracy").
#
# Usage: scripts/accuracy/tracking_accuracy.sh BUILD_DIR OUT_DIR [SEQUENCE...] [-- TRACK_FLAGS...]
#   BUILD_DIR   a build with evloc-sim, evloc-track and evloc-eval
#   OUT_DIR     where the datasets and results go (outside the repository: datasets are gigabytes)
#   SEQUENCE    MOTION[:SECONDS] with MOTION one of slow | mid | fast | aggressive (evloc-sim
#               --motion; default 10 s), dark | hdr (the mid motion under --lighting dark / hdr;
#               default 5 s), or fr1_xyz[:SECONDS] (the TUM fr1_xyz ground truth replayed, default
#               the whole 30 s); default: mid fr1_xyz. The dataset folder is OUT_DIR/NAME-SECONDSs.
#   TRACK_FLAGS extra evloc-track flags for every run (e.g. --tau 0.005)
# Env: VARIANTS (default "EVT") and RATES (default "300") run every combination. Variants:
#   EVT, EVT-PR, EVT-OH, EVT-- (docs/tracking.md, "Variants"); EVT1 = EVT with --two-stage off
#   (one signed solve, as the paper); VT = Canny-VT on the dataset's frames (--mode frames; the
#   rate does not apply).
#   RUN_TAG names the results folder's variant of the flags (OUT_DIR/results/...-RATE-RUN_TAG), so
#   that runs with different TRACK_FLAGS (e.g. the noise filters) keep their results apart.
#   MAP=built uses OUT_DIR/maps/NAME-SECONDSs (an evloc-mapper map of the sequence's frames, built
#   beforehand) instead of the dataset's gt_map.
# A dataset already in OUT_DIR is reused (rendering 10 s of mid at 640x480 takes 10-30 min).
# Prints one table row per run: ATE and RPE (evloc-eval, alignment none), coverage, the time the
# error first exceeded evloc-eval's failure threshold, LOST steps, and the fraction of confident
# polarity predictions that match the events (docs/tracking.md).
set -euo pipefail
if [ $# -lt 2 ]; then sed -n 2,22p "$0"; exit 2; fi
BUILD=$(realpath "$1"); OUT=$2; shift 2
SEQUENCES=(); EXTRA=()
while [ $# -gt 0 ]; do
  if [ "$1" = "--" ]; then shift; EXTRA=("$@"); break; fi
  SEQUENCES+=("$1"); shift
done
[ ${#SEQUENCES[@]} -gt 0 ] || SEQUENCES=(mid fr1_xyz)
VARIANTS=${VARIANTS:-EVT}
RATES=${RATES:-300}
MAP=${MAP:-gt}
SIM=$BUILD/tools/sim/evloc-sim; TRACK=$BUILD/localizer/offline/evloc-track
EVAL=$BUILD/tools/eval/evloc-eval
TUM=${TUM_TRAJECTORY:-/work/shared/data/tum-trajectories/fr1_xyz_groundtruth.txt}
for tool in "$SIM" "$TRACK" "$EVAL"; do
  [ -x "$tool" ] || { echo "tracking_accuracy: $tool is missing; build it first" >&2; exit 1; }
done
mkdir -p "$OUT"

folder() {  # SEQUENCE -> dataset folder name
  local motion=${1%%:*} seconds=${1#*:}
  if [ "$seconds" = "$1" ]; then
    case $motion in dark|hdr) seconds=5 ;; fr1_xyz) seconds=30 ;; *) seconds=10 ;; esac
  fi
  echo "$motion-${seconds}s"
}

generate() {  # SEQUENCE -> dataset folder (rendered when missing)
  local motion=${1%%:*} name dir
  name=$(folder "$1"); dir=$OUT/$name
  local seconds=${name##*-}; seconds=${seconds%s}
  if [ ! -f "$dir/groundtruth.txt" ]; then
    case $motion in
      fr1_xyz) "$SIM" render --out "$dir" --trajectory "$TUM" --duration "$seconds" --force >&2 ;;
      slow|mid|fast|aggressive)
        "$SIM" render --out "$dir" --motion "$motion" --duration "$seconds" --force >&2 ;;
      dark|hdr)
        "$SIM" render --out "$dir" --motion mid --lighting "$motion" --duration "$seconds" \
          --force >&2 ;;
      *) echo "tracking_accuracy: unknown sequence '$1' (see the usage)" >&2; exit 2 ;;
    esac
  fi
  echo "$dir"
}

printf '%-14s %-7s %5s %9s %9s %9s %9s %8s %8s %11s %6s %8s\n' sequence variant Hz ate_t_cm \
  ate_r_deg rpe_t_cms rpe_r_degs coverage failed lost polarity wall_s
for sequence in "${SEQUENCES[@]}"; do
  dataset=$(generate "$sequence")
  name=$(basename "$dataset")
  map=$dataset/gt_map
  if [ "$MAP" = built ]; then
    map=$OUT/maps/$name
    [ -f "$map/map.evmap" ] || { echo "$name: no built map at $map (run evloc-mapper build first)"; continue; }
  fi
  for variant in $VARIANTS; do
    rates=$RATES
    [ "$variant" = VT ] && rates=frames
    for rate in $rates; do
      case $variant in
        EVT1) flags=(--variant EVT --two-stage off --rate "$rate") ;;
        VT) flags=(--mode frames) ;;
        *) flags=(--variant "$variant" --rate "$rate") ;;
      esac
      run=$OUT/results/$MAP-$name-$variant-$rate${RUN_TAG:+-$RUN_TAG}
      mkdir -p "$run"
      "$TRACK" --map "$map" --dataset "$dataset" --out "$run/est.txt" --stats "$run/stats.json" \
        "${flags[@]}" --quiet ${EXTRA[@]+"${EXTRA[@]}"} > "$run/track.log" 2>&1 ||
        { echo "$name $variant $rate: evloc-track failed, see $run/track.log"; continue; }
      "$EVAL" --gt "$dataset/groundtruth.txt" --est "$run/est.txt" --align none \
        --json "$run/eval.json" > "$run/eval.log" 2>&1 ||
        { echo "$name $variant $rate: evloc-eval failed, see $run/eval.log"; continue; }
      /usr/bin/python3 - "$run" "$name" "$variant" "$rate" <<'PY'
import json, sys
run, name, variant, rate = sys.argv[1:]
e = json.load(open(f"{run}/eval.json")); s = json.load(open(f"{run}/stats.json"))
def f(key, fmt="%.3f"):
    v = e.get(key)
    return "-" if v is None else fmt % v
steps = s["per_step"]
predicted = sum(x.get("polarity_predictions", 0) for x in steps)
matched = sum(x.get("polarity_matches", 0) for x in steps)
polarity = "%.3f" % (matched / predicted) if predicted else "-"
print("%-14s %-7s %5s %9s %9s %9s %9s %8s %8s %11s %6s %8.1f" % (
    name, variant, rate, f("ate_t_rmse_cm"), f("ate_r_rmse_deg"), f("rpe_t_rmse_cm_s"),
    f("rpe_r_rmse_deg_s"), f("coverage"), f("failed_at_s", "%.2f s"),
    "%d/%d" % (s["lost_steps"], s["steps"]), polarity, s["wall_s"]))
PY
    done
  done
done
