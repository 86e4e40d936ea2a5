#!/usr/bin/env bash
# The tracking step in a real run against BM_TrackingStep replaying the same steps (issue 16,
# target 2; docs/benchmarks.md, "Tracking: the benchmark against the real run").
#
# Usage: scripts/bench-tracking-replay.sh DATASET [SECONDS] [BUILD_DIR] [REPEATS]
#   DATASET    a dataset folder with events, ground truth and gt_map/ (an evloc-sim render)
#   SECONDS    the first seconds of the run compared (default 2)
#   BUILD_DIR  a build with evloc-track and bench/evloc_tracking_benchmark (default build)
#   REPEATS    runs of each, alternating (default 3); the table gives the median of their medians
# Both are pinned to core 1 (taskset). evloc-track runs the whole dataset with --stats; its median
# step time (`total_ms`, the step without the ingestion of its events) is taken over the steps of
# the first SECONDS. BM_TrackingStep (lazy EVT, the defaults) replays those seconds
# (EVLOC_BENCH_DATASET, EVLOC_BENCH_SECONDS): its step_median_ms counter is the same measure; its
# CPU time per iteration also includes the ingestion of the step's packet.
set -euo pipefail
if [[ $# -lt 1 ]]; then sed -n 2,16p "$0"; exit 2; fi
dataset=$(realpath "$1")
seconds=${2:-2}
build=$(realpath "${3:-build}")
repeats=${4:-3}
track=$build/localizer/offline/evloc-track
bench=$build/bench/evloc_tracking_benchmark
for tool in "$track" "$bench"; do
  [[ -x "$tool" ]] || { echo "bench-tracking-replay: $tool is missing; build it first" >&2; exit 1; }
done
[[ -f "$dataset/gt_map/map.evmap" ]] || { echo "bench-tracking-replay: no $dataset/gt_map" >&2; exit 1; }
pin=(taskset -c 1)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
echo "load before: $(uptime)"
for ((run = 0; run < repeats; run++)); do
  "${pin[@]}" "$track" --map "$dataset/gt_map" --dataset "$dataset" --out "$work/est.txt" \
    --stats "$work/stats$run.json" --quiet
  EVLOC_BENCH_DATASET=$dataset EVLOC_BENCH_SECONDS=$seconds "${pin[@]}" "$bench" \
    --benchmark_filter='BM_TrackingStep/0/1/1/0/1$' --benchmark_min_time=2 \
    --benchmark_format=json > "$work/bench$run.json"
done
echo "load after:  $(uptime)"
/usr/bin/python3 - "$work" "$repeats" "$seconds" "$(basename "$dataset")" <<'PY'
import json, statistics, sys
work, repeats, seconds, name = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
track_median, track_p99, bench_median, bench_cpu = [], [], [], []
for run in range(repeats):
    steps = json.load(open(f"{work}/stats{run}.json"))["per_step"]
    first = steps[0]["t_s"]
    times = sorted(s["total_ms"] for s in steps if s["t_s"] < first + seconds)
    track_median.append(statistics.median(times))
    track_p99.append(times[min(len(times) - 1, int(0.99 * len(times)))])
    b = json.load(open(f"{work}/bench{run}.json"))["benchmarks"][0]
    bench_median.append(b["step_median_ms"])
    scale = {"ns": 1e-6, "us": 1e-3, "ms": 1.0}[b["time_unit"]]
    bench_cpu.append(b["cpu_time"] * scale)
tm, bm = statistics.median(track_median), statistics.median(bench_median)
print(f"| data | steps compared | evloc-track --stats median / p99 ms | BM_TrackingStep step_median_ms "
      f"| BM CPU per iteration ms | BM / --stats |")
print("|---|---|---|---|---|---|")
print(f"| {name}, first {seconds:g} s | {len(times)} | {tm:.3f} / {statistics.median(track_p99):.3f} "
      f"| {bm:.3f} | {statistics.median(bench_cpu):.3f} | {bm / tm:.2f} |")
print("runs (--stats median, BM step median):",
      ", ".join(f"{a:.3f}/{b:.3f}" for a, b in zip(track_median, bench_median)))
PY
