#!/usr/bin/env bash
# Serving a site of tiles against serving the whole map (docs/benchmarks.md, "Sites"):
#
#   scripts/bench-site.sh --maps DIR --dataset DIR [--build DIR] [--out DIR] [--sessions N]
#                         [--spread CxR:P | --stagger N:S] [--session-s S] [--duration S]
#                         [--rate HZ] [--speed S] [--map-memory SIZE] [--server-args "ARGS"]
#                         [--load-args "ARGS"] [--taskset CPUS]
#
# DIR (--maps) holds `whole` (a map) and `site` (the same map tiled), e.g. as written by
# build/bench/evloc_replicated_site. For each of the two, starts evloc-localizer on 127.0.0.1
# with --map-memory SIZE and a metrics endpoint, runs evloc-load with N sessions spread over the
# copies of the dataset's scene (--spread), or along a long dataset (--stagger: the k-th session
# starts (k mod N) * S seconds into it), at real time (or --speed) for --duration seconds, and
# writes the load report (server latency p50/p95/p99, step time p50/p99, the TRACKING poses'
# error against the ground truth) and the final metrics (tile loads,
# evictions, resident bytes) to OUT/{whole,site}.{json,metrics}, and one summary line per run to
# OUT/summary.txt. --server-args go to evloc-localizer serve, --load-args to evloc-load (e.g.
# "--initial-velocity truth"). Prints `uptime` before each run: the figures need a quiet machine.
set -euo pipefail
BUILD=build
MAPS=""
DATASET=""
OUT=/tmp/evloc-bench-site
SESSIONS=20
SPREAD="8x8:5"
STAGGER=""
SPEED=1
SESSION_S=3
DURATION=30
RATE=100
MAP_MEMORY=2G
SERVER_ARGS=""
LOAD_ARGS=""
TASKSET=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --build) BUILD="$2"; shift 2 ;;
    --maps) MAPS="$2"; shift 2 ;;
    --dataset) DATASET="$2"; shift 2 ;;
    --out) OUT="$2"; shift 2 ;;
    --sessions) SESSIONS="$2"; shift 2 ;;
    --spread) SPREAD="$2"; shift 2 ;;
    --stagger) STAGGER="$2"; shift 2 ;;
    --speed) SPEED="$2"; shift 2 ;;
    --session-s) SESSION_S="$2"; shift 2 ;;
    --duration) DURATION="$2"; shift 2 ;;
    --rate) RATE="$2"; shift 2 ;;
    --map-memory) MAP_MEMORY="$2"; shift 2 ;;
    --server-args) SERVER_ARGS="$2"; shift 2 ;;
    --load-args) LOAD_ARGS="$2"; shift 2 ;;
    --taskset) TASKSET="$2"; shift 2 ;;
    -h|--help) sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "bench-site: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
if [[ -z "$MAPS" || -z "$DATASET" ]]; then
  echo "bench-site: --maps and --dataset are required (see --help)" >&2
  exit 2
fi
for name in whole site; do
  if [[ ! -d "$MAPS/$name" ]]; then
    echo "bench-site: $MAPS/$name is missing (make it with build/bench/evloc_replicated_site)" >&2
    exit 2
  fi
done
mkdir -p "$OUT"
: > "$OUT/summary.txt"
PLACES=(--spread "$SPREAD")
if [[ -n "$STAGGER" ]]; then PLACES=(--stagger "$STAGGER"); fi
PINNED=()
if [[ -n "$TASKSET" ]]; then PINNED=(taskset -c "$TASKSET"); fi

free_port() { /usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

for name in whole site; do
  port=$(free_port)
  metrics_port=$(free_port)
  # shellcheck disable=SC2086
  "${PINNED[@]}" "$BUILD/localizer/service/evloc-localizer" serve --maps "$MAPS" \
    --listen "127.0.0.1:$port" --metrics "127.0.0.1:$metrics_port" --map-memory "$MAP_MEMORY" \
    --max-sessions $((SESSIONS + 4)) $SERVER_ARGS > "$OUT/$name.server.log" 2>&1 &
  server=$!
  for _ in $(seq 100); do
    if "$BUILD/tools/replay/evloc-replay" --server "127.0.0.1:$port" --health-check \
         > /dev/null 2>&1; then break; fi
    sleep 0.2
  done
  echo "bench-site: $name: $(uptime)" | tee -a "$OUT/summary.txt"
  status=0
  # shellcheck disable=SC2086
  "$BUILD/tools/load/evloc-load" --server "127.0.0.1:$port" --map "$name" --dataset "$DATASET" \
    --sessions "$SESSIONS" "${PLACES[@]}" --session-s "$SESSION_S" --duration "$DURATION" \
    --rate "$RATE" --speed "$SPEED" --report "$OUT/$name.json" $LOAD_ARGS \
    > "$OUT/$name.load.txt" 2>&1 || status=$?
  /usr/bin/python3 -c "import urllib.request,sys; sys.stdout.write(urllib.request.urlopen('http://127.0.0.1:$metrics_port/metrics').read().decode())" > "$OUT/$name.metrics" || true
  kill "$server"
  wait "$server" || true
  /usr/bin/python3 - "$OUT/$name.json" "$OUT/$name.metrics" "$name" "$status" >> "$OUT/summary.txt" <<'PY'
import json, sys
report = json.load(open(sys.argv[1]))
metrics = {}
for line in open(sys.argv[2]):
    if line.startswith("evloc_tile_") or line.startswith("evloc_lost_poses_total"):
        key, value = line.split()
        metrics[key] = float(value)
print(sys.argv[3], "load-exit", sys.argv[4], json.dumps({k: report[k] for k in report
      if k in ("sessions", "sessions_as_planned", "poses", "backpressure_notices",
               "server_latency_us", "step_ms", "error_m", "wall_s")}), json.dumps(metrics))
PY
done
cat "$OUT/summary.txt"
