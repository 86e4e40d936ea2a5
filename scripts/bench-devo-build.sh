#!/usr/bin/env bash
# Canny-DEVO's reference-frame build in a real run (issue 17, "a reference-map build per keyframe
# <= 10 ms at VGA"; docs/accuracy.md, "Mapless odometry").
#
# Usage: scripts/bench-devo-build.sh DATASET [BUILD_DIR] [REPEATS] [OTHER_BUILD_DIR]
#   DATASET          a dataset with events and depth (evloc-sim render ... --depth-camera)
#   BUILD_DIR        a build with evloc-track (default build)
#   REPEATS          runs of each build (default 3)
#   OTHER_BUILD_DIR  a second build to compare with, run alternately with the first
# Every run is `evloc-track --mode devo --stats`, pinned to core 1. A build's time is the CPU
# time of the building thread (build_cpu_ms of "reference_frames" in the statistics). The table
# gives, per reference frame, the median over the runs; then the median over the frames, and the
# same without the first frame (which pays for the first touch of every buffer). The runs of a
# build must give the same trajectory (the tracker is deterministic); the script says so.
set -euo pipefail
if [[ $# -lt 1 ]]; then sed -n 2,15p "$0"; exit 2; fi
dataset=$(realpath "$1")
builds=("$(realpath "${2:-build}")")
repeats=${3:-3}
[[ $# -ge 4 ]] && builds+=("$(realpath "$4")")
for build in "${builds[@]}"; do
  [[ -x "$build/localizer/offline/evloc-track" ]] ||
    { echo "bench-devo-build: no evloc-track in $build; build it first" >&2; exit 1; }
done
[[ -f "$dataset/depth.txt" ]] ||
  { echo "bench-devo-build: $dataset has no depth.txt (render it with --depth-camera)" >&2; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
echo "load before: $(uptime)"
for ((run = 0; run < repeats; run++)); do
  for ((b = 0; b < ${#builds[@]}; b++)); do
    taskset -c 1 "${builds[$b]}/localizer/offline/evloc-track" --mode devo --dataset "$dataset" \
      --out "$work/est$b-$run.txt" --stats "$work/stats$b-$run.json" --quiet
  done
done
echo "load after:  $(uptime)"
/usr/bin/python3 - "$work" "$repeats" "${builds[@]}" <<'PY'
import filecmp, json, statistics, sys
work, repeats, builds = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
for b, build in enumerate(builds):
    runs = [json.load(open(f"{work}/stats{b}-{r}.json"))["reference_frames"] for r in range(repeats)]
    frames = runs[0]
    per_frame = [statistics.median(run[i]["build_cpu_ms"] for run in runs) for i in range(len(frames))]
    same = all(filecmp.cmp(f"{work}/est{b}-0.txt", f"{work}/est{b}-{r}.txt", shallow=False)
               for r in range(repeats))
    print(f"\n{build}: {len(frames)} reference frames, {repeats} runs"
          f" ({'identical trajectories' if same else 'TRAJECTORIES DIFFER between runs'})")
    print("| frame | t s | semi-dense pixels | points | build CPU ms (median of runs) |")
    print("|---|---|---|---|---|")
    for i, frame in enumerate(frames):
        print(f"| {i} | {frame['t_s']:.3f} | {frame['semi_dense_pixels']} | {frame['points']} "
              f"| {per_frame[i]:.1f} |")
    rest = per_frame[1:] if len(per_frame) > 1 else per_frame
    print(f"median over frames {statistics.median(per_frame):.1f} ms; without the first "
          f"{statistics.median(rest):.1f} ms; max {max(per_frame):.1f} ms")
if len(builds) == 2:
    same = filecmp.cmp(f"{work}/est0-0.txt", f"{work}/est1-0.txt", shallow=False)
    print(f"\nthe two builds' trajectories are {'identical' if same else 'different'}")
PY
