#!/usr/bin/env bash
# Soak test of the localizer service (docs/reliability.md §4): SESSIONS session slots open and
# close sessions for MINUTES against a server built with AddressSanitizer + LeakSanitizer +
# UndefinedBehaviorSanitizer, while the server's resident memory is sampled every INTERVAL
# seconds from /proc. Passes when every session ends as planned, the server exits cleanly on
# SIGTERM with no sanitizer report (LeakSanitizer checks at exit), and memory is flat.
#
#   scripts/soak-service.sh [--asan-build DIR] [--client-build DIR] [--dataset DIR] [--out DIR]
#                           [--sessions 32] [--minutes 10] [--session-s 0.3] [--interval 10]
#
# The sanitizer build (once):
#   cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DEVLOC_SANITIZE=ON
#   cmake --build build-asan --target evloc-localizer
# Sessions stream --session-s seconds of the dataset as fast as the server confirms them; 10 %
# are cancelled by the client at a random packet (a vanished client) and 10 % send an event
# outside the sensor (INVALID_ARGUMENT). RSS samples go to OUT/rss.csv (seconds, kB).
set -euo pipefail

ASAN_BUILD=build-asan
CLIENT_BUILD=build
DATASET=/work/data/sim/mid10
OUT=/tmp/evloc-soak-service
SESSIONS=32
MINUTES=10
SESSION_S=0.3
INTERVAL=10

usage() { sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --asan-build) ASAN_BUILD="$2"; shift 2 ;;
    --client-build) CLIENT_BUILD="$2"; shift 2 ;;
    --dataset) DATASET="$2"; shift 2 ;;
    --out) OUT="$2"; shift 2 ;;
    --sessions) SESSIONS="$2"; shift 2 ;;
    --minutes) MINUTES="$2"; shift 2 ;;
    --session-s) SESSION_S="$2"; shift 2 ;;
    --interval) INTERVAL="$2"; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "soak-service: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done

SERVER_BIN="$ASAN_BUILD/localizer/service/evloc-localizer"
LOAD_BIN="$CLIENT_BUILD/tools/load/evloc-load"
[[ -x "$SERVER_BIN" ]] || { echo "soak-service: $SERVER_BIN is missing (see --help for the sanitizer build)" >&2; exit 1; }
grep -q "__asan_init" "$SERVER_BIN" ||
  { echo "soak-service: $SERVER_BIN is not built with AddressSanitizer (-DEVLOC_SANITIZE=ON)" >&2; exit 1; }
[[ -x "$LOAD_BIN" ]] || { echo "soak-service: $LOAD_BIN is missing: cmake --build $CLIENT_BUILD --target evloc-load" >&2; exit 1; }
[[ -f "$DATASET/gt_map/map.evmap" ]] || { echo "soak-service: $DATASET has no gt_map/map.evmap" >&2; exit 1; }

mkdir -p "$OUT/maps"
ln -sfn "$(realpath "$DATASET/gt_map")" "$OUT/maps/soak"
SERVER_LOG="$OUT/server.log"
RSS_CSV="$OUT/rss.csv"

# shellcheck source=scripts/service-lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/service-lib.sh"
# halt_on_error: any sanitizer finding stops the server (and fails the soak); detect_leaks:
# LeakSanitizer reports at exit.
export ASAN_OPTIONS="detect_leaks=1:halt_on_error=1:abort_on_error=0:exitcode=23"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1:exitcode=24"
start_localizer "$SERVER_LOG" "$SERVER_BIN" --maps "$OUT/maps" \
  --max-sessions "$(( SESSIONS * 2 ))" --idle-timeout 60
unset ASAN_OPTIONS UBSAN_OPTIONS

START=$(date +%s)
echo "seconds,rss_kb" > "$RSS_CSV"
(
  while kill -0 "$SERVER_PID" 2>/dev/null; do
    rss=$(awk '/^VmRSS:/ {print $2}' "/proc/$SERVER_PID/status" 2>/dev/null || true)
    [[ -n "$rss" ]] && echo "$(( $(date +%s) - START )),$rss" >> "$RSS_CSV"
    sleep "$INTERVAL"
  done
) &
SAMPLER_PID=$!

echo "soak-service: $SESSIONS slots for $MINUTES min against $SERVER_BIN (pid $SERVER_PID, port $PORT)"
load_status=0
"$LOAD_BIN" --server "127.0.0.1:$PORT" --map soak --dataset "$DATASET" --sessions "$SESSIONS" \
  --session-s "$SESSION_S" --duration "$(( MINUTES * 60 ))" --speed max \
  --cancel-fraction 0.1 --bad-fraction 0.1 --report "$OUT/load.json" \
  > "$OUT/load.txt" 2>&1 || load_status=$?
cat "$OUT/load.txt"
# One idle sample after the load, then stop the server; LeakSanitizer runs at its exit.
sleep "$INTERVAL"
echo "$(( $(date +%s) - START )),$(awk '/^VmRSS:/ {print $2}' "/proc/$SERVER_PID/status")" >> "$RSS_CSV"
kill -TERM "$SERVER_PID"
server_status=0
wait "$SERVER_PID" || server_status=$?
kill "$SAMPLER_PID" 2>/dev/null || true
wait "$SAMPLER_PID" 2>/dev/null || true

sanitizer_reports=$(grep -c -E "ERROR: (AddressSanitizer|LeakSanitizer)|runtime error:" "$SERVER_LOG" || true)
python3 - "$RSS_CSV" <<'EOF'
import csv, sys
rows = [(int(r["seconds"]), int(r["rss_kb"])) for r in csv.DictReader(open(sys.argv[1]))]
loaded = rows[1:-1] or rows  # the first sample is before any session; the last after the load
first, last, peak = loaded[0], loaded[-1], max(loaded, key=lambda r: r[1])
print(f"soak-service: RSS under load: first {first[1] / 1024:.0f} MiB at {first[0]} s, "
      f"last {last[1] / 1024:.0f} MiB at {last[0]} s, max {peak[1] / 1024:.0f} MiB at {peak[0]} s; "
      f"before the load {rows[0][1] / 1024:.0f} MiB, idle after it {rows[-1][1] / 1024:.0f} MiB "
      f"({len(rows)} samples)")
EOF
echo "soak-service: evloc-load exit $load_status, server exit $server_status, sanitizer reports: $sanitizer_reports"
grep -E "session [0-9]+ end" "$SERVER_LOG" | sed 's/.*end: \([A-Za-z ]*\).*/\1/' | cut -c1-40 | sort | uniq -c | sort -rn | head -8
if [[ $load_status -ne 0 || $server_status -ne 0 || $sanitizer_reports -ne 0 ]]; then
  echo "soak-service: FAILED (see $SERVER_LOG and $OUT/load.txt)"
  exit 1
fi
echo "soak-service: passed; figures in $OUT"
