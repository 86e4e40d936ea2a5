#!/usr/bin/python3
"""How often the brightness-constancy polarity of a map point matches the simulated events, with
ground-truth poses and flow (docs/accuracy.md, "Polarity sign").

The tracker counts, per step, the points with a confident ON/OFF prediction whose own pixel fired
since the previous step, and how many of those fired with the predicted polarity
(TrackingQuality::polarity_predictions / polarity_matches). This script computes the same figure
from the dataset alone: the exact map (gt_map/map.ply), the ground-truth trajectory, and the
events (events.txt, `t x y p` with p in {0, 1}), so the tracker's figure can be compared with what
a perfect pose and a perfect flow would score on the same scene.

Usage: /usr/bin/python3 scripts/accuracy/polarity_ceiling.py DATASET [--rate 300] [--band 30]
DATASET: an `evloc-sim render ... --events-txt` folder with a pinhole camera (no distortion).
Needs python3-numpy (Debian).
"""
import argparse
import math
import sys

import numpy as np


def read_ply_points(path):
    raw = open(path, "rb").read()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    header = raw[:end].decode()
    if "binary_little_endian" not in header or "property float nz" not in header:
        sys.exit(f"{path}: expected evloc's binary PLY with x y z nx ny nz")
    values = np.frombuffer(raw[end:], dtype="<f4").reshape(-1, 6).astype(np.float64)
    return values[:, :3], values[:, 3:]


def read_pinhole(path):
    fields = {}
    for line in open(path):
        line = line.split("#")[0].strip()
        if ":" in line:
            key, value = line.split(":", 1)
            fields[key.strip()] = value.strip()
    if fields.get("model") != "pinhole":
        sys.exit(f"{path}: this script needs a pinhole camera (got {fields.get('model')})")
    fx, fy, cx, cy = [float(v) for v in fields["intrinsics"].strip("[]").split(",")]
    return int(fields["width"]), int(fields["height"]), fx, fy, cx, cy


def rotation(qx, qy, qz, qw):
    return np.array([
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("dataset")
    parser.add_argument("--rate", type=float, default=300.0, help="step rate, Hz")
    parser.add_argument("--band", type=float, default=30.0, help="neutral band, degrees")
    parser.add_argument("--min-flow", type=float, default=0.05, help="pixels per step")
    parser.add_argument("--every", type=float, default=0.05, help="seconds between checked steps")
    args = parser.parse_args()
    d = args.dataset
    positions, gradients = read_ply_points(d + "/gt_map/map.ply")
    width, height, fx, fy, cx, cy = read_pinhole(d + "/calib.yaml")
    ground_truth = np.loadtxt(d + "/groundtruth.txt")
    events = np.loadtxt(d + "/events.txt")
    events[:, 3] = np.where(events[:, 3] > 0, 1, -1)
    period = 1.0 / args.rate

    def project(t):
        j = np.argmin(abs(ground_truth[:, 0] - t))
        r = rotation(*ground_truth[j, 4:8])
        in_cam = (positions - ground_truth[j, 1:4]) @ r
        gradient_in_cam = gradients @ r
        u = fx * in_cam[:, 0] / in_cam[:, 2] + cx
        v = fy * in_cam[:, 1] / in_cam[:, 2] + cy
        probe = in_cam + 0.01 * in_cam[:, 2:3] * gradient_in_cam
        du = fx * probe[:, 0] / probe[:, 2] + cx - u
        dv = fy * probe[:, 1] / probe[:, 2] + cy - v
        return u, v, du, dv, in_cam[:, 2] > 0.1

    band_sine = math.sin(math.radians(args.band / 2))
    checked = matched = 0
    t = ground_truth[0, 0] + 0.1
    while t < min(events[-1, 0], ground_truth[-1, 0]) - 0.01:
        u, v, du, dv, valid = project(t)
        u_before, v_before, _, _, _ = project(t - 0.01)
        flow_u = (u - u_before) / 0.01 * period
        flow_v = (v - v_before) / 0.01 * period
        window = events[(events[:, 0] > t - period) & (events[:, 0] <= t)]
        window = window[np.argsort(window[:, 0], kind="stable")]
        last_polarity = np.zeros((height, width))
        last_polarity[window[:, 2].astype(int), window[:, 1].astype(int)] = window[:, 3]
        valid &= (u > 1) & (v > 1) & (u < width - 2) & (v < height - 2)
        flow_norm = np.hypot(flow_u, flow_v)
        cosine = (du * flow_u + dv * flow_v) / np.maximum(np.hypot(du, dv) * flow_norm, 1e-12)
        confident = valid & (abs(cosine) > band_sine) & (flow_norm >= args.min_flow)
        predicted = np.where(-cosine > 0, 1, -1)
        x = np.round(u[confident]).astype(int)
        y = np.round(v[confident]).astype(int)
        observed = last_polarity[y, x]
        fired = observed != 0
        checked += int(fired.sum())
        matched += int((observed[fired] == predicted[confident][fired]).sum())
        t += args.every
    if checked == 0:
        sys.exit("no confident prediction fired: is the dataset too short or static?")
    print(f"ground-truth pose and flow: {matched} of {checked} confident predictions whose pixel "
          f"fired in the step match ({matched / checked:.3f})")


if __name__ == "__main__":
    main()
