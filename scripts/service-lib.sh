# Shared by scripts/bench-service.sh and scripts/soak-service.sh (sourced, not run).

# start_localizer LOG BINARY ARGS...: starts `BINARY serve ARGS... --listen 127.0.0.1:0` in the
# background with its output in LOG, waits until it logs its port (at most 30 s; text or JSON
# logs), and sets SERVER_PID and PORT. Exits with the log on stderr when the server stops or does not start.
# A caller may set the array SERVER_LAUNCH to a command that runs the binary (taskset -c 0).
start_localizer() {
  local log=$1 binary=$2
  shift 2
  ${SERVER_LAUNCH[@]+"${SERVER_LAUNCH[@]}"} "$binary" serve --listen 127.0.0.1:0 "$@" > "$log" 2>&1 &
  SERVER_PID=$!
  PORT=""
  for _ in $(seq 300); do
    # The text line, or the JSON record of --log-format json.
    PORT=$(sed -n -e 's/^evloc-localizer: serving on port \([0-9]*\)$/\1/p' \
      -e 's/^{.*"message":"serving on port \([0-9]*\)".*$/\1/p' "$log")
    [[ -n "$PORT" ]] && return 0
    kill -0 "$SERVER_PID" 2>/dev/null || { cat "$log" >&2; exit 1; }
    sleep 0.1
  done
  echo "$(basename "$0"): the server did not start within 30 s (see $log)" >&2
  kill "$SERVER_PID"
  exit 1
}
