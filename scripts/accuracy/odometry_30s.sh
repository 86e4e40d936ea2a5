#!/bin/bash
# Mapless odometry over 30 s of real hand-held motion (docs/accuracy.md, "Mapless odometry": "A
# local map of kept reference frames"): Canny-DEVO and Canny-VO on the TUM fr1_xyz trajectory
# rendered by evloc-sim with the depth-camera model.
#
# Usage: scripts/accuracy/odometry_30s.sh BUILD_DIR OUT_DIR [RUN...]
#   BUILD_DIR   a build with evloc-sim, evloc-track and evloc-eval
#   OUT_DIR     where the datasets and results go (outside the repository)
#   RUN         MODE-LIGHT with MODE devo or vo and LIGHT bright, dark or hdr (240x180, the
#               DAVIS240 preset), or devo-vga (640x480, bright) (default: all seven)
# The trajectory file comes from the shared data folder (EVLOC_TUM_TRAJECTORY overrides it).
# TRACK_FLAGS adds flags to evloc-track (e.g. "--stamp-at-step-time on"; DEVO's tracker takes
# the tracker's flags) and TAG names the results (OUT_DIR/results/RUN$TAG).
# A dataset already in OUT_DIR is reused (4-7 min each to render at 240x180 on this VM, 20 min
# at 640x480). Prints one table row per run: ATE and RPE (evloc-eval, no alignment, delta 1 s;
# RPE also as a percentage of the path's 30.5 cm/s), the first time beyond 10 cm, LOST steps,
# and for DEVO its reference frames and their build CPU time (pin the script with taskset -c N
# for comparable times). The drift column is evloc-eval --segments 1,2,4: the mean translation
# error over 1, 2 and 4 m of the path, in % of the length (docs/accuracy.md, "Drift over path
# lengths").
set -euo pipefail
if [ $# -lt 2 ]; then sed -n 2,20p "$0"; exit 2; fi
BUILD=$(realpath "$1"); OUT=$2; shift 2
RUNS=("$@")
[ ${#RUNS[@]} -gt 0 ] || RUNS=(devo-bright devo-dark devo-hdr devo-vga vo-bright vo-dark vo-hdr)
TRAJECTORY=${EVLOC_TUM_TRAJECTORY:-$(dirname "$0")/../../../shared/data/tum-trajectories/fr1_xyz_groundtruth.txt}
SIM=$BUILD/tools/sim/evloc-sim; TRACK=$BUILD/localizer/offline/evloc-track
EVAL=$BUILD/tools/eval/evloc-eval
for tool in "$SIM" "$TRACK" "$EVAL"; do
  [ -x "$tool" ] || { echo "odometry_30s: $tool is missing; build it first" >&2; exit 1; }
done
[ -f "$TRAJECTORY" ] || {
  echo "odometry_30s: no trajectory at $TRAJECTORY; set EVLOC_TUM_TRAJECTORY to a TUM file" >&2
  exit 1
}
mkdir -p "$OUT/results"

generate() {  # NAME CAMERA LIGHT -> dataset folder (rendered when missing)
  local dir=$OUT/$1
  if [ ! -f "$dir/groundtruth.txt" ]; then
    "$SIM" render --out "$dir" --camera "$2" --trajectory "$TRAJECTORY" --duration 30 \
      --lighting "$3" --depth-camera --force >&2
  fi
  echo "$dir"
}

echo "| run | ATE cm | ATE ° | RPE cm/s (% of path) | RPE °/s | drift % over 1 / 2 / 4 m | beyond 10 cm | LOST / steps | reference frames | build CPU ms median / max |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for run in "${RUNS[@]}"; do
  mode=${run%%-*}; light=${run#*-}
  case $mode in devo | vo) ;; *) echo "odometry_30s: unknown run '$run'" >&2; exit 2 ;; esac
  case $light in
    bright | dark | hdr) dataset=$(generate "fr1-$light-30s" davis240 "$light") ;;
    vga) [ "$mode" = devo ] || { echo "odometry_30s: vga is for devo only" >&2; exit 2; }
      dataset=$(generate vga-fr1-30s default bright) ;;
    *) echo "odometry_30s: unknown run '$run'" >&2; exit 2 ;;
  esac
  result=$OUT/results/$run${TAG:-}
  mkdir -p "$result"
  # shellcheck disable=SC2086
  "$TRACK" --mode "$mode" --dataset "$dataset" --out "$result/estimate.txt" \
    --stats "$result/stats.json" ${TRACK_FLAGS:-} > "$result/track.log" 2>&1
  "$EVAL" --gt "$dataset/groundtruth.txt" --est "$result/estimate.txt" \
    --json "$result/eval.json" --plot "$result/plot.png" --segments 1,2,4 > /dev/null
  /usr/bin/python3 - "$run" "$result" "$dataset/groundtruth.txt" <<'EOF'
import json, math, re, statistics, sys
run, result, truth = sys.argv[1:4]
e = json.load(open(result + "/eval.json"))
s = json.load(open(result + "/stats.json"))
poses = [list(map(float, line.split()[:4])) for line in open(truth)
         if line.strip() and not line.startswith("#")]
length = sum(math.dist(a[1:4], b[1:4]) for a, b in zip(poses, poses[1:]))
speed_cm_s = 100 * length / (poses[-1][0] - poses[0][0])
log = open(result + "/track.log").read()
builds = [float(v) for v in re.findall(r"\(([0-9.]+) ms CPU\)", log)]
frames = re.search(r"evloc-track: (\d+) (?:reference frames|keyframes)", log)
failed = e["failed_at_s"]
drift = " / ".join("-" if d["t_percent"] is None else "%.2f" % d["t_percent"] for d in e["drift"])
print("| %s | %.2f | %.2f | %.3f (%.1f %%) | %.2f | %s | %s | %d / %d | %s | %s |" % (
    run, e["ate_t_rmse_cm"], e["ate_r_rmse_deg"], e["rpe_t_rmse_cm_s"],
    100 * e["rpe_t_rmse_cm_s"] / speed_cm_s, e["rpe_r_rmse_deg_s"], drift,
    "never" if failed is None else "%.2f s" % failed, s["lost_steps"], s["steps"],
    frames.group(1) if frames else "-",
    "%.1f / %.1f" % (statistics.median(builds), max(builds)) if builds else "-"))
EOF
done
