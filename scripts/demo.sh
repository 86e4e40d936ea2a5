#!/usr/bin/env bash
# make demo: evloc end to end on data it makes itself (docs/demo.md).
#   1. simulate a camera circling in the synthetic room: RGB frames, events, ground truth (evloc-sim)
#   2. build a map from the RGB frames alone: COLMAP estimates the poses, the map is aligned to the
#      ground-truth poses (evloc-mapper build --align-to)
#   3. start the localizer service on loopback (evloc-localizer serve) and wait for gRPC health
#   4. stream the events to it (evloc-replay), against the built map and the simulator's exact map,
#      and once more against the built map without an initial pose (the service finds the camera)
#   5. stop the service and check that it stopped cleanly
#   6. score the trajectories against ground truth (evloc-eval), check them, print the table
# Everything goes to demo-out/ (or $EVLOC_DEMO_OUT). A failing step or check stops the demo with a
# non-zero exit, its name and the path of its log.
set -euo pipefail

BUILD_DIR=${BUILD_DIR:-build}
OUT=${EVLOC_DEMO_OUT:-demo-out}
DURATION=${EVLOC_DEMO_DURATION:-3}              # seconds of simulated camera motion
FPS=${EVLOC_DEMO_FPS:-10}                       # RGB frames per second (the mapper's input)
CAMERA=${EVLOC_DEMO_CAMERA:-default}            # evloc-sim --camera name, or an evloc camera YAML
MAX_FEATURES=${EVLOC_DEMO_MAX_FEATURES:-2048}   # SIFT features per frame for COLMAP
MAX_ATE_CM=${EVLOC_DEMO_MAX_ATE_CM:-5}          # checks: the demo fails beyond these
MIN_COVERAGE=${EVLOC_DEMO_MIN_COVERAGE:-0.9}
MAX_ALIGNMENT_CM=${EVLOC_DEMO_MAX_ALIGNMENT_CM:-3}
MAX_FIND_S=${EVLOC_DEMO_MAX_FIND_S:-1}          # without a pose: first TRACKING pose within this
# The circle: radius, distance of the point the camera keeps looking at, time for one lap.
CIRCLE_RADIUS_M=0.2
CIRCLE_LOOK_AT_M=2.0
CIRCLE_LAP_S=3.0

HERE=$(cd "$(dirname "$0")" && pwd)
TOTAL=7
# The tools, the steps, cleanup and the service (check_tools, begin, run, finish, fail,
# start_service, stop_service).
source "$HERE/demo-lib.sh"
check_tools
if ! command -v colmap >/dev/null 2>&1; then
  echo "demo: colmap is not installed: run scripts/install-deps.sh (make demo does it for you)" >&2
  exit 1
fi

DATASET="$OUT/dataset"
MAPS="$OUT/maps"
LOGS="$OUT/logs"
mkdir -p "$LOGS"

# ---------------------------------------------------------------------------------------------
begin "simulate ${DURATION} s of a camera circling in the synthetic room (evloc-sim)"
# A circle keeps the same part of the room in view with parallax in every direction: COLMAP gets
# a well-conditioned reconstruction, and the semi-dense stereo sees both horizontal and vertical
# edges move across their epipolar lines.
"$PYTHON" - "$DURATION" "$CIRCLE_RADIUS_M" "$CIRCLE_LOOK_AT_M" "$CIRCLE_LAP_S" \
  >"$OUT/circle_trajectory.txt" <<'PYTHON'
import math, sys
duration, radius, look_at, lap = (float(a) for a in sys.argv[1:5])
def unit(v):
    n = math.sqrt(sum(a * a for a in v))
    return [a / n for a in v]
def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
print("# world_from_cam of a camera circling in its image plane while looking at a point ahead")
print("# timestamp tx ty tz qx qy qz qw (camera: x right, y down, z forward; seconds, metres)")
for k in range(int(round(duration * 1000)) + 1):
    t = k / 1000
    phi = 2 * math.pi * t / lap
    c = [radius * math.cos(phi), radius * math.sin(phi), 0.0]
    z = unit([-c[0], -c[1], look_at])
    x = unit(cross([0, 1, 0], z))
    y = cross(z, x)
    w = math.sqrt(1 + x[0] + y[1] + z[2]) / 2  # the rotation stays within 6 degrees of identity
    q = [(y[2] - z[1]) / (4 * w), (z[0] - x[2]) / (4 * w), (x[1] - y[0]) / (4 * w), w]
    print(f"{t:.3f} {c[0]:.9f} {c[1]:.9f} {c[2]:.9f} {q[0]:.9f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f}")
PYTHON
FRAMES_EXPECTED=$("$PYTHON" -c "import math; print(math.floor($DURATION * $FPS))")
sim_progress() {
  local written
  written=$(find "$DATASET.partial/images" -name '*.png' 2>/dev/null | wc -l)
  echo "$written of about $FRAMES_EXPECTED frames rendered"
}
if [[ "$CAMERA" == *.yaml || "$CAMERA" == *.yml ]]; then
  CAMERA_FLAG=(--camera-yaml "$CAMERA")
else
  CAMERA_FLAG=(--camera "$CAMERA")
fi
run "$LOGS/1-simulate.log" sim_progress \
  "$SIM" render --out "$DATASET" "${CAMERA_FLAG[@]}" --trajectory "$OUT/circle_trajectory.txt" \
  --duration "$DURATION" --fps "$FPS" --seed 1 --force
finish

# ---------------------------------------------------------------------------------------------
begin "build a map from the RGB frames: COLMAP poses, aligned to ground truth (evloc-mapper)"
rm -rf "$MAPS"
mkdir -p "$MAPS"
map_progress() {
  local log line
  log=$(find "$OUT/colmap-workspace/logs" -name '*.log' -printf '%T@ %p\n' 2>/dev/null |
    sort -n | tail -n 1 | cut -d' ' -f2-)
  [[ -n "$log" ]] || return 0
  line=$(grep -E 'Processed file \[|Matching image \[|Registering image #' "$log" | tail -n 1)
  echo "COLMAP $(basename "$log" .log)${line:+: $line}"
}
run "$LOGS/2-map.log" map_progress \
  "$MAPPER" build --images "$DATASET/images" --images-list "$DATASET/images.txt" \
  --calib "$DATASET/calib.yaml" --align-to "$DATASET/groundtruth.txt" --out "$MAPS/room" \
  --colmap-workspace "$OUT/colmap-workspace" --max-keyframes 15 --max-features "$MAX_FEATURES"
# COLMAP can return a model that is wrong yet complete (a collapsed or bent path); the alignment
# residual to the ground-truth camera centres shows it.
"$PYTHON" - "$MAPS/room/report.json" "$MAX_ALIGNMENT_CM" >"$LOGS/2-map-check.log" <<'PYTHON' ||
import json, sys
report, bound = json.load(open(sys.argv[1])), float(sys.argv[2])
alignment = report["alignment"]
rms, worst = alignment["rms_m"] * 100, alignment["max_m"] * 100
rotation = (f", orientations RMS {alignment['rotation_rms_deg']:.3f} deg"
            if "rotation_rms_deg" in alignment else "")
print(f"{report['images_registered']}/{report['images']} frames registered by COLMAP, "
      f"{report['points']} map points from {report['keyframes']} keyframes; COLMAP's cameras vs "
      f"ground truth after the Sim(3) alignment: centres RMS {rms:.2f} cm, worst {worst:.2f} cm"
      f"{rotation}")
if report["images_registered"] < report["images"]:
    sys.exit("COLMAP left frames out: the reconstruction is incomplete")
if not rms <= bound:
    sys.exit(f"the COLMAP poses are off by {rms:.1f} cm RMS (bound {bound} cm): the model is wrong "
             "(see colmap/ and logs/ in the map folder)")
PYTHON
  fail "the map does not pass its check" "$LOGS/2-map-check.log"
sed 's/^/   /' "$LOGS/2-map-check.log"
# The simulator's exact map, served next to the built one for comparison.
cp -r "$DATASET/gt_map" "$MAPS/room-exact"
finish

# ---------------------------------------------------------------------------------------------
begin "start the localizer service on loopback and wait until gRPC health says SERVING"
start_service "$MAPS"
finish

# ---------------------------------------------------------------------------------------------
# As fast as the service keeps up (--speed max): evloc-replay keeps at most 5 ms of events ahead
# of the last pose, so it never overruns the session's queue however loaded the machine is, and
# the latency is that of a camera whose packets arrive just ahead of the tracker. At real time a
# loaded machine that falls behind for a moment ends the session (RESOURCE_EXHAUSTED).
# replay MAP NAME [FLAGS...]: one session on MAP, written as trajectory_NAME.txt, replay_NAME.json.
replay() {
  local map=$1 name=$2
  shift 2
  run "$LOGS/4-replay-$name.log" "" \
    "$REPLAY" --server "127.0.0.1:$PORT" --map "$map" --dataset "$DATASET" --speed max \
    --max-lead-ms 5 --out "$OUT/trajectory_$name.txt" --report "$OUT/replay_$name.json" "$@"
}
begin "stream the events to the service: built map, exact map, and built map without a pose"
replay room room
replay room-exact room-exact
# A client that does not know where it is: no initial pose, the service finds the camera in the
# map from the events alone (INITIALIZING until a pose is verified, docs/relocalization.md).
replay room room-nopose --init-pose none
finish

# ---------------------------------------------------------------------------------------------
begin "stop the service (SIGTERM) and check that it stopped cleanly"
stop_service
finish

# ---------------------------------------------------------------------------------------------
begin "score the trajectories against ground truth (evloc-eval) and check them"
for map in room room-exact room-nopose; do
  run "$LOGS/6-eval-$map.log" "" \
    "$EVAL" --gt "$DATASET/groundtruth.txt" --est "$OUT/trajectory_$map.txt" \
    --json "$OUT/eval_$map.json" --plot "$OUT/eval_$map.png"
done
"$PYTHON" - "$OUT" "$MAX_ATE_CM" "$MIN_COVERAGE" "$MAX_FIND_S" >"$LOGS/6-check.log" <<'PYTHON' ||
import json, sys
out, max_ate, min_coverage, max_find = (sys.argv[1], float(sys.argv[2]), float(sys.argv[3]),
                                        float(sys.argv[4]))
bad = []
found = json.load(open(f"{out}/replay_room-nopose.json"))["first_tracking_s"]
print(f"room-nopose: first TRACKING pose {found} s after the first event")
if found is None or not found <= max_find:
    bad.append(f"room-nopose: the service did not find the camera within {max_find} s of events")
times = [float(line.split()[0]) for line in open(f"{out}/dataset/groundtruth.txt")
         if line.strip() and not line.startswith("#")]
span = times[-1] - times[0]
for name in ("room", "room-exact", "room-nopose"):
    e = json.load(open(f"{out}/eval_{name}.json"))
    coverage = e["coverage"]
    if name == "room-nopose" and found is not None:
        # Before it was found the session had no pose to give: its coverage counts from then.
        coverage = min(1.0, coverage * span / (span - found))
    print(f"{name}: ATE {e['ate_t_rmse_cm']:.2f} cm, coverage {coverage:.3f}")
    if not e["ate_t_rmse_cm"] <= max_ate:
        bad.append(f"{name}: ATE {e['ate_t_rmse_cm']:.2f} cm is above {max_ate} cm")
    if not coverage >= min_coverage:
        bad.append(f"{name}: coverage {coverage:.3f} is below {min_coverage}")
if bad:
    sys.exit("; ".join(bad) + f" (plots: {out}/eval_*.png)")
PYTHON
  fail "a trajectory is not good enough to report" "$LOGS/6-check.log"
finish

# ---------------------------------------------------------------------------------------------
begin "write the summary"
"$PYTHON" - "$OUT" "$DURATION" "$CAMERA" "$FPS" >"$OUT/summary.txt" <<'PYTHON'
import json, sys
out, duration, camera, fps = sys.argv[1], float(sys.argv[2]), sys.argv[3], sys.argv[4]
def load(path):
    return json.load(open(f"{out}/{path}"))
info, report = load("dataset/info.json"), load("maps/room/report.json")
speed = info["motion_measured"]
print(f"Sequence: {duration:g} s of a camera circling (radius 20 cm, {speed['peak_linear_m_per_s']:.2f} m/s, "
      f"{speed['peak_angular_deg_per_s']:.0f} deg/s) in the synthetic room,")
print(f"{info['camera']['width']}x{info['camera']['height']} camera '{camera}', "
      f"{info['counts']['events'] / 1e6:.2f} M events, {info['counts']['frames']} RGB frames at {fps} Hz.")
print(f"Map: {report['points']} points from {report['keyframes']} keyframes; COLMAP registered "
      f"{report['images_registered']}/{report['images']} frames without their poses;")
print(f"its camera centres fit the ground-truth ones (Sim(3)) with RMS "
      f"{report['alignment']['rms_m'] * 100:.2f} cm (the map's frame is the ground truth's).")
print()
print("Tracking: the events streamed through the gRPC service (evloc-replay --speed max, at most")
print("5 ms of events ahead of the last pose). ATE/RPE: no alignment, association 0.02 s, RPE over")
print("1 s (docs/accuracy.md). cover: time covered by poses. Mev/s: events / replay wall time.")
print("speed: sequence duration / replay wall time (1x = real time). p50/p99 ms: latency from")
print("packet sent to pose received, loopback. The paper's rows are ITS figures on ITS sequences")
print("(Table 'RPE and ATE on self-collected, VECtor and TUM datasets'), not on this one.")
columns = (f"{'ATE cm':>6} {'ATE deg':>7} {'RPE cm/s':>8} {'RPE deg/s':>9} {'cover':>6} {'LOST':>4} "
           f"{'Mev/s':>5} {'speed':>5} {'p50/p99 ms':>12}")
header = f"{'run':41} {columns}"
print(header)
print("-" * len(header))
for label, name in (("evloc, map built from the frames", "room"),
                    ("evloc, the simulator's exact map", "room-exact"),
                    ("evloc, built map, started without a pose", "room-nopose")):
    e, r = load(f"eval_{name}.json"), load(f"replay_{name}.json")
    rate = r["events_sent"] / r["wall_s"] / 1e6
    latency = f"{r['client_latency_p50_us'] / 1000:.1f}/{r['client_latency_p99_us'] / 1000:.1f}"
    # RPE is null when no pair of poses spans its delta (a short run found late).
    rpe_t, rpe_r = e["rpe_t_rmse_cm_s"], e["rpe_r_rmse_deg_s"]
    rpe_t = f"{rpe_t:8.2f}" if rpe_t is not None else f"{'n/a':>8}"
    rpe_r = f"{rpe_r:9.2f}" if rpe_r is not None else f"{'n/a':>9}"
    print(f"{label:41} {e['ate_t_rmse_cm']:6.2f} {e['ate_r_rmse_deg']:7.2f} "
          f"{rpe_t} {rpe_r} {e['coverage'] * 100:5.1f}% "
          f"{r['lost_poses']:4d} {rate:5.2f} {duration / r['wall_s']:4.2f}x {latency:>12}")
print("-" * len(header))
paper = [("paper Canny-EVT, table_bright_mid", 1.25, 2.44, 0.94, 1.23),
         ("paper Canny-EVT, sofa_normal (VECtor)", 1.06, 1.17, 0.95, 0.96),
         ("paper Canny-EVT, fr1_xyz (TUM) [*]", 0.95, 0.006, 0.46, 0.010),
         ("paper Canny-VT (frames), table_bright_mid", 1.42, 1.79, 0.92, 1.31)]
for label, ate_cm, ate_deg, rpe_cm, rpe_deg in paper:
    print(f"{label:41} {ate_cm:6.2f} {ate_deg:7.3g} {rpe_cm:8.2f} {rpe_deg:9.3g} "
          f"{'-':>6} {'-':>4} {'-':>5} {'-':>5} {'-':>12}")
print("[*] events made from TUM frames with vid2e; its rotation figures as printed (unit doubtful).")
nopose = load("replay_room-nopose.json")
print(f"Started without a pose, the service found the camera in the built map "
      f"{nopose['first_tracking_s']:.3f} s (of events) after the first event; "
      f"{nopose['searching_updates']} updates said INITIALIZING")
print("before it (no pose invented while searching); the row's ATE and coverage count from there.")
PYTHON
finish

echo
echo "== Results"
cat "$OUT/summary.txt"
{
  echo
  echo "Steps (wall time on this machine; total $(elapsed) s):"
  printf '  %s\n' "${STEP_TIMES[@]}"
  cat <<EOF

What is where (in $OUT/):
  circle_trajectory.txt   the camera path given to evloc-sim
  dataset/                the simulated sequence: images/ (RGB frames), events.evb, groundtruth.txt,
                          calib.yaml, gt_map/ (the exact map), info.json (counts, measured speeds)
  maps/room/              the map built from the frames: map.evmap, map.ply (open in MeshLab or
                          CloudCompare), preview.png (map points over keyframes), report.json,
                          colmap/ (COLMAP's model and logs)
  maps/room-exact/        the simulator's exact map (the best a map can be)
  trajectory_room.txt     poses returned by the service (TUM: t tx ty tz qx qy qz qw)
  trajectory_room-exact.txt
  trajectory_room-nopose.txt  the session started without a pose (--init-pose none)
  eval_room.png, .json    evloc-eval: top view of estimate and ground truth, error over time
  eval_room-exact.png, .json
  replay_*.json           evloc-replay's figures (events, poses, LOST, latency)
  logs/                   one log per step; logs/server.log is the service's log
  summary.txt             this summary
EOF
} | tee -a "$OUT/summary.txt"
echo
echo "demo: done in $(elapsed) s."
