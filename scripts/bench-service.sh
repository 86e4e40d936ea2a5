#!/usr/bin/env bash
# Latency and capacity of the localizer service on loopback (docs/benchmarks.md §4).
#
#   scripts/bench-service.sh [--build DIR] [--dataset DIR] [--out DIR] [--latency-s S]
#                            [--capacity "1 2 3 4"] [--capacity-s S] [--server-args "ARGS"]
#                            [--taskset CPUS] [--capacity-speed S|max] [--skip-latency]
#                            [--rate HZ] [--viewer-clients N] [--viewer-rate HZ]
#                            [--client-taskset CPUS] [--packet-us N]
#
# Starts evloc-localizer on 127.0.0.1 (any free port) with the dataset's ground-truth map, then
#  (a) latency: one evloc-replay session at real time (300 Hz, PACKED 1 ms packets) for
#      --latency-s seconds: server latency (packet received -> pose handed to gRPC) and client
#      latency (packet sent -> pose received), p50 / p99;
#  (b) capacity: for each N of --capacity, N concurrent real-time sessions (evloc-load) of
#      --capacity-s seconds each. A run keeps up when every session ends OK with no Backpressure
#      notice and the server latency p99 stays below 100 ms (the queue does not grow).
#      The capacity curve (sessions, kept up, server latency p50/p99, server CPU in cores, the
#      server's thread count) goes to OUT/capacity.csv and, with python3-matplotlib, to
#      OUT/capacity.png (scripts/plot-capacity.py).
# --server-args passes more options to `evloc-localizer serve` (e.g. "--max-points 500");
# --taskset pins the server to CPUS (taskset -c; default: not pinned). --capacity-speed max
# streams the capacity runs as fast as the server confirms (evloc-load --speed max): then the
# figure is the server's CPU per session-second of events (cpu_per_session_s in capacity.csv),
# which other jobs on the machine change far less than the wall-clock latency. --skip-latency
# leaves out (a). --rate sets the sessions' step rate (default 300). --viewer-clients N serves the
# live viewer (--viewer) and keeps N pages' event streams open during the runs (curl reading
# /api/events at --viewer-rate, default 30 Hz): the viewer's cost shows as the difference with a
# run without it; the events each page received per second go to the summary. --client-taskset
# pins evloc-load, evloc-replay and the viewer clients (taskset -c). --packet-us sets the capacity
# runs' packet window (default 1000).
# Every figure also goes to OUT (JSON per run, server log, summary.txt). Wall-clock figures need
# an otherwise idle machine; the script prints the load average before each run.
set -euo pipefail

BUILD=build
DATASET=/work/data/sim/mid10
OUT=/tmp/evloc-bench-service
LATENCY_S=10
CAPACITY="1 2 3 4 6"
CAPACITY_S=10
RATE=300
SERVER_ARGS=""
TASKSET=""
CAPACITY_SPEED=1
SKIP_LATENCY=0
VIEWER_CLIENTS=0
VIEWER_RATE=30
CLIENT_TASKSET=""
PACKET_US=1000

usage() { sed -n '2,28p' "$0" | sed 's/^# \{0,1\}//'; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --build) BUILD="$2"; shift 2 ;;
    --dataset) DATASET="$2"; shift 2 ;;
    --out) OUT="$2"; shift 2 ;;
    --latency-s) LATENCY_S="$2"; shift 2 ;;
    --capacity) CAPACITY="$2"; shift 2 ;;
    --capacity-s) CAPACITY_S="$2"; shift 2 ;;
    --server-args) SERVER_ARGS="$2"; shift 2 ;;
    --taskset) TASKSET="$2"; shift 2 ;;
    --capacity-speed) CAPACITY_SPEED="$2"; shift 2 ;;
    --skip-latency) SKIP_LATENCY=1; shift ;;
    --rate) RATE="$2"; shift 2 ;;
    --viewer-clients) VIEWER_CLIENTS="$2"; shift 2 ;;
    --viewer-rate) VIEWER_RATE="$2"; shift 2 ;;
    --client-taskset) CLIENT_TASKSET="$2"; shift 2 ;;
    --packet-us) PACKET_US="$2"; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "bench-service: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done

SERVER_BIN="$BUILD/localizer/service/evloc-localizer"
REPLAY_BIN="$BUILD/tools/replay/evloc-replay"
LOAD_BIN="$BUILD/tools/load/evloc-load"
for bin in "$SERVER_BIN" "$REPLAY_BIN" "$LOAD_BIN"; do
  [[ -x "$bin" ]] || { echo "bench-service: $bin is missing: cmake --build $BUILD --target evloc-localizer evloc-replay evloc-load" >&2; exit 1; }
done
[[ -f "$DATASET/gt_map/map.evmap" ]] || { echo "bench-service: $DATASET has no gt_map/map.evmap (render one with evloc-sim render)" >&2; exit 1; }

mkdir -p "$OUT/maps"
ln -sfn "$(realpath "$DATASET/gt_map")" "$OUT/maps/bench"
SUMMARY="$OUT/summary.txt"
: > "$SUMMARY"
say() { echo "$*" | tee -a "$SUMMARY"; }

SERVER_LOG="$OUT/server.log"
# shellcheck source=scripts/service-lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/service-lib.sh"
VIEWER_ARGS=()
(( VIEWER_CLIENTS > 0 )) && VIEWER_ARGS=(--viewer 127.0.0.1:0 --viewer-max-clients "$VIEWER_CLIENTS")
# shellcheck disable=SC2086  # SERVER_ARGS is a list of options
start_localizer "$SERVER_LOG" "$SERVER_BIN" --maps "$OUT/maps" --max-sessions 64 --rate "$RATE" \
  "${VIEWER_ARGS[@]}" $SERVER_ARGS
# Every thread of the server (threads created later inherit it).
[[ -n "$TASKSET" ]] && taskset -a -p -c "$TASKSET" "$SERVER_PID" > /dev/null
trap 'kill "$SERVER_PID" 2>/dev/null || true; wait "$SERVER_PID" 2>/dev/null || true' EXIT
ADDRESS="127.0.0.1:$PORT"
# The clients (evloc-load, evloc-replay, viewer pages), pinned when asked.
CLIENT_PREFIX=()
[[ -n "$CLIENT_TASKSET" ]] && CLIENT_PREFIX=(taskset -c "$CLIENT_TASKSET")
LOAD_BIN=("${CLIENT_PREFIX[@]}" "$LOAD_BIN")
REPLAY_BIN=("${CLIENT_PREFIX[@]}" "$REPLAY_BIN")
VIEWER_PIDS=()
if (( VIEWER_CLIENTS > 0 )); then
  VIEWER_URL=$(sed -n 's|^evloc-localizer: viewer: \(http://[0-9.:]*/\)$|\1|p' "$SERVER_LOG")
  [[ -n "$VIEWER_URL" ]] || { echo "bench-service: the server printed no viewer address" >&2; exit 1; }
  command -v curl >/dev/null || { echo "bench-service: --viewer-clients needs curl" >&2; exit 1; }
  VIEWER_START=$(date +%s.%N)
  for i in $(seq "$VIEWER_CLIENTS"); do
    "${CLIENT_PREFIX[@]}" curl -sN "${VIEWER_URL}api/events?rate=$VIEWER_RATE" \
      > "$OUT/viewer_$i.sse" 2>/dev/null &
    VIEWER_PIDS+=($!)
  done
fi
stop_viewers() {
  for pid in "${VIEWER_PIDS[@]}"; do kill "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; done
  VIEWER_PIDS=()
}
trap 'stop_viewers; kill "$SERVER_PID" 2>/dev/null || true; wait "$SERVER_PID" 2>/dev/null || true' EXIT

# CPU seconds (user + system) the server has used so far.
server_cpu() { awk -v hz="$(getconf CLK_TCK)" '{print ($14 + $15) / hz}' "/proc/$SERVER_PID/stat"; }
minus() { awk -v a="$1" -v b="$2" 'BEGIN { print a - b }'; }

say "bench-service: $(date -u +%FT%TZ) on $(nproc) cores, server $ADDRESS, dataset $DATASET, $RATE Hz${SERVER_ARGS:+, server options $SERVER_ARGS}${TASKSET:+, server on CPUs $TASKSET}"
# The server's threads now.
server_threads() { awk '/^Threads:/ {print $2}' "/proc/$SERVER_PID/status"; }

# Warm-up: loads the map (a first session pays it) so that it does not count in the figures.
"${LOAD_BIN[@]}" --server "$ADDRESS" --map bench --dataset "$DATASET" --sessions 1 --session-s 0.2 \
  --speed max --rate "$RATE" > "$OUT/warmup.txt"

if (( ! SKIP_LATENCY )); then
say "(a) latency: one real-time session, ${LATENCY_S} s; load average: $(cut -d' ' -f1-3 /proc/loadavg)"
cpu_before=$(server_cpu)
"${REPLAY_BIN[@]}" --server "$ADDRESS" --map bench --dataset "$DATASET" --out "$OUT/latency_traj.txt" \
  --speed 1 --rate "$RATE" --packet-us 1000 --duration "$LATENCY_S" --report "$OUT/latency.json" \
  > "$OUT/latency.txt" 2>&1 || say "  the session did not keep up (a figure too): $(tail -1 "$OUT/latency.txt")"
cpu_after=$(server_cpu)
grep -E "latency|sent" "$OUT/latency.txt" | tee -a "$SUMMARY" || true
grep "session 2 end" "$SERVER_LOG" | sed 's/^evloc-localizer: /  server: /' | tee -a "$SUMMARY" || true
say "  server CPU: $(minus "$cpu_after" "$cpu_before") s for ${LATENCY_S} s of events"
fi

say "(b) capacity: N concurrent sessions of ${CAPACITY_S} s at speed $CAPACITY_SPEED"
echo "sessions,kept_up,server_p50_us,server_p99_us,client_p99_us,step_p50_ms,step_p99_ms,server_cpu_s,wall_s,server_cores,server_threads,load1,cpu_per_session_s" > "$OUT/capacity.csv"
for sessions in $CAPACITY; do
  load=$(cut -d' ' -f1-3 /proc/loadavg)
  cpu_before=$(server_cpu)
  "${LOAD_BIN[@]}" --server "$ADDRESS" --map bench --dataset "$DATASET" --sessions "$sessions" \
    --session-s "$CAPACITY_S" --speed "$CAPACITY_SPEED" --rate "$RATE" --packet-us "$PACKET_US" \
    --report "$OUT/capacity_$sessions.json" > "$OUT/capacity_$sessions.txt" 2>&1 &
  load_pid=$!
  # The most threads the server had while the sessions ran (sampled every 0.5 s).
  threads=$(server_threads)
  while kill -0 "$load_pid" 2>/dev/null; do
    now=$(server_threads)
    (( now > threads )) && threads=$now
    sleep 0.5
  done
  wait "$load_pid" || true  # A run that falls behind is a figure too.
  cpu_after=$(server_cpu)
  python3 - "$OUT/capacity_$sessions.json" "$sessions" "$load" \
    "$(minus "$cpu_after" "$cpu_before")" "$threads" "$OUT/capacity.csv" "$CAPACITY_S" \
    <<'EOF' | tee -a "$SUMMARY"
import json, sys
r = json.load(open(sys.argv[1]))
keeps = (r["sessions_as_planned"] == r["sessions_opened"] and r["backpressure_notices"] == 0
         and r["server_latency_us"]["p99"] < 100e3)
cpu = float(sys.argv[4])
with open(sys.argv[6], "a") as csv:
    csv.write(f"{sys.argv[2]},{int(keeps)},{r['server_latency_us']['p50']:.0f},"
              f"{r['server_latency_us']['p99']:.0f},{r['client_latency_us']['p99']:.0f},"
              f"{r['step_ms']['p50']:.3f},{r['step_ms']['p99']:.3f},{cpu:.2f},{r['wall_s']:.2f},"
              f"{cpu / r['wall_s'] if r['wall_s'] > 0 else 0:.2f},{sys.argv[5]},"
              f"{sys.argv[3].split()[0]},"
              f"{cpu / (int(sys.argv[2]) * float(sys.argv[7])):.3f}\n")
unplanned = ", ".join(f"{v} {k}" for k, v in r["unplanned"].items()) or "none"
print(f"  N={sys.argv[2]}: {'keeps up' if keeps else 'falls behind'}; ok {r['sessions_as_planned']}/"
      f"{r['sessions_opened']}, unplanned: {unplanned}, backpressure {r['backpressure_notices']}, "
      f"server latency p50/p99/max {r['server_latency_us']['p50']:.0f}/"
      f"{r['server_latency_us']['p99']:.0f}/{r['server_latency_us']['max']:.0f} us, client p99 "
      f"{r['client_latency_us']['p99']:.0f} us, step p50/p99 {r['step_ms']['p50']:.2f}/"
      f"{r['step_ms']['p99']:.2f} ms, server CPU {float(sys.argv[4]):.1f} s in {r['wall_s']:.1f} s "
      f"(load {sys.argv[3]}), server threads {sys.argv[5]}, server CPU per session-second "
      f"{cpu / (int(sys.argv[2]) * float(sys.argv[7])):.3f} s")
EOF
done
if /usr/bin/python3 -c "import matplotlib" 2>/dev/null; then
  /usr/bin/python3 "$(dirname "${BASH_SOURCE[0]}")/plot-capacity.py" --out "$OUT/capacity.png" \
    "$OUT/capacity.csv" && say "capacity curve: $OUT/capacity.csv, $OUT/capacity.png"
else
  say "capacity curve: $OUT/capacity.csv (no plot: python3-matplotlib is missing, scripts/install-deps.sh)"
fi
if (( VIEWER_CLIENTS > 0 )); then
  viewer_s=$(minus "$(date +%s.%N)" "$VIEWER_START")
  stop_viewers
  for i in $(seq "$VIEWER_CLIENTS"); do
    events=$(grep -c '^event: poses' "$OUT/viewer_$i.sse" || true)
    poses=$(grep -o '"position"' "$OUT/viewer_$i.sse" | wc -l)
    say "  viewer page $i: $events events ($(awk -v e="$events" -v s="$viewer_s" 'BEGIN {printf "%.1f", e / s}') /s), $poses session poses in ${viewer_s%.*} s"
  done
fi
say "bench-service: figures in $OUT"
