#!/usr/bin/env bash
# Local scale-out test (docs/deploy.md, "Scale-out test"): three evloc-localizer replicas on
# loopback behind HAProxy (deploy/haproxy/evloc-localizer.cfg: HTTP/2, one Track stream per
# request, leastconn), CLIENTS evloc-replay clients streaming one dataset through the proxy with
# --reconnect, and one replica killed mid-run. As deployed: TLS from the clients to the proxy
# and from the proxy to the replicas (a test CA and certificate made here with openssl), and a
# bearer token (in a file) on every session. The clients that were on it must reconnect through
# the proxy to a live replica and resume at their last pose; every client must finish. Prints
# how many sessions were affected, how long they took to resume (distribution), and the accuracy
# of the affected and unaffected trajectories (evloc-eval against ground truth).
#
# Usage: scripts/scale-out-test.sh [options]
#   --build DIR        build folder with the binaries (default: build)
#   --dataset DIR      dataset with groundtruth.txt and gt_map/map.evmap (default: render a 2 s
#                      'mid' sequence with the 240x180 davis240 camera into OUT/dataset)
#   --out DIR          output folder (default: /tmp/evloc-scale-out); its previous run is replaced
#   --clients N        replay clients (default 9)
#   --speed S|max      replay speed (default max: paced by the poses, so a loaded machine slows
#                      the replay down instead of overflowing a server's queue)
#   --signal KILL|TERM how the replica goes away: KILL (a crash) or TERM (a graceful stop: health
#                      NOT_SERVING, 1 s for running calls, then they are cancelled) (default KILL)
#   --kill-at F        kill when this fraction of all expected poses has been sent (default 0.33)
#   --base-port P      proxy on P, replicas on P+1..P+3, their metrics on P+11..P+13 (default 50160)
# Exit status: 0 passed, 1 failed, 2 bad usage, 77 haproxy, openssl or a binary is missing
# (skipped).
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD="$ROOT/build"
DATASET=""
OUT=/tmp/evloc-scale-out
CLIENTS=9
SPEED=max
SIGNAL=KILL
KILL_AT=0.33
BASE_PORT=50160
RATE_HZ=300
TIMEOUT_S=900

usage() { sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//'; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --build) BUILD=$2; shift 2 ;;
    --dataset) DATASET=$2; shift 2 ;;
    --out) OUT=$2; shift 2 ;;
    --clients) CLIENTS=$2; shift 2 ;;
    --speed) SPEED=$2; shift 2 ;;
    --signal) SIGNAL=$2; shift 2 ;;
    --kill-at) KILL_AT=$2; shift 2 ;;
    --base-port) BASE_PORT=$2; shift 2 ;;
    --help|-h) usage; exit 0 ;;
    *) echo "scale-out: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[[ "$CLIENTS" =~ ^[1-9][0-9]*$ ]] || { echo "scale-out: --clients must be a positive integer" >&2; exit 2; }
[[ "$SIGNAL" == KILL || "$SIGNAL" == TERM ]] || { echo "scale-out: --signal must be KILL or TERM" >&2; exit 2; }
[[ "$BASE_PORT" =~ ^[0-9]+$ && "$BASE_PORT" -ge 1024 && "$BASE_PORT" -le 65000 ]] ||
  { echo "scale-out: --base-port must be in 1024..65000" >&2; exit 2; }

LOCALIZER="$BUILD/localizer/service/evloc-localizer"
REPLAY="$BUILD/tools/replay/evloc-replay"
EVAL="$BUILD/tools/eval/evloc-eval"
SIM="$BUILD/tools/sim/evloc-sim"
for binary in "$LOCALIZER" "$REPLAY" "$EVAL"; do
  [[ -x "$binary" ]] || { echo "scale-out: SKIPPED: $binary is not built" >&2; exit 77; }
done
command -v haproxy >/dev/null 2>&1 ||
  { echo "scale-out: SKIPPED: haproxy is not installed (scripts/install-deploy-tools.sh)" >&2; exit 77; }
command -v openssl >/dev/null 2>&1 ||
  { echo "scale-out: SKIPPED: openssl is not installed (scripts/install-deps.sh)" >&2; exit 77; }

rm -rf "$OUT/run"
mkdir -p "$OUT/run/maps/room"
RUN="$OUT/run"

# The dataset and its exact map.
if [[ -z "$DATASET" ]]; then
  DATASET="$OUT/dataset"
  if [[ ! -d "$DATASET" ]]; then
    [[ -x "$SIM" ]] || { echo "scale-out: SKIPPED: $SIM is not built (or pass --dataset)" >&2; exit 77; }
    echo "scale-out: rendering a 2 s dataset (240x180) into $DATASET"
    nice -n 10 "$SIM" render --out "$DATASET" --camera davis240 --motion mid --duration 2 \
      > "$OUT/render.log" 2>&1 || { echo "scale-out: evloc-sim failed: $OUT/render.log" >&2; exit 1; }
  fi
fi
for file in groundtruth.txt gt_map/map.evmap; do
  [[ -f "$DATASET/$file" ]] || { echo "scale-out: $DATASET has no $file" >&2; exit 1; }
done
cp "$DATASET/gt_map/map.evmap" "$RUN/maps/room/map.evmap"
duration_s=$(awk '!/^#/ && NF {if (first == "") first = $1; last = $1} END {print last - first}' \
  "$DATASET/groundtruth.txt")
expected_poses=$(awk -v d="$duration_s" -v r="$RATE_HZ" -v n="$CLIENTS" 'BEGIN {printf "%d", d * r * n}')
kill_poses=$(awk -v e="$expected_poses" -v f="$KILL_AT" 'BEGIN {printf "%d", e * f}')

PIDS=()
# shellcheck disable=SC2317  # called by the EXIT trap
cleanup() {
  for pid in "${PIDS[@]}"; do kill "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
}
trap cleanup EXIT

# A test CA, one certificate for localhost / 127.0.0.1 (replicas and proxy), the token files.
TLS="$RUN/tls"
mkdir -p "$TLS"
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 1 \
  -subj /CN=evloc-scale-out-ca -keyout "$TLS/ca.key" -out "$TLS/ca.crt" > /dev/null 2>&1
openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -subj /CN=localhost \
  -keyout "$TLS/server.key" -out "$TLS/server.csr" > /dev/null 2>&1
printf 'subjectAltName=DNS:localhost,IP:127.0.0.1\n' > "$TLS/server.ext"
openssl x509 -req -days 1 -in "$TLS/server.csr" -CA "$TLS/ca.crt" -CAkey "$TLS/ca.key" \
  -CAcreateserial -extfile "$TLS/server.ext" -out "$TLS/server.crt" > /dev/null 2>&1
cat "$TLS/server.crt" "$TLS/server.key" > "$TLS/proxy.pem"
token=$(openssl rand -hex 24)
printf '%s room\n' "$token" > "$RUN/tokens.txt"
printf '%s\n' "$token" > "$RUN/client-token"
TLS_CLIENT=(--tls-ca "$TLS/ca.crt" --tls-server-name localhost)

# Three replicas and the proxy.
server_pid=()
for i in 1 2 3; do
  "$LOCALIZER" serve --maps "$RUN/maps" --listen "127.0.0.1:$((BASE_PORT + i))" \
    --tls-cert "$TLS/server.crt" --tls-key "$TLS/server.key" --auth-tokens "$RUN/tokens.txt" \
    --metrics "127.0.0.1:$((BASE_PORT + 10 + i))" --max-sessions 8 --rate "$RATE_HZ" \
    > "$RUN/server$i.log" 2>&1 &
  server_pid[i]=$!
  PIDS+=("$!")
done
export EVLOC_PROXY_BIND="127.0.0.1:$BASE_PORT"
export EVLOC_PROXY_CERT="$TLS/proxy.pem"
export EVLOC_BACKEND_CA="$TLS/ca.crt"
export EVLOC_BACKEND_SERVER_NAME=localhost
export EVLOC_BACKEND_1="127.0.0.1:$((BASE_PORT + 1))"
export EVLOC_BACKEND_2="127.0.0.1:$((BASE_PORT + 2))"
export EVLOC_BACKEND_3="127.0.0.1:$((BASE_PORT + 3))"
haproxy -db -f "$ROOT/deploy/haproxy/evloc-localizer.cfg" > "$RUN/haproxy.log" 2>&1 &
PIDS+=("$!")
for address in "127.0.0.1:$((BASE_PORT + 1))" "127.0.0.1:$((BASE_PORT + 2))" \
               "127.0.0.1:$((BASE_PORT + 3))" "127.0.0.1:$BASE_PORT"; do
  ready=false
  for _ in $(seq 1 50); do
    if "$REPLAY" --health-check --server "$address" "${TLS_CLIENT[@]}" --health-timeout 1 \
         > /dev/null 2>&1; then
      ready=true
      break
    fi
    sleep 0.2
  done
  [[ "$ready" == true ]] || { echo "scale-out: $address never became SERVING (logs in $RUN)" >&2; exit 1; }
done
echo "scale-out: 3 replicas on 127.0.0.1:$((BASE_PORT + 1))-$((BASE_PORT + 3)) behind HAProxy on" \
     "127.0.0.1:$BASE_PORT; $CLIENTS clients, speed $SPEED, ${duration_s} s dataset $DATASET"

# One metric of replica I (its Prometheus text at /metrics), 0 when it does not answer.
metric() {
  local port=$((BASE_PORT + 10 + $1)) name=$2
  { exec 3<>"/dev/tcp/127.0.0.1/$port" &&
    printf 'GET /metrics HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n' >&3 &&
    awk -v n="$name" '$1 == n {v = $2} END {print v + 0}' <&3
    exec 3<&-; } 2>/dev/null || echo 0
}
# Sum of one metric over the live replicas.
metric_sum() {
  local total=0
  for i in 1 2 3; do
    kill -0 "${server_pid[i]}" 2>/dev/null || continue
    total=$((total + $(metric "$i" "$1")))
  done
  echo "$total"
}

# The clients.
client_pid=()
start_s=$(date +%s.%N)
for c in $(seq 1 "$CLIENTS"); do
  mkdir -p "$RUN/client$c"
  "$REPLAY" --server "127.0.0.1:$BASE_PORT" --map room --dataset "$DATASET" \
    --out "$RUN/client$c/trajectory.txt" --report "$RUN/client$c/report.json" \
    --speed "$SPEED" --reconnect 10 "${TLS_CLIENT[@]}" --token-file "$RUN/client-token" \
    > "$RUN/client$c/replay.log" 2>&1 &
  client_pid[c]=$!
  PIDS+=("$!")
done

# Kill replica 1 once the fleet has sent KILL_AT of the expected poses (and it has sessions).
victim=1
while :; do
  poses=$(metric_sum evloc_poses_total)
  if [[ $poses -ge $kill_poses && $(metric "$victim" evloc_sessions_active) -gt 0 ]]; then break; fi
  if awk -v s="$start_s" -v now="$(date +%s.%N)" -v t="$TIMEOUT_S" 'BEGIN {exit !(now - s > t)}'; then
    echo "scale-out: timed out before the kill (logs in $RUN)" >&2
    exit 1
  fi
  sleep 0.1
done
sessions_on_victim=$(metric "$victim" evloc_sessions_active)
active_total=$(metric_sum evloc_sessions_active)
kill_s=$(date +%s.%N)
kill -s "$SIGNAL" "${server_pid[victim]}"
{ wait "${server_pid[victim]}"; } 2>/dev/null || true
echo "scale-out: SIG$SIGNAL to replica $victim at $(awk -v a="$start_s" -v b="$kill_s" 'BEGIN {printf "%.2f", b - a}') s" \
     "after $poses poses; it had $sessions_on_victim of $active_total active sessions"

# Wait for every client (bounded).
failed_clients=0
for c in $(seq 1 "$CLIENTS"); do
  remaining=$(awk -v s="$start_s" -v now="$(date +%s.%N)" -v t="$TIMEOUT_S" 'BEGIN {r = t - (now - s); print (r > 1 ? int(r) : 1)}')
  if ! timeout "$remaining" tail --pid="${client_pid[c]}" -f /dev/null; then
    echo "scale-out: client $c did not finish in time" >&2
    kill "${client_pid[c]}" 2>/dev/null || true
  fi
  if ! wait "${client_pid[c]}"; then
    echo "scale-out: client $c failed: $(tail -1 "$RUN/client$c/replay.log")" >&2
    failed_clients=$((failed_clients + 1))
  fi
done
wall_s=$(awk -v a="$start_s" -v b="$(date +%s.%N)" 'BEGIN {printf "%.1f", b - a}')

# Accuracy of every trajectory.
for c in $(seq 1 "$CLIENTS"); do
  if [[ -s "$RUN/client$c/trajectory.txt" ]]; then
    "$EVAL" --gt "$DATASET/groundtruth.txt" --est "$RUN/client$c/trajectory.txt" \
      --json "$RUN/client$c/eval.json" > "$RUN/client$c/eval.txt" 2>&1 || true
  fi
done

python3 - "$RUN" "$CLIENTS" "$sessions_on_victim" "$failed_clients" "$SIGNAL" "$wall_s" "$kill_s" <<'EOF'
import json, os, statistics, sys
run, clients, on_victim, failed, signal, wall = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5], sys.argv[6]
kill_time = float(sys.argv[7])
status_names = {1: "CANCELLED", 2: "UNKNOWN", 4: "DEADLINE_EXCEEDED", 8: "RESOURCE_EXHAUSTED",
                10: "ABORTED", 13: "INTERNAL", 14: "UNAVAILABLE"}
rows, resume, interruption, attempts, statuses, other = [], [], [], [], {}, []
for c in range(1, clients + 1):
    folder = os.path.join(run, f"client{c}")
    try:
        report = json.load(open(os.path.join(folder, "report.json")))
        evaluation = json.load(open(os.path.join(folder, "eval.json")))
    except (OSError, ValueError):
        rows.append((c, None, None, None))
        continue
    # Failures before the kill (e.g. a connection refused while the machine was busy) are
    # reported apart: the figures below are those of the sessions the kill interrupted.
    early = [o for o in report["outages"] if o["failed_at_unix_s"] < kill_time]
    for outage in early:
        name = status_names.get(outage["status_code"], str(outage["status_code"]))
        other.append(f"client {c}: {name} {outage['status_message']!r}, resumed after {outage['resume_ms']:.0f} ms")
    outages = [o for o in report["outages"] if o["failed_at_unix_s"] >= kill_time]
    for outage in outages:
        resume.append(outage["resume_ms"])
        interruption.append(outage["interruption_ms"])
        attempts.append(outage["attempts"])
        name = status_names.get(outage["status_code"], str(outage["status_code"]))
        statuses[name] = statuses.get(name, 0) + 1
    rows.append((c, report, evaluation, len(outages)))

def pct(values, q):
    values = sorted(values)
    return values[min(len(values) - 1, int(q * len(values)))]

def ate_cm(evaluation):
    return evaluation["ate_t_rmse_cm"]

def coverage(evaluation):
    return "%.1f %%" % (100 * evaluation["coverage"])

lines = [f"clients {clients}, failed {failed}, signal {signal}, wall {wall} s",
         f"sessions on the stopped replica at the kill: {on_victim}",
         f"sessions affected (clients that reconnected): {sum(1 for r in rows if r[3])}"]
if resume:
    lines.append("resume time, failure to first pose of the new session, ms: min %.0f p50 %.0f p90 %.0f max %.0f"
                 % (min(resume), pct(resume, 0.5), pct(resume, 0.9), max(resume)))
    lines.append("interruption, last pose before to first pose after, ms: min %.0f p50 %.0f p90 %.0f max %.0f"
                 % (min(interruption), pct(interruption, 0.5), pct(interruption, 0.9), max(interruption)))
    lines.append("attempts per resume: " + ", ".join(str(a) for a in attempts)
                 + "; failure statuses: " + ", ".join(f"{k} x{v}" for k, v in statuses.items()))
if other:
    lines.append("failures before the kill (recovered): " + "; ".join(other))
lines.append("client  outages  poses  LOST  resent  ATE RMSE cm  ATE max cm  coverage   (outages: caused by the kill)")
affected_ate, unaffected_ate = [], []
for c, report, evaluation, outages in rows:
    if report is None:
        lines.append(f"{c:6d}  (no report: the client failed)")
        continue
    ate = ate_cm(evaluation)
    (affected_ate if outages else unaffected_ate).append(ate)
    lines.append(f"{c:6d}  {outages:7d}  {report['poses']:5d}  {report['lost_poses']:4d}  {report['packets_resent']:6d}  {ate:11.2f}  {evaluation['ate_t_max_cm']:10.2f}  {coverage(evaluation)}")
latency = [r[1]["client_latency_p50_us"] / 1000 for r in rows if r[1] is not None]
if latency:
    lines.append("load: median packet-to-pose latency per client, ms: min %.0f p50 %.0f max %.0f (the queueing a new session waits through too)"
                 % (min(latency), pct(latency, 0.5), max(latency)))
if affected_ate and unaffected_ate:
    lines.append("ATE RMSE cm: affected mean %.2f max %.2f; unaffected mean %.2f max %.2f"
                 % (statistics.mean(affected_ate), max(affected_ate), statistics.mean(unaffected_ate), max(unaffected_ate)))
text = "\n".join(lines)
print(text)
open(os.path.join(run, "summary.txt"), "w").write(text + "\n")
EOF

status=0
if [[ $failed_clients -gt 0 ]]; then
  echo "scale-out: FAILED: $failed_clients client(s) did not complete" >&2
  status=1
fi
affected=$(awk '/^sessions affected/ {print $NF}' "$RUN/summary.txt")
if [[ "$sessions_on_victim" -gt 0 && "$affected" -lt "$sessions_on_victim" ]]; then
  echo "scale-out: FAILED: $sessions_on_victim sessions were on the stopped replica, only $affected resumed" >&2
  status=1
fi
echo "scale-out: logs and trajectories in $RUN"
[[ $status -eq 0 ]] && echo "scale-out: passed"
exit $status
