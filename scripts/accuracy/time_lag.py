#!/usr/bin/python3
"""Time lag of an estimated trajectory against its ground truth.

Usage: scripts/accuracy/time_lag.py GROUNDTRUTH.txt ESTIMATE.txt [--max-ms 40] [--step-ms 0.5]

Both files are TUM trajectories (t tx ty tz qx qy qz qw, '#' comments), no alignment (the
trajectories share the ground truth's frame, as evloc-eval --align none assumes). For every
offset d in [-max, +max] the estimated positions are compared with the ground truth at t - d
(linear interpolation), and the RMSE of the position error is printed for the offset with the
smallest RMSE and for d = 0. A positive lag means the estimate shows where the camera was d
seconds before its time stamp. Used for the tracker's lag figures in docs/accuracy.md.
"""

import argparse
import sys

import numpy as np


def read_tum(path):
    rows = []
    with open(path) as f:
        for number, line in enumerate(f, 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            fields = line.split()
            if len(fields) != 8:
                sys.exit(f"time_lag: {path}:{number}: expected 8 fields "
                         f"(t tx ty tz qx qy qz qw), found {len(fields)}")
            rows.append([float(v) for v in fields[:4]])
    if len(rows) < 2:
        sys.exit(f"time_lag: {path}: fewer than two poses")
    data = np.array(rows)
    return data[:, 0], data[:, 1:4]


def rmse_at(offset, gt_t, gt_p, est_t, est_p):
    times = est_t - offset
    inside = (times >= gt_t[0]) & (times <= gt_t[-1])
    if inside.sum() < 2:
        return float("inf"), 0
    truth = np.stack([np.interp(times[inside], gt_t, gt_p[:, k]) for k in range(3)], axis=1)
    error = np.linalg.norm(est_p[inside] - truth, axis=1)
    return float(np.sqrt(np.mean(error**2))), int(inside.sum())


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("groundtruth")
    parser.add_argument("estimate")
    parser.add_argument("--max-ms", type=float, default=40.0)
    parser.add_argument("--step-ms", type=float, default=0.5)
    args = parser.parse_args()
    if args.max_ms <= 0 or args.step_ms <= 0:
        sys.exit("time_lag: --max-ms and --step-ms must be positive")
    gt_t, gt_p = read_tum(args.groundtruth)
    est_t, est_p = read_tum(args.estimate)
    offsets = np.arange(-args.max_ms, args.max_ms + 1e-9, args.step_ms) / 1000.0
    results = [rmse_at(d, gt_t, gt_p, est_t, est_p) for d in offsets]
    best = int(np.argmin([r[0] for r in results]))
    zero, _ = rmse_at(0.0, gt_t, gt_p, est_t, est_p)
    print(f"lag {offsets[best] * 1000:.1f} ms: position RMSE {results[best][0] * 100:.3f} cm "
          f"({results[best][1]} poses); at 0 ms: {zero * 100:.3f} cm")


if __name__ == "__main__":
    main()
