#!/usr/bin/env bash
# Does a session that searches the map (started without a pose, never found) slow the other
# sessions of the same server? (docs/benchmarks.md, "A relocalizing neighbour").
#
#   scripts/bench-relocalizing-neighbour.sh --honest DIR --search DIR [--build DIR] [--out DIR]
#        [--sessions N] [--seconds S] [--repeats R] [--rate HZ] [--server-arg FLAG=VALUE ...]
#        [--server-cpus LIST --client-cpus LIST]
#
#   --honest DIR   dataset with gt_map/ whose events N sessions track from their ground-truth pose
#                  at real time (evloc-load), against that map
#   --search DIR   dataset of another scene: one more session streams its events at real time
#                  with no pose (evloc-replay --init-pose none) against the same map, so it
#                  searches for the whole run (the worst case: it is never found)
# Alternates R runs without and R runs with the searching session, S seconds each, and prints
# the honest sessions' server latency and step time (p50 / p99) per run and the medians. The
# server runs at --rate HZ (default 300) with every other option at its default, or as the
# repeatable --server-arg sets it (one word each: --server-arg --search-priority --server-arg idle).
# --server-cpus and --client-cpus (taskset lists, "0" and "1") keep the server and every client on
# CPUs of their own: the nearest this one machine comes to clients on other machines.
set -euo pipefail

BUILD=build
OUT=/tmp/evloc-bench-neighbour
SESSIONS=2
SECONDS_PER_RUN=10
REPEATS=3
RATE=300
SERVER_ARGS=()
HONEST=""
SEARCH=""
SERVER_LAUNCH=()
CLIENT_LAUNCH=()
usage() { sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --build) BUILD="$2"; shift 2 ;;
    --out) OUT="$2"; shift 2 ;;
    --honest) HONEST="$2"; shift 2 ;;
    --search) SEARCH="$2"; shift 2 ;;
    --sessions) SESSIONS="$2"; shift 2 ;;
    --seconds) SECONDS_PER_RUN="$2"; shift 2 ;;
    --repeats) REPEATS="$2"; shift 2 ;;
    --rate) RATE="$2"; shift 2 ;;
    --server-arg) SERVER_ARGS+=("$2"); shift 2 ;;
    --server-arg=*) SERVER_ARGS+=("${1#--server-arg=}"); shift ;;
    --server-cpus) SERVER_LAUNCH=(taskset -c "$2"); shift 2 ;;
    --client-cpus) CLIENT_LAUNCH=(taskset -c "$2"); shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "bench-relocalizing-neighbour: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[[ -n "$HONEST" && -n "$SEARCH" ]] || { usage >&2; exit 2; }
SERVER_BIN="$BUILD/localizer/service/evloc-localizer"
REPLAY_BIN="$BUILD/tools/replay/evloc-replay"
LOAD_BIN="$BUILD/tools/load/evloc-load"
for bin in "$SERVER_BIN" "$REPLAY_BIN" "$LOAD_BIN"; do
  [[ -x "$bin" ]] || { echo "bench-relocalizing-neighbour: $bin is missing; build it" >&2; exit 1; }
done
[[ -f "$HONEST/gt_map/map.evmap" ]] ||
  { echo "bench-relocalizing-neighbour: $HONEST has no gt_map/map.evmap" >&2; exit 1; }

mkdir -p "$OUT/maps"
ln -sfn "$(realpath "$HONEST/gt_map")" "$OUT/maps/honest"
# shellcheck source=scripts/service-lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/service-lib.sh"
start_localizer "$OUT/server.log" "$SERVER_BIN" --maps "$OUT/maps" --max-sessions 16 --rate "$RATE" \
  ${SERVER_ARGS[@]+"${SERVER_ARGS[@]}"}
trap 'kill "$SERVER_PID" 2>/dev/null || true; wait "$SERVER_PID" 2>/dev/null || true' EXIT
ADDRESS="127.0.0.1:$PORT"
echo "bench-relocalizing-neighbour: $(date -u +%FT%TZ), $(nproc) cores, $SESSIONS honest sessions" \
  "of $HONEST, $SECONDS_PER_RUN s per run, $RATE Hz; searching: $SEARCH;" \
  "server on CPUs ${SERVER_LAUNCH[2]:-any}, clients on CPUs ${CLIENT_LAUNCH[2]:-any}"
# Warm-up: the first session loads the map.
${CLIENT_LAUNCH[@]+"${CLIENT_LAUNCH[@]}"} "$LOAD_BIN" --server "$ADDRESS" --map honest --dataset "$HONEST" --sessions 1 --session-s 0.2 \
  --speed max --rate "$RATE" >/dev/null

for ((run = 1; run <= REPEATS; ++run)); do
  for mode in alone neighbour; do
    label="${mode}_$run"
    load=$(cut -d' ' -f1-3 /proc/loadavg)
    searcher=""
    if [[ $mode == neighbour ]]; then
      ${CLIENT_LAUNCH[@]+"${CLIENT_LAUNCH[@]}"} "$REPLAY_BIN" --server "$ADDRESS" --map honest --dataset "$SEARCH" --init-pose none \
        --speed 1 --rate "$RATE" --duration "$SECONDS_PER_RUN" --out "$OUT/$label.search.txt" \
        --report "$OUT/$label.search.json" >"$OUT/$label.search.log" 2>&1 &
      searcher=$!
      sleep 0.5  # the searching session is under way before the honest ones start
    fi
    status=0
    ${CLIENT_LAUNCH[@]+"${CLIENT_LAUNCH[@]}"} "$LOAD_BIN" --server "$ADDRESS" --map honest \
      --dataset "$HONEST" --sessions "$SESSIONS" \
      --session-s "$SECONDS_PER_RUN" --speed 1 --rate "$RATE" --report "$OUT/$label.json" \
      >"$OUT/$label.log" 2>&1 || status=$?
    search_status=""
    if [[ -n "$searcher" ]]; then
      wait "$searcher" && search_status=0 || search_status=$?
    fi
    /usr/bin/python3 - "$OUT" "$label" "$load" "$status" "$search_status" <<'PYTHON'
import json, os, sys
out, label, load, status, search_status = sys.argv[1:6]
r = json.load(open(f"{out}/{label}.json"))
line = (f"{label:12} honest: ok {r['sessions_as_planned']}/{r['sessions_opened']} (exit {status}), "
        f"backpressure {r['backpressure_notices']}, server latency p50/p99 "
        f"{r['server_latency_us']['p50'] / 1e3:.2f}/{r['server_latency_us']['p99'] / 1e3:.2f} ms, "
        f"step p50/p99 {r['step_ms']['p50']:.2f}/{r['step_ms']['p99']:.2f} ms")
search = f"{out}/{label}.search.json"
if os.path.exists(search):
    s = json.load(open(search))
    line += (f"; searching session (exit {search_status}): {s['searching_updates']} updates, "
             f"TRACKING {s['first_tracking_s']}, its step p50 {s['step_p50_ms']:.1f} ms, "
             f"sent {s['events_sent']} events, thinned {s.get('events_thinned', 0)}, "
             f"packets shed by the server {s.get('packets_shed', 0)}")
elif search_status:
    line += f"; searching session failed (exit {search_status}, see {label}.search.log)"
print(line + f" (load {load})")
PYTHON
  done
done
/usr/bin/python3 - "$OUT" "$REPEATS" <<'PYTHON'
import json, statistics, sys
out, repeats = sys.argv[1], int(sys.argv[2])
def median(mode, key, percentile):
    return statistics.median(json.load(open(f"{out}/{mode}_{run}.json"))[key][percentile]
                             for run in range(1, repeats + 1))
for key, scale, unit in (("server_latency_us", 1e-3, "ms"), ("step_ms", 1, "ms")):
    alone, neighbour = (median(m, key, "p99") * scale for m in ("alone", "neighbour"))
    print(f"median over {repeats} runs, honest {key} p99: alone {alone:.2f} {unit}, with a "
          f"searching neighbour {neighbour:.2f} {unit}: {neighbour / alone:.2f}x")
PYTHON
