#!/usr/bin/env python3
"""evloc in Python, notebook style (docs/python.md): map, track, plot.

Each `# %%` cell runs as a notebook cell (VS Code, Jupyter with jupytext) or the whole file as a
script. Without arguments it simulates a short sequence with evloc-sim (the built-in synthetic
room), builds a map from its RGB frames with evloc-mapper (known poses: COLMAP only
triangulates), tracks the events against that map with the bindings (the tracker of
evloc-track, in-process), writes the trajectory as a TUM file (evo reads it) and plots it
against the ground truth into a PNG.

    make python
    .venv/bin/python examples/python/track_and_plot.py --out python-out

Options: --out DIR (default python-out), --build DIR (the evloc build, default build/),
--dataset DIR (an existing dataset with images, events and ground truth instead of simulating),
--map DIR (an existing map: skips mapping). Exit code 0 on success, 1 on a failure (the message
says which step), 2 for a bad command line.
"""

# %% Setup: where things are, and the package.
import argparse
import os
import subprocess
import sys
import time

import numpy as np

import matplotlib

matplotlib.use("Agg")  # files only, no display needed
import matplotlib.pyplot as plt  # noqa: E402  pylint: disable=wrong-import-position

import evloc  # noqa: E402  pylint: disable=wrong-import-position

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
parser.add_argument("--out", default="python-out")
parser.add_argument("--build", default=os.path.join(ROOT, "build"))
parser.add_argument("--dataset")
parser.add_argument("--map")
args = parser.parse_args()
os.makedirs(args.out, exist_ok=True)


def run(step, command):
    """Runs one evloc tool, its output in OUT/step.log; stops the example on failure."""
    log_path = os.path.join(args.out, step + ".log")
    print(f"[{step}] {' '.join(command)}")
    start = time.monotonic()
    with open(log_path, "w", encoding="utf-8") as log:
        status = subprocess.run(command, stdout=log, stderr=subprocess.STDOUT, check=False)
    if status.returncode != 0:
        with open(log_path, encoding="utf-8") as log:
            tail = "".join(log.readlines()[-10:])
        sys.exit(f"track_and_plot: step '{step}' failed (status {status.returncode}); "
                 f"the end of {log_path}:\n{tail}")
    print(f"[{step}] done in {time.monotonic() - start:.1f} s")


def tool(relative):
    path = os.path.join(args.build, relative)
    if not os.access(path, os.X_OK):
        sys.exit(f"track_and_plot: {path} is missing: build evloc first (make python)")
    return path


# %% 1. Data: a simulated second of a camera moving slowly in front of the synthetic room.
dataset_path = args.dataset
if dataset_path is None:
    dataset_path = os.path.join(args.out, "dataset")
    run("simulate", [tool("tools/sim/evloc-sim"), "render", "--out", dataset_path, "--motion",
                     "slow", "--duration", "1", "--seed", "3", "--force"])
dataset = evloc.read_dataset(dataset_path)
print(dataset)

# %% 2. Map: evloc-mapper on the RGB frames with their poses (COLMAP triangulates).
map_path = args.map
if map_path is None:
    map_path = os.path.join(args.out, "map")
    if os.path.exists(os.path.join(map_path, "map.evmap")):
        print(f"[map] reusing {map_path}")
    else:
        run("map", [tool("mapper/evloc-mapper"), "build", "--images",
                    os.path.join(dataset.root, "images"), "--images-list",
                    os.path.join(dataset.root, "images.txt"), "--calib",
                    os.path.join(dataset.root, "calib.yaml"), "--known-poses",
                    os.path.join(dataset.root, "groundtruth.txt"), "--out", map_path,
                    "--max-keyframes", "10", "--max-features", "2048", "--no-relocalization",
                    "--quiet"])
the_map = evloc.load_map(map_path)
summary = the_map.summary()
print(f"map: {summary['num_points']} points, {summary['num_keyframes']} keyframes, "
      f"box {np.round(summary['bounding_box_min'], 2)} .. {np.round(summary['bounding_box_max'], 2)}")

# %% 3. Track: the events as NumPy arrays, through the tracker of evloc-track.
events = dataset.events().read_all()
t0, initial_pose = dataset.initial_pose()
print(f"events: {len(events)} from {events['t'][0] * 1e-9:.3f} s to {events['t'][-1] * 1e-9:.3f} s")
result = evloc.track_events(the_map, dataset.camera, events, initial_pose, t0)
print(result, f"median step {result.median_step_ms:.2f} ms")
estimate_path = os.path.join(args.out, "estimate.txt")
result.trajectory.save_tum(estimate_path)
print(f"trajectory: {estimate_path}  (evo_ape tum {dataset.root}/groundtruth.txt {estimate_path})")

# %% 4. Accuracy: position error against the ground truth at the estimate's times.
truth = dataset.ground_truth
estimate = result.trajectory
true_positions = np.stack([np.interp(estimate.timestamps, truth.timestamps, truth.positions[:, k])
                           for k in range(3)], axis=1)
errors_m = np.linalg.norm(estimate.positions - true_positions, axis=1)
rmse_cm = 100 * float(np.sqrt(np.mean(errors_m ** 2)))
tracking = sum(1 for s in result.steps.statuses if s == evloc.Status.TRACKING)
print(f"position RMSE {rmse_cm:.2f} cm over {len(estimate)} poses; "
      f"{tracking}/{len(result.steps)} steps TRACKING")

# %% 5. Plot: the path seen from above, and the error and the quality of every step.
figure, (top, error_axis) = plt.subplots(1, 2, figsize=(11, 4.5))
top.plot(truth.positions[:, 0], truth.positions[:, 2], "k-", lw=3, alpha=0.3, label="ground truth")
top.plot(estimate.positions[:, 0], estimate.positions[:, 2], "C0-", lw=1.2, label="evloc")
top.set_xlabel("x (m)")
top.set_ylabel("z (m)")
top.set_title("camera path, top view")
top.axis("equal")
top.legend()
seconds = estimate.timestamps - estimate.timestamps[0]
error_axis.plot(seconds, 100 * errors_m, "C3-", label="position error (cm)")
error_axis.set_xlabel("time (s)")
error_axis.set_ylabel("error (cm)")
quality = error_axis.twinx()
quality.plot((result.steps.t_ns - result.steps.t_ns[0]) * 1e-9, result.steps.on_edge_fraction,
             "C2-", lw=0.8, label="on-edge fraction")
quality.set_ylabel("on-edge fraction")
quality.set_ylim(0, 1)
error_axis.set_title(f"RMSE {rmse_cm:.2f} cm, {tracking}/{len(result.steps)} steps TRACKING")
figure.tight_layout()
png_path = os.path.join(args.out, "trajectory.png")
figure.savefig(png_path, dpi=110)
print(f"plot: {png_path}")
