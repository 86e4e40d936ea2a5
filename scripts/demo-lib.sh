# Shared by scripts/demo.sh and scripts/demo-site.sh (sourced, not run): the steps of a demo
# (begin, run, finish, fail with the step's log), cleanup of what it started, and the localizer
# service started on loopback and stopped, the tools' paths under BUILD_DIR. The caller sets
# BUILD_DIR, TOTAL (steps), LOGS, and names itself in messages through DEMO_NAME (default "demo").
DEMO_NAME=${DEMO_NAME:-demo}
SIM="$BUILD_DIR/tools/sim/evloc-sim"
MAPPER="$BUILD_DIR/mapper/evloc-mapper"
SERVER="$BUILD_DIR/localizer/service/evloc-localizer"
REPLAY="$BUILD_DIR/tools/replay/evloc-replay"
EVAL="$BUILD_DIR/tools/eval/evloc-eval"
PYTHON=/usr/bin/python3

# check_tools: exits with a message when a binary the demos run is missing.
check_tools() {
  for binary in "$SIM" "$MAPPER" "$SERVER" "$REPLAY" "$EVAL"; do
    if [[ ! -x "$binary" ]]; then
      echo "$DEMO_NAME: $binary is missing: run 'make build' first (make $DEMO_NAME does it for you)" >&2
      exit 1
    fi
  done
}
START=$(date +%s)
STEP=0
STEP_TIMES=()
CURRENT_PID=""
SERVER_PID=""

elapsed() { echo $(($(date +%s) - START)); }

# Stops whatever the demo started (the current step, the service) when it ends or is interrupted.
cleanup() {
  if [[ -n "$CURRENT_PID" ]] && kill -0 "$CURRENT_PID" 2>/dev/null; then
    kill -TERM "$CURRENT_PID" 2>/dev/null || true
  fi
  if [[ -n "$SERVER_PID" ]] && kill -0 "$SERVER_PID" 2>/dev/null; then
    kill -TERM "$SERVER_PID" 2>/dev/null || true
    for _ in $(seq 50); do kill -0 "$SERVER_PID" 2>/dev/null || break; sleep 0.2; done
    kill -KILL "$SERVER_PID" 2>/dev/null || true
  fi
}
trap cleanup EXIT
trap 'echo "$DEMO_NAME: interrupted" >&2; exit 130' INT TERM

# fail MESSAGE [LOG]: reports the failed step and exits non-zero.
fail() {
  echo >&2
  echo "$DEMO_NAME: FAILED at step $STEP/$TOTAL '$STEP_NAME' after $(elapsed) s: $1" >&2
  if [[ -n "${2:-}" ]]; then
    echo "$DEMO_NAME: last lines of its log:" >&2
    tail -n 15 "$2" | sed 's/^/    /' >&2
    echo "$DEMO_NAME: the full log is $2" >&2
  fi
  exit 1
}

# begin NAME: starts a step.
begin() {
  STEP=$((STEP + 1))
  STEP_NAME=$1
  STEP_START=$(date +%s)
  echo
  echo "== [$STEP/$TOTAL] $STEP_NAME  (elapsed $(elapsed) s)"
}

# finish: records the step's duration.
finish() {
  local seconds=$(($(date +%s) - STEP_START))
  STEP_TIMES+=("$STEP. $STEP_NAME: $seconds s")
  echo "   done in $seconds s"
}

# run LOG PROGRESS COMMAND...: runs a command with its output in LOG, printing the log's new lines
# as they come and, every 15 s without any, a heartbeat from PROGRESS (a function name or "").
run() {
  local log=$1 progress=$2
  shift 2
  echo "   \$ $*" | cut -c1-200
  echo "   (log: $log)"
  "$@" >"$log" 2>&1 &
  CURRENT_PID=$!
  local shown=0 quiet=0 lines
  while kill -0 "$CURRENT_PID" 2>/dev/null; do
    sleep 1
    lines=$(wc -l <"$log")
    if ((lines > shown)); then
      sed -n "$((shown + 1)),${lines}p" "$log" | cut -c1-160 | sed 's/^/   | /'
      shown=$lines
      quiet=0
    elif ((++quiet % 15 == 0)); then
      echo "   ... $(($(date +%s) - STEP_START)) s${progress:+: $($progress)}"
    fi
  done
  local status=0
  wait "$CURRENT_PID" || status=$?
  CURRENT_PID=""
  sed -n "$((shown + 1)),\$p" "$log" | cut -c1-160 | sed 's/^/   | /'
  ((status == 0)) || fail "the command exited with status $status" "$log"
}

# start_service MAPS [FLAGS...]: starts `evloc-localizer serve --maps MAPS [FLAGS...]` on a free
# loopback port (log LOGS/server.log), waits until gRPC health says SERVING (LOGS/health.log) and
# sets SERVER_PID, SERVER_LOG and PORT.
start_service() {
  local maps=$1
  shift
  SERVER_LOG="$LOGS/server.log"
  # One session at a time at --speed max: no neighbour for the search's CPU share to protect, and
  # with a share the search's progress per second of events depends on the machine's speed
  # (docs/relocalization.md, "Cost"), so the demo's time to find the camera would too. For the
  # same reason the search runs at normal priority: at idle priority it would wait for whatever
  # else the machine runs (the demo is not in a container or a unit of its own).
  echo "   \$ $SERVER serve --maps $maps --listen 127.0.0.1:0 --search-cpu-share 0 --search-priority normal $*   (log: $SERVER_LOG)"
  "$SERVER" serve --maps "$maps" --listen 127.0.0.1:0 --search-cpu-share 0 \
    --search-priority normal "$@" >"$SERVER_LOG" 2>&1 &
  SERVER_PID=$!
  PORT=""
  for _ in $(seq 300); do
    kill -0 "$SERVER_PID" 2>/dev/null || fail "the service exited at start" "$SERVER_LOG"
    PORT=$(sed -n 's/^evloc-localizer: serving on port \([0-9]*\)$/\1/p' "$SERVER_LOG")
    [[ -n "$PORT" ]] && break
    sleep 0.2
  done
  [[ -n "$PORT" ]] || fail "the service did not report its port within 60 s" "$SERVER_LOG"
  echo "   listening on 127.0.0.1:$PORT (a free port chosen by the system)"
  local healthy=""
  for _ in $(seq 30); do
    if "$REPLAY" --health-check --server "127.0.0.1:$PORT" --health-timeout 2 \
      >"$LOGS/health.log" 2>&1; then
      healthy=1
      break
    fi
    kill -0 "$SERVER_PID" 2>/dev/null || fail "the service exited" "$SERVER_LOG"
    sleep 1
  done
  [[ -n "$healthy" ]] || fail "gRPC health never said SERVING" "$LOGS/health.log"
  sed 's/^/   /' "$LOGS/health.log"
}

# stop_service: SIGTERM, then checks that the service exited 0 and logged 'stopped'; prints its
# session lines.
stop_service() {
  kill -TERM "$SERVER_PID"
  local status=0
  wait "$SERVER_PID" || status=$?
  SERVER_PID=""
  ((status == 0)) || fail "the service exited with status $status" "$SERVER_LOG"
  grep -q '^evloc-localizer: stopped' "$SERVER_LOG" ||
    fail "the service log does not end with 'stopped'" "$SERVER_LOG"
  grep -E 'session [0-9]+ (start|end)|stopped' "$SERVER_LOG" | cut -c1-160 | sed 's/^/   | /'
}
