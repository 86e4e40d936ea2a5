#!/usr/bin/env bash
# Attack suite of the localizer service (docs/reliability.md, "Attack suite"; issue 14): a real
# `evloc-localizer serve` on 127.0.0.1 with a small rendered map, 4 honest real-time evloc-replay
# sessions, and one attack per finding of issue 14 while they track (scripts/attack_service.py).
# Prints a table, one row per attack and per check (honest poses bit-identical to an undisturbed
# run, honest p99 latency within 2x, server RSS within the budget, the status each attacking
# stream ends with), and exits 1 when any row fails. Only 127.0.0.1; about 2-3 minutes.
#
#   scripts/attack-service.sh [--build DIR] [--dataset DIR] [--out DIR] [--duration S]
#                             [--rss-budget-mib N] [--only 1,2,...] [--server-arg ARG]...
#
#   --build DIR          build folder with evloc-localizer, evloc-replay, evloc-sim (default build)
#   --dataset DIR        dataset with groundtruth.txt, events.evb, calib.yaml, gt_map/map.evmap
#                        (default: render DURATION s of the 'mid' motion with the 240x180 davis240
#                        camera into OUT/dataset, kept for later runs)
#   --out DIR            output folder (default /tmp/evloc-attack-service); OUT/run is replaced
#   --duration S         length of the rendered dataset, seconds (default 2)
#   --rss-budget-mib N   the server's memory budget; its RSS must stay below (default 512)
#   --only LIST          run only these attacks (ids 1,2,3,5,6,7,8,9,11,13)
#   --server-arg ARG     extra argument of `evloc-localizer serve` (repeatable), e.g. a memory
#                        budget flag matching --rss-budget-mib
# Exit status: 0 every check passed, 1 a check failed, 2 bad usage, 77 skipped (python3-grpcio,
# protoc or grpc_python_plugin missing, or a binary not built).
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD="$ROOT/build"
DATASET=""
OUT=/tmp/evloc-attack-service
DURATION=2
RSS_BUDGET_MIB=512
ONLY=""
SERVER_ARGS=()
PYTHON=/usr/bin/python3

usage() { sed -n '2,23p' "$0" | sed 's/^# \{0,1\}//'; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --build) BUILD=$2; shift 2 ;;
    --dataset) DATASET=$2; shift 2 ;;
    --out) OUT=$2; shift 2 ;;
    --duration) DURATION=$2; shift 2 ;;
    --rss-budget-mib) RSS_BUDGET_MIB=$2; shift 2 ;;
    --only) ONLY=$2; shift 2 ;;
    --server-arg) SERVER_ARGS+=("--server-arg=$2"); shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "attack-service: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done

# The server's own memory budget (--max-memory: queued decoded events and gRPC's buffers) is half
# the RSS budget unless given: the rest holds the code, the map and the sessions' trackers.
if [[ " ${SERVER_ARGS[*]-} " != *"--server-arg=--max-memory"* ]]; then
  SERVER_ARGS+=("--server-arg=--max-memory" "--server-arg=$((RSS_BUDGET_MIB * 1048576 / 2))")
fi

LOCALIZER="$BUILD/localizer/service/evloc-localizer"
REPLAY="$BUILD/tools/replay/evloc-replay"
SIM="$BUILD/tools/sim/evloc-sim"
for binary in "$LOCALIZER" "$REPLAY"; do
  [[ -x "$binary" ]] || { echo "attack-service: SKIPPED: $binary is not built" >&2; exit 77; }
done
"$PYTHON" -c 'import grpc, google.protobuf' 2>/dev/null ||
  { echo "attack-service: SKIPPED: $PYTHON lacks grpcio or protobuf (Debian: python3-grpcio python3-protobuf)" >&2; exit 77; }
PLUGIN=$(command -v grpc_python_plugin || echo /usr/bin/grpc_python_plugin)
if ! command -v protoc >/dev/null 2>&1 || [[ ! -x "$PLUGIN" ]]; then
  echo "attack-service: SKIPPED: protoc or grpc_python_plugin missing (Debian: protobuf-compiler protobuf-compiler-grpc)" >&2
  exit 77
fi

mkdir -p "$OUT"
if [[ -z "$DATASET" ]]; then
  DATASET="$OUT/dataset"
  if [[ ! -f "$DATASET/gt_map/map.evmap" ]]; then
    [[ -x "$SIM" ]] || { echo "attack-service: SKIPPED: $SIM is not built (or pass --dataset)" >&2; exit 77; }
    echo "attack-service: rendering a ${DURATION} s dataset (240x180) into $DATASET"
    nice -n 10 "$SIM" render --out "$DATASET" --camera davis240 --motion mid \
      --duration "$DURATION" --force > "$OUT/render.log" 2>&1 ||
      { echo "attack-service: evloc-sim failed: $OUT/render.log" >&2; exit 1; }
  fi
fi
for file in groundtruth.txt events.evb calib.yaml gt_map/map.evmap; do
  [[ -f "$DATASET/$file" ]] || { echo "attack-service: $DATASET has no $file" >&2; exit 1; }
done

# The Python stubs of the service API, from this checkout's protos.
STUBS="$OUT/stubs"
rm -rf "$STUBS"
mkdir -p "$STUBS"
protoc -I "$ROOT/proto" --python_out="$STUBS" --grpc_python_out="$STUBS" \
  --plugin=protoc-gen-grpc_python="$PLUGIN" evloc/map.proto evloc/localizer.proto

exec "$PYTHON" "$ROOT/scripts/attack_service.py" --build "$BUILD" --dataset "$DATASET" \
  --out "$OUT/run" --stubs "$STUBS" --rss-budget-mib "$RSS_BUDGET_MIB" --only "$ONLY" \
  ${SERVER_ARGS[@]+"${SERVER_ARGS[@]}"}
