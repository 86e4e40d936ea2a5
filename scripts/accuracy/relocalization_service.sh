#!/usr/bin/env bash
# Relocalization through the service: a client that starts without a pose and streams a dataset
# at real time (evloc-replay --init-pose none), found by the server's search and then tracked.
# Prints, per run, when the first TRACKING pose came, what the server shed, and the trajectory's
# error against the ground truth (evloc-eval, no alignment). docs/accuracy.md, "Relocalization
# through the service".
#
# Usage: scripts/accuracy/relocalization_service.sh BUILD MAP_DIR DATASET OUT [RUNS] [REPLAY_ARGS...]
#   BUILD    the build folder (evloc-localizer, evloc-replay, evloc-eval)
#   MAP_DIR  a folder with map.evmap (scripts/accuracy/relocalization.sh makes OUT/map_known)
#   DATASET  an evloc dataset folder with groundtruth.txt (OUT/evseq of the same script)
#   OUT      where the runs' trajectories, reports and logs go
#   RUNS     how many runs (default 4)
#   REPLAY_ARGS  passed to evloc-replay, e.g. --thin-while-searching off
# SERVER_CPUS / CLIENT_CPUS (taskset lists, default: none) pin the server and the client.
set -euo pipefail
if [ $# -lt 4 ]; then sed -n 2,17p "$0"; exit 2; fi
BUILD=$(realpath "$1"); MAP_DIR=$(realpath "$2"); DATASET=$(realpath "$3"); OUT=$4
RUNS=${5:-4}
shift $(( $# < 5 ? $# : 5 ))
HERE=$(cd "$(dirname "$0")/.." && pwd)
# shellcheck source=../service-lib.sh
source "$HERE/service-lib.sh"
LOCALIZER=$BUILD/localizer/service/evloc-localizer
REPLAY=$BUILD/tools/replay/evloc-replay
EVAL=$BUILD/tools/eval/evloc-eval
for tool in "$LOCALIZER" "$REPLAY" "$EVAL"; do
  [ -x "$tool" ] || { echo "relocalization_service: $tool is missing; build it first" >&2; exit 1; }
done
[ -f "$MAP_DIR/map.evmap" ] || { echo "relocalization_service: no $MAP_DIR/map.evmap" >&2; exit 1; }
[ -f "$DATASET/groundtruth.txt" ] ||
  { echo "relocalization_service: no $DATASET/groundtruth.txt" >&2; exit 1; }
mkdir -p "$OUT/maps"
ln -sfn "$MAP_DIR" "$OUT/maps/map"
SERVER_LAUNCH=()
CLIENT_LAUNCH=()
[ -n "${SERVER_CPUS:-}" ] && SERVER_LAUNCH=(taskset -c "$SERVER_CPUS")
[ -n "${CLIENT_CPUS:-}" ] && CLIENT_LAUNCH=(taskset -c "$CLIENT_CPUS")
echo "relocalization_service: $(date -u +%FT%TZ), $(nproc) cores, $RUNS runs of $DATASET," \
  "replay args: ${*:-none}; load $(cut -d' ' -f1-3 /proc/loadavg)"
for run in $(seq "$RUNS"); do
  start_localizer "$OUT/server_$run.log" "$LOCALIZER" --maps "$OUT/maps"
  status=0
  ${CLIENT_LAUNCH[@]+"${CLIENT_LAUNCH[@]}"} "$REPLAY" --server "127.0.0.1:$PORT" --map map \
    --dataset "$DATASET" --out "$OUT/run_$run.txt" --init-pose none \
    --report "$OUT/run_$run.json" "$@" > "$OUT/replay_$run.log" 2>&1 || status=$?
  kill "$SERVER_PID"; wait "$SERVER_PID" 2>/dev/null || true
  summary=$(/usr/bin/python3 - "$OUT/run_$run.json" "$status" "$OUT/replay_$run.log" <<'EOF'
import json, sys
path, status, log = sys.argv[1], int(sys.argv[2]), sys.argv[3]
try:
    r = json.load(open(path))
except (OSError, ValueError):
    error = [l.strip() for l in open(log) if "error" in l]
    print(json.dumps({"exit": status, "error": error[-1] if error else "no report"}))
    sys.exit()
print(json.dumps({"exit": status, "first_tracking_s": r.get("first_tracking_s"),
                  "poses": r["poses"], "searching_updates": r["searching_updates"],
                  "packets_shed": r["packets_shed"], "events_thinned": r["events_thinned"]}))
EOF
)
  errors="{}"
  if [ -s "$OUT/run_$run.txt" ] && grep -qv '^#' "$OUT/run_$run.txt"; then
    "$EVAL" --gt "$DATASET/groundtruth.txt" --est "$OUT/run_$run.txt" --fail-cm 5 \
      --json "$OUT/eval_$run.json" > /dev/null && errors=$(cat "$OUT/eval_$run.json")
  fi
  /usr/bin/python3 - "$run" "$summary" "$errors" <<'EOF'
import json, sys
run, summary, errors = sys.argv[1], json.loads(sys.argv[2]), json.loads(sys.argv[3])
# failed_at_s: the first TRACKING pose farther than 5 cm from the truth (null: none).
keep = {k: errors[k] for k in ("ate_t_rmse_cm", "ate_t_max_cm", "ate_r_rmse_deg", "failed_at_s")
        if k in errors}
print(json.dumps({"run": int(run), **summary, **keep}))
EOF
done
echo "relocalization_service: done; load $(cut -d' ' -f1-3 /proc/loadavg)"
