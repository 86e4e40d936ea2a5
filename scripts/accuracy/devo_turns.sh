#!/bin/bash
# Plain Canny-DEVO on a family of hand-held paths that turn away from the mapped view of the
# rendered room and back (docs/accuracy.md, "DEVO on turning paths"): how often odometry alone
# loses more than 10 cm, and in which direction it goes wrong.
#
# Usage: scripts/accuracy/devo_turns.sh BUILD_DIR OUT_DIR [TAG [FLAG...]]
#   BUILD_DIR   a build with evloc-sim, evloc-track and evloc-eval
#   OUT_DIR     where the renders (reused when present) and results go, outside the repository
#   TAG         names this run's results (OUT_DIR/results/TAG-PATH.*; default "default")
#   FLAG...     added to `evloc-track --mode devo` (e.g. --velocity-window 0.1)
# HANDOVER=1 runs the hand-over instead (`evloc-track --map PATH/gt_map --handover`: the map of
# the first 1.5 s, DEVO while it is not seen) and adds when each path is back on the map for good.
# The 34 paths: handover_path.py with --turn 2.0 and --yaw +-60/+-90/+-120, --turn 1.0 and 3.0
# with +-90/+-120, --turn 1.5 and 2.5 with +-60/+-75/+-90/+-105/+-120 (positive = right), each
# rendered as `evloc-sim render --camera davis240 --trajectory P --depth-camera --map-until 1.5`
# (about 1 min each on one core). JOBS (default 2) runs that many at once, job k pinned to core
# k (accuracy does not depend on it: every run is deterministic).
# Prints one row per path (ATE RMSE and max, cm; when the error first exceeds 10 cm, and how the
# error moves in the camera frame over the next 0.3 s) and a summary line.
set -euo pipefail
if [ $# -lt 2 ]; then sed -n 2,19p "$0"; exit 2; fi
BUILD=$(realpath "$1"); OUT=$(realpath -m "$2"); shift 2
TAG=${1:-default}; [ $# -gt 0 ] && shift
JOBS=${JOBS:-2}
SCRIPTS=$(dirname "$(realpath "$0")")
SIM=$BUILD/tools/sim/evloc-sim; TRACK=$BUILD/localizer/offline/evloc-track
EVAL=$BUILD/tools/eval/evloc-eval
for tool in "$SIM" "$TRACK" "$EVAL"; do
  [ -x "$tool" ] || { echo "devo_turns: $tool is missing; build it first" >&2; exit 1; }
done
PATHS=()
for yaw in 60 -60 90 -90 120 -120; do PATHS+=("y${yaw}-t2.0"); done
for turn in 1.0 3.0; do for yaw in 90 -90 120 -120; do PATHS+=("y${yaw}-t${turn}"); done; done
for turn in 1.5 2.5; do
  for yaw in 60 -60 75 -75 90 -90 105 -105 120 -120; do PATHS+=("y${yaw}-t${turn}"); done
done
mkdir -p "$OUT/results"

render() {  # NAME
  local name=$1 yaw turn
  yaw=${name#y}; yaw=${yaw%%-t*}; turn=${name##*-t}
  [ -f "$OUT/$name/groundtruth.txt" ] && return 0
  /usr/bin/python3 "$SCRIPTS/handover_path.py" "$OUT/$name.path.txt" --yaw "$yaw" --turn "$turn"
  "$SIM" render --out "$OUT/$name" --camera davis240 --trajectory "$OUT/$name.path.txt" \
    --depth-camera --map-until 1.5 --force > "$OUT/$name.render.log" 2>&1
}

run() {  # NAME CORE
  local name=$1 result=$OUT/results/$TAG-$1
  render "$name"
  local mode=(--mode devo)
  [ "${HANDOVER:-0}" = 1 ] && mode=(--map "$OUT/$name/gt_map" --handover)
  taskset -c "$2" "$TRACK" "${mode[@]}" --dataset "$OUT/$name" --out "$result.txt" \
    --stats "$result.stats.json" --quiet "${FLAGS[@]}" > "$result.log" 2>&1
  "$EVAL" --gt "$OUT/$name/groundtruth.txt" --est "$result.txt" --json "$result.eval.json" \
    > /dev/null
}
FLAGS=("$@")

for ((i = 0; i < ${#PATHS[@]}; i += JOBS)); do
  for ((k = 0; k < JOBS && i + k < ${#PATHS[@]}; ++k)); do run "${PATHS[i + k]}" "$k" & done
  wait
done

/usr/bin/python3 - "$OUT" "$TAG" "${HANDOVER:-0}" "${PATHS[@]}" <<'EOF'
import json, statistics, sys
import numpy as np

out, tag, handover, names = sys.argv[1], sys.argv[2], sys.argv[3] == "1", sys.argv[4:]


def rotation_matrix(q):  # x, y, z, w
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


print("| path | ATE cm | max cm | beyond 10 cm at | error moves over the next 0.3 s (camera x, y, z; cm) |"
      + (" back on the map at |" if handover else ""))
print("|---|---|---|---|---|" + ("---|" if handover else ""))
ates, back = [], 0
for name in names:
    e = json.load(open(f"{out}/results/{tag}-{name}.eval.json"))
    ates.append(e["ate_t_rmse_cm"])
    truth = np.loadtxt(f"{out}/{name}/groundtruth.txt", comments="#")
    estimate = np.loadtxt(f"{out}/results/{tag}-{name}.txt", comments="#")
    # The camera-frame position error of every estimate against the nearest truth pose.
    index = np.clip(np.searchsorted(truth[:, 0], estimate[:, 0]), 0, len(truth) - 1)
    errors = [rotation_matrix(truth[i, 4:8]).T @ (p[1:4] - truth[i, 1:4])
              for i, p in zip(index, estimate)]
    beyond = next((k for k, d in enumerate(errors) if np.linalg.norm(d) > 0.10), None)
    if beyond is None:
        when, moves = "never", ""
    else:
        later = np.searchsorted(estimate[:, 0], estimate[beyond, 0] + 0.3)
        move = 100 * (errors[min(later, len(errors) - 1)] - errors[beyond])
        when, moves = f"{estimate[beyond, 0]:.2f} s", "%+.0f, %+.0f, %+.0f" % tuple(move)
    row = f"| {name} | {e['ate_t_rmse_cm']:.1f} | {e['ate_t_max_cm']:.0f} | {when} | {moves} |"
    if handover:
        # The first step of the last stretch from the map, if the odometry ran before it.
        steps = json.load(open(f"{out}/results/{tag}-{name}.stats.json"))["per_step"]
        k = len(steps)
        while k > 0 and steps[k - 1].get("source") == "map":
            k -= 1
        returned = 0 < k < len(steps) and any(s.get("source") == "odometry" for s in steps[:k])
        back += returned
        row += f" {steps[k]['t_s']:.2f} s |" if returned else " never |"
    print(row)
print(f"{tag}: {len(ates)} paths, ATE median {statistics.median(ates):.2f} cm, mean "
      f"{statistics.mean(ates):.1f} cm, {sum(a > 10 for a in ates)} beyond 10 cm"
      + (f", {back} back on the map by the end" if handover else ""))
EOF
