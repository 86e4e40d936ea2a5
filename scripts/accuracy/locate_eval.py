#!/usr/bin/python3
"""Runs `evloc-localizer locate --json` on images and scores the answers (docs/accuracy.md,
"Relocalization from one image").

  locate_eval.py LOCALIZER MAP --dataset DIR [--every N] [--label L]
      the frames of an evloc dataset (images.txt, calib.yaml, groundtruth.txt): FOUND rate, how
      many FOUND within 2 cm / 1 degree of the ground truth (pose at the frame's time, linearly
      interpolated), how many FOUND farther than 10 cm, errors, time per locate.
      With --gnss-sigma S --anchor LAT,LON,ALT,HEADING (the map's given anchor: its +y axis
      HEADING degrees east of north), each locate gets --gnss: the true position moved by
      Gaussian noise of S metres on each axis (seeded by --seed), in WGS84.
  locate_eval.py LOCALIZER MAP --foreign CALIB IMAGE... [--label L]
      images of scenes that are not in the map, with their calibration: every one should be
      NOT_FOUND (exit 3).
Prints one JSON line with the figures (and, with --details FILE, every answer).
"""

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from relocalization_eval import lookup, quat_angle_deg, read_tum  # noqa: E402


def pose_at(ground_truth, t):
    """Ground-truth (translation, quaternion xyzw) at time t, interpolated as
    relocalization_eval.py does; the first or last pose outside the ground truth's span."""
    rows, times = ground_truth
    truth = lookup(rows, times, t)
    if truth is None:
        row = rows[0] if t <= times[0] else rows[-1]
        truth = row[1:4], row[4:8]
    return np.array(truth[0]), truth[1]


WGS84_A = 6378137.0
WGS84_E2 = 6.69437999014e-3


def map_to_wgs84(position, anchor):
    """The WGS84 latitude, longitude (degrees) and ellipsoid height of a map-frame position,
    for an anchor (lat, lon, alt, heading) whose map +y axis points `heading` east of north:
    map -> ENU (rotation about up), ENU -> ECEF about the anchor, ECEF -> geodetic (iterated)."""
    lat0, lon0, alt0, heading = anchor
    h = np.radians(heading)
    x, y, z = position
    east = x * np.cos(h) + y * np.sin(h)
    north = -x * np.sin(h) + y * np.cos(h)
    up = z
    phi, lam = np.radians(lat0), np.radians(lon0)

    def ecef(phi_, lam_, height):
        n = WGS84_A / np.sqrt(1 - WGS84_E2 * np.sin(phi_) ** 2)
        return np.array([(n + height) * np.cos(phi_) * np.cos(lam_),
                         (n + height) * np.cos(phi_) * np.sin(lam_),
                         (n * (1 - WGS84_E2) + height) * np.sin(phi_)])

    p = ecef(phi, lam, alt0) + np.array([
        -np.sin(lam) * east - np.sin(phi) * np.cos(lam) * north + np.cos(phi) * np.cos(lam) * up,
        np.cos(lam) * east - np.sin(phi) * np.sin(lam) * north + np.cos(phi) * np.sin(lam) * up,
        np.cos(phi) * north + np.sin(phi) * up])
    lon = np.arctan2(p[1], p[0])
    r = np.hypot(p[0], p[1])
    lat = np.arctan2(p[2], r * (1 - WGS84_E2))
    for _ in range(10):
        n = WGS84_A / np.sqrt(1 - WGS84_E2 * np.sin(lat) ** 2)
        height = r / np.cos(lat) - n
        lat = np.arctan2(p[2], r * (1 - WGS84_E2 * n / (n + height)))
    n = WGS84_A / np.sqrt(1 - WGS84_E2 * np.sin(lat) ** 2)
    return np.degrees(lat), np.degrees(lon), r / np.cos(lat) - n


def locate(localizer, map_path, image, calib, gnss=None):
    start = time.monotonic()
    command = [localizer, "locate", "--map", map_path, "--image", image, "--calib", calib, "--json"]
    if gnss is not None:
        command += ["--gnss", ",".join("%.10f" % value for value in gnss)]
    run = subprocess.run(command, capture_output=True, text=True, check=False)
    seconds = time.monotonic() - start
    if run.returncode not in (0, 3):
        sys.exit(f"locate failed on {image} (exit {run.returncode}): {run.stderr.strip()}")
    answer = json.loads(run.stdout)
    answer["exit"] = run.returncode
    answer["wall_s"] = seconds
    answer["image"] = image
    return answer


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n", maxsplit=1)[0])
    parser.add_argument("localizer")
    parser.add_argument("map")
    parser.add_argument("--dataset")
    parser.add_argument("--every", type=int, default=1, help="every N-th frame of the dataset")
    parser.add_argument("--foreign", nargs="+", metavar="CALIB IMAGE",
                        help="a calibration file, then images of other scenes")
    parser.add_argument("--label", default="")
    parser.add_argument("--details", help="write every answer as JSON lines")
    parser.add_argument("--gnss-sigma", type=float,
                        help="send a GNSS fix this noisy (metres, each axis) with each locate")
    parser.add_argument("--anchor", help="LAT,LON,ALT,HEADING of the map (with --gnss-sigma)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the GNSS noise")
    args = parser.parse_args()
    if args.gnss_sigma is not None and not args.anchor:
        parser.error("--gnss-sigma needs --anchor")
    noise = np.random.default_rng(args.seed)
    answers = []
    figures = {"label": args.label}
    if args.dataset:
        rows = read_tum(os.path.join(args.dataset, "groundtruth.txt"))
        ground_truth = (rows, [row[0] for row in rows])
        calib = os.path.join(args.dataset, "calib.yaml")
        with open(os.path.join(args.dataset, "images.txt"), encoding="utf-8") as file:
            frames = [line.split() for line in file if line.strip() and not line.startswith("#")]
        translation_errors, rotation_errors = [], []
        within, far = 0, 0
        for t, name in frames[::args.every]:
            gnss = None
            if args.gnss_sigma is not None:
                truth_t, _ = pose_at(ground_truth, float(t))
                noisy = truth_t + noise.normal(0.0, args.gnss_sigma, 3)
                anchor = [float(value) for value in args.anchor.split(",")]
                gnss = list(map_to_wgs84(noisy, anchor)) + [args.gnss_sigma]
            answer = locate(args.localizer, args.map, os.path.join(args.dataset, name), calib, gnss)
            answer["t_s"] = float(t)
            if answer["status"] == "FOUND":
                truth_t, truth_q = pose_at(ground_truth, float(t))
                pose = np.array(answer["world_from_cam"])
                answer["error_m"] = float(np.linalg.norm(pose[:3] - truth_t))
                answer["error_deg"] = quat_angle_deg(list(pose[3:]), truth_q)
                translation_errors.append(answer["error_m"])
                rotation_errors.append(answer["error_deg"])
                within += answer["error_m"] <= 0.02 and answer["error_deg"] <= 1.0
                far += answer["error_m"] > 0.10
            answers.append(answer)
        found = len(translation_errors)
        figures.update({
            "frames": len(answers), "found": found, "found_fraction": found / len(answers),
            "within_2cm_1deg": within, "within_fraction": within / len(answers),
            "found_beyond_10cm": far,
            "error_cm_median": 100 * float(np.median(translation_errors)) if found else None,
            "error_cm_max": 100 * max(translation_errors) if found else None,
            "error_deg_median": float(np.median(rotation_errors)) if found else None,
            "error_deg_max": max(rotation_errors) if found else None})
    if args.foreign:
        calib, images = args.foreign[0], args.foreign[1:]
        for image in images:
            answers.append(locate(args.localizer, args.map, image, calib))
        figures.update({"images": len(images),
                        "found": sum(a["status"] == "FOUND" for a in answers),
                        "not_found_exit_3": sum(a["exit"] == 3 for a in answers)})
    walls = [a["wall_s"] for a in answers]
    figures["wall_s_median"] = float(np.median(walls))
    figures["wall_s_p99"] = float(np.percentile(walls, 99))
    if args.details:
        with open(args.details, "w", encoding="utf-8") as file:
            for answer in answers:
                answer.pop("covariance", None)
                file.write(json.dumps(answer) + "\n")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
