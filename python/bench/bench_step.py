#!/usr/bin/env python3
"""What the bindings add to a tracking step (docs/benchmarks.md, "Python bindings"): the same
dataset and map tracked by evloc-track (the C++ tool) and by evloc.track_events (NumPy arrays in,
the GIL released) and evloc.track_dataset (evloc-track in-process), alternately, REPEATS times
each; the medians of each run's median step time (the tracker's own per-step wall time), of its
wall time and of its CPU time (user + system of the process: evloc-track's as a child, the
bindings' in this process; less disturbed by other processes on a loaded machine than wall
time). Pin it: taskset -c 1 python bench_step.py ...

Usage: bench_step.py --build BUILD --dataset DIR --map MAP [--repeats N] [--json OUT]
"""

import argparse
import json
import os
import resource
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
            children = resource.getrusage(resource.RUSAGE_CHILDREN)
            start = time.perf_counter()
            subprocess.run([track, "--map", args.map, "--dataset", args.dataset, "--out",
                            os.path.join(folder, "cli.txt"), "--stats", stats_path, "--quiet"],
                           check=True)
            wall = time.perf_counter() - start
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (after.ru_utime - children.ru_utime) + (after.ru_stime - children.ru_stime)
            with open(stats_path, encoding="utf-8") as handle:
                stats = json.load(handle)
            runs["evloc-track"].append((stats["median_step_ms"], stats["wall_s"], wall, cpu))
            cpu_start, start = time.process_time(), time.perf_counter()
            result = evloc.track_events(the_map, dataset.camera, events, pose, t0)
            runs["track_events"].append((result.median_step_ms, result.wall_s,
                                         time.perf_counter() - start,
                                         time.process_time() - cpu_start))
            cpu_start, start = time.process_time(), time.perf_counter()
            result = evloc.track_dataset(args.map, args.dataset)
            runs["track_dataset"].append((result.median_step_ms, result.wall_s,
                                          time.perf_counter() - start,
                                          time.process_time() - cpu_start))
    summary = {}
    for name, values in runs.items():
        summary[name] = {"median_step_ms": statistics.median(v[0] for v in values),
                         "run_wall_s": statistics.median(v[1] for v in values),
                         "call_wall_s": statistics.median(v[2] for v in values),
                         "cpu_s": statistics.median(v[3] for v in values),
                         "runs": values}
    reference = summary["evloc-track"]
    for name, values in summary.items():
        values["step_vs_evloc_track"] = values["median_step_ms"] / reference["median_step_ms"]
        values["cpu_vs_evloc_track"] = values["cpu_s"] / reference["cpu_s"]
        print(f"{name:14s} median step {values['median_step_ms']:.3f} ms "
              f"({100 * (values['step_vs_evloc_track'] - 1):+.1f} %), run "
              f"{values['run_wall_s']:.3f} s, call {values['call_wall_s']:.3f} s, CPU "
              f"{values['cpu_s']:.3f} s ({100 * (values['cpu_vs_evloc_track'] - 1):+.1f} %)")
    print(f"events {len(events)}, steps {len(result.steps)}, repeats {args.repeats}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(summary, handle, indent=1)


if __name__ == "__main__":
    main()
