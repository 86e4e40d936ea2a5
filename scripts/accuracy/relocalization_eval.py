#!/usr/bin/env python3
"""Scores an evloc-track run that started without a pose (docs/accuracy.md, "Relocalization from
events").

Usage: relocalization_eval.py STATS.json TRAJECTORY.txt GROUNDTRUTH.txt [--label NAME]
  [--blackout T0 T1]

Prints one JSON object: the start time, the time to the first TRACKING step, the number of
TRACKING steps, the largest position and rotation error of any TRACKING pose against the ground
truth (interpolated; no alignment), the ATE (RMS position error over the TRACKING steps), the
search episodes, and the CPU figures of the searching steps (median, p99 and max step time). With
--blackout, also the time from the end of the blackout to the first TRACKING step after it.
"""
import argparse
import bisect
import json
import math


def read_tum(path):
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            v = [float(x) for x in line.split()]
            rows.append(v)
    rows.sort(key=lambda r: r[0])
    return rows


def quat_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def quat_angle_deg(a, b):
    dot = abs(sum(x * y for x, y in zip(a, b)))
    na = math.sqrt(sum(x * x for x in a))
    nb = math.sqrt(sum(x * x for x in b))
    return math.degrees(2 * math.acos(min(1.0, dot / (na * nb))))


def lookup(gt, times, t):
    i = bisect.bisect_left(times, t)
    if i <= 0 or i >= len(gt):
        return None
    a, b = gt[i - 1], gt[i]
    w = (t - a[0]) / (b[0] - a[0]) if b[0] > a[0] else 0
    pos = [a[1 + k] + w * (b[1 + k] - a[1 + k]) for k in range(3)]
    qa, qb = a[4:8], b[4:8]
    if sum(x * y for x, y in zip(qa, qb)) < 0:
        qb = [-x for x in qb]
    q = [qa[k] + w * (qb[k] - qa[k]) for k in range(4)]  # nlerp: the samples are 1 ms apart
    return pos, q


def percentile(values, p):
    if not values:
        return 0.0
    values = sorted(values)
    k = min(len(values) - 1, max(0, int(math.ceil(p / 100.0 * len(values))) - 1))
    return values[k]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("stats")
    parser.add_argument("trajectory")
    parser.add_argument("groundtruth")
    parser.add_argument("--label", default="")
    parser.add_argument("--blackout", nargs=2, type=float, default=None)
    args = parser.parse_args()
    stats = json.load(open(args.stats))
    steps = stats["per_step"]
    status = {round(s["t_s"], 6): s["status"] for s in steps}
    gt = read_tum(args.groundtruth)
    gt_times = [r[0] for r in gt]
    start = steps[0]["t_s"] if steps else 0
    first_tracking = next((s["t_s"] for s in steps if s["status"] == "TRACKING"), None)
    errors_t, errors_r = [], []
    for row in read_tum(args.trajectory):
        if status.get(round(row[0], 6)) != "TRACKING":
            continue
        truth = lookup(gt, gt_times, row[0])
        if truth is None:
            continue
        pos, q = truth
        errors_t.append(math.dist(pos, row[1:4]))
        errors_r.append(quat_angle_deg(q, row[4:8]))
    searching = [s["total_ms"] for s in steps if s["status"] in ("INITIALIZING", "RELOCALIZING")]
    result = {
        "label": args.label,
        "start_t_s": start,
        "time_to_tracking_s": None if first_tracking is None else first_tracking - start,
        "tracking_steps": len(errors_t),
        "steps": len(steps),
        "max_error_cm": 100 * max(errors_t) if errors_t else None,
        "max_error_deg": max(errors_r) if errors_r else None,
        "ate_cm": 100 * math.sqrt(sum(e * e for e in errors_t) / len(errors_t)) if errors_t else None,
        "tracking_poses_beyond_5cm_3deg": sum(
            1 for t, r in zip(errors_t, errors_r) if t > 0.05 or r > 3.0),
        "episodes": [(e["start_t_s"], e["end_t_s"], e["outcome"]) for e in
                     stats.get("relocalizations", [])],
        "searching_steps": len(searching),
        "searching_step_ms_median": percentile(searching, 50),
        "searching_step_ms_p99": percentile(searching, 99),
        "searching_step_ms_max": max(searching) if searching else 0.0,
    }
    if args.blackout:
        end = args.blackout[1]
        back = next((s["t_s"] for s in steps if s["t_s"] > end and s["status"] == "TRACKING"), None)
        result["back_to_tracking_after_blackout_s"] = None if back is None else back - end
    print(json.dumps(result))


if __name__ == "__main__":
    main()
