#!/usr/bin/env python3
"""What the bindings add to a tracking step (docs/benchmarks.md, "Python bindings"): the same
dataset and map tracked by evloc-track (the C++ tool) and by evloc.track_events (NumPy arrays in,
the GIL released) and evloc.track_dataset (evloc-track in-process), alternately, REPEATS times
each; the medians of each run's median step time (the tracker's own per-step wall time) and of
its wall time. Pin it: taskset -c 1 python bench_step.py ...

Usage: bench_step.py --build BUILD --dataset DIR --map MAP [--repeats N] [--json OUT]
"""

import argparse
import json
import os
import statistics
import subprocess
import tempfile
import time

import evloc


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--build", required=True)
    parser.add_argument("--dataset", required=True)
    parser.add_argument("--map", required=True)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json")
    args = parser.parse_args()
    track = os.path.join(args.build, "localizer", "offline", "evloc-track")
    dataset = evloc.read_dataset(args.dataset)
    events = dataset.events().read_all()
    t0, pose = dataset.initial_pose()
    the_map = evloc.load_map(args.map)
    runs = {"evloc-track": [], "track_events": [], "track_dataset": []}
    with tempfile.TemporaryDirectory() as folder:
        stats_path = os.path.join(folder, "stats.json")
        for _ in range(args.repeats):
            start = time.perf_counter()
            subprocess.run([track, "--map", args.map, "--dataset", args.dataset, "--out",
                            os.path.join(folder, "cli.txt"), "--stats", stats_path, "--quiet"],
                           check=True)
            wall = time.perf_counter() - start
            with open(stats_path, encoding="utf-8") as handle:
                stats = json.load(handle)
            runs["evloc-track"].append((stats["median_step_ms"], stats["wall_s"], wall))
            start = time.perf_counter()
            result = evloc.track_events(the_map, dataset.camera, events, pose, t0)
            runs["track_events"].append((result.median_step_ms, result.wall_s,
                                         time.perf_counter() - start))
            start = time.perf_counter()
            result = evloc.track_dataset(args.map, args.dataset)
            runs["track_dataset"].append((result.median_step_ms, result.wall_s,
                                          time.perf_counter() - start))
    summary = {}
    for name, values in runs.items():
        summary[name] = {"median_step_ms": statistics.median(v[0] for v in values),
                         "run_wall_s": statistics.median(v[1] for v in values),
                         "call_wall_s": statistics.median(v[2] for v in values),
                         "runs": values}
    reference = summary["evloc-track"]["median_step_ms"]
    for name, values in summary.items():
        values["step_vs_evloc_track"] = values["median_step_ms"] / reference
        print(f"{name:14s} median step {values['median_step_ms']:.3f} ms "
              f"({100 * (values['step_vs_evloc_track'] - 1):+.1f} %), run {values['run_wall_s']:.3f} s, "
              f"call {values['call_wall_s']:.3f} s")
    print(f"events {len(events)}, steps {len(result.steps)}, repeats {args.repeats}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(summary, handle, indent=1)


if __name__ == "__main__":
    main()
