#!/usr/bin/env bash
# make demo-site: a small geo-referenced site end to end on data evloc makes itself
# (docs/demo.md, "A site").
#   1. a mapping car surveys part of the simulated car park: photos with exact poses (evloc-sim)
#   2. the chunked build turns them into a site of tiles with a WGS84 anchor (evloc-mapper build
#      --chunked --known-poses --geo-anchor: chunks built by two worker processes, merged, tiled)
#   3. a vehicle drives through the surveyed part at 5 m/s with an event camera (evloc-sim)
#   4. the localizer serves the site (evloc-localizer serve), and
#   5. the vehicle's events stream to it (evloc-replay --geo): poses in the map frame and in WGS84;
#      photos of another pass are located in the site with a 3 m GNSS fix (evloc-localizer locate)
#   6. the service stops cleanly; the poses are scored against ground truth (evloc-eval)
# Everything goes to demo-site-out/ (or $EVLOC_DEMO_SITE_OUT). A failing step or check stops the
# demo with a non-zero exit, its name and the path of its log.
set -euo pipefail

BUILD_DIR=${BUILD_DIR:-build}
OUT=${EVLOC_DEMO_SITE_OUT:-demo-site-out}
PHOTOS=${EVLOC_DEMO_SITE_PHOTOS:-60}          # survey photos, 2 m apart along the car's route
VEHICLE_START_M=${EVLOC_DEMO_SITE_START_M:-40} # where along the route the vehicle starts, metres
DURATION=${EVLOC_DEMO_SITE_DURATION:-3}       # seconds of vehicle motion at 5 m/s
QUERIES=${EVLOC_DEMO_SITE_QUERIES:-10}        # photos of another pass to locate
MAX_ATE_CM=${EVLOC_DEMO_SITE_MAX_ATE_CM:-15}  # checks: the demo fails beyond these
MIN_COVERAGE=${EVLOC_DEMO_SITE_MIN_COVERAGE:-0.9}
MIN_LOCATED=${EVLOC_DEMO_SITE_MIN_LOCATED:-0.8}
MAX_GEO_M=${EVLOC_DEMO_SITE_MAX_GEO_M:-0.001}  # WGS84 poses against the map-frame ones
# The site's anchor: a car park in Zurich, the map's +y axis 30 degrees east of north.
ANCHOR=47.3769,8.5417,408.0,30.0

HERE=$(cd "$(dirname "$0")" && pwd)
TOTAL=6
DEMO_NAME=demo-site
# The tools, the steps, cleanup and the service (check_tools, begin, run, finish, fail,
# start_service, stop_service).
source "$HERE/demo-lib.sh"
check_tools

MAPS="$OUT/maps"
LOGS="$OUT/logs"
rm -rf "$OUT"
mkdir -p "$LOGS" "$MAPS"

# ---------------------------------------------------------------------------------------------
begin "survey the car park: $PHOTOS photos of a mapping car, 2 m apart, exact poses (evloc-sim)"
run "$LOGS/1-survey.log" "" \
  "$SIM" survey --out "$OUT/survey" --survey car --spacing 2 --max-photos "$PHOTOS"
finish

# ---------------------------------------------------------------------------------------------
begin "build a geo-referenced site of tiles from the photos in chunks (evloc-mapper build --chunked)"
run "$LOGS/2-build.log" "" \
  "$MAPPER" build --images "$OUT/survey/images" --images-list "$OUT/survey/images.txt" \
  --calib "$OUT/survey/calib.yaml" --known-poses "$OUT/survey/groundtruth.txt" \
  --out "$MAPS/carpark" --chunked --chunk-size $((PHOTOS / 2)) --workers 2 \
  --tile-size 25 --tile-overlap 5 --geo-anchor "$ANCHOR"
finish

# ---------------------------------------------------------------------------------------------
begin "drive a vehicle through it at 5 m/s with a DAVIS240 event camera (evloc-sim render)"
run "$LOGS/3-vehicle.log" "" \
  "$SIM" render --out "$OUT/vehicle" --scene carpark --camera davis240 --path vehicle --speed 5 \
  --path-start "$VEHICLE_START_M" --duration "$DURATION" --map-spacing 0.2 --force
# Photos of another pass (3 m apart, 1 m off the survey's), to locate from nothing.
run "$LOGS/3-queries.log" "" \
  "$SIM" survey --out "$OUT/queries" --survey car --spacing 3 --path-start 1 \
  --max-photos "$QUERIES" --seed 2
finish

# ---------------------------------------------------------------------------------------------
begin "start the localizer service on the site and wait until gRPC health says SERVING"
# A vehicle's poses are stamped at their step time (docs/tracking.md, "Pose time": at 5 m/s the
# registered pose is about 9 cm behind), and its solves hold the smooth velocity's prediction
# (docs/tracking.md, "Motion prior").
start_service "$MAPS" --stamp-at-step-time on --motion-prior 2,0
finish

# ---------------------------------------------------------------------------------------------
begin "stream the vehicle's events to the service (evloc-replay --geo), locate photos (locate --gnss)"
run "$LOGS/5-replay.log" "" \
  "$REPLAY" --server "127.0.0.1:$PORT" --map carpark --dataset "$OUT/vehicle" --speed max \
  --max-lead-ms 5 --out "$OUT/trajectory.txt" --geo "$OUT/trajectory_wgs84.txt" \
  --report "$OUT/replay.json"
run "$LOGS/5-locate.log" "" \
  "$PYTHON" "$HERE/accuracy/locate_eval.py" "$SERVER" "$MAPS/carpark" --dataset "$OUT/queries" \
  --gnss-sigma 3 --anchor "$ANCHOR" --label "located with a 3 m GNSS fix" \
  --details "$OUT/located.jsonl"
finish

# ---------------------------------------------------------------------------------------------
begin "stop the service, score the poses against ground truth (evloc-eval) and check them"
stop_service
run "$LOGS/6-eval.log" "" \
  "$EVAL" --gt "$OUT/vehicle/groundtruth.txt" --est "$OUT/trajectory.txt" --align none \
  --json "$OUT/eval.json" --plot "$OUT/eval.png"
"$PYTHON" - "$OUT" "$MAX_ATE_CM" "$MIN_COVERAGE" "$MIN_LOCATED" "$MAX_GEO_M" "$ANCHOR" \
  "$HERE/accuracy" >"$LOGS/6-check.log" <<'PYTHON' ||
import json, sys
import numpy as np
out = sys.argv[1]
max_ate, min_coverage, min_located, max_geo = (float(a) for a in sys.argv[2:6])
anchor = [float(a) for a in sys.argv[6].split(",")]
sys.path.insert(0, sys.argv[7])
from locate_eval import map_to_wgs84  # an independent conversion (not evloc's core/geo)
bad = []
e = json.load(open(f"{out}/eval.json"))
print(f"vehicle at 5 m/s through the site: ATE {e['ate_t_rmse_cm']:.2f} cm (no alignment), "
      f"coverage {e['coverage']:.3f}")
if not e["ate_t_rmse_cm"] <= max_ate:
    bad.append(f"ATE {e['ate_t_rmse_cm']:.2f} cm is above {max_ate} cm")
if not e["coverage"] >= min_coverage:
    bad.append(f"coverage {e['coverage']:.3f} is below {min_coverage}")
# Its WGS84 poses (PoseUpdate.geodetic) against its map-frame poses through the anchor.
rows = lambda path: [l.split() for l in open(path) if l.strip() and not l.startswith("#")]
worst = 0.0
for pose, geo in zip(rows(f"{out}/trajectory.txt"), rows(f"{out}/trajectory_wgs84.txt")):
    lat, lon, alt = map_to_wgs84(np.array([float(v) for v in pose[1:4]]), anchor)
    d = np.array([(lat - float(geo[1])) * 111320.0,
                  (lon - float(geo[2])) * 111320.0 * np.cos(np.radians(lat)), alt - float(geo[3])])
    worst = max(worst, float(np.linalg.norm(d)))
print(f"WGS84 poses: within {worst * 1000:.3f} mm of the map-frame poses through the anchor")
if not worst <= max_geo:
    bad.append(f"WGS84 poses {worst:.4f} m from the map-frame ones")
located = [json.loads(line) for line in open(f"{out}/located.jsonl")]
found = sum(a["status"] == "FOUND" for a in located)
far = sum(a["status"] == "FOUND" and a["error_m"] > 0.1 for a in located)
errors = sorted(100 * a["error_m"] for a in located if a["status"] == "FOUND")
print(f"photos of another pass located in the site with a 3 m GNSS fix: {found} of "
      f"{len(located)} FOUND" + (f", error median {errors[len(errors) // 2]:.2f} cm" if errors else "")
      + f", {far} beyond 10 cm")
if found < min_located * len(located) or far > 0:
    bad.append(f"{found} of {len(located)} photos located ({far} beyond 10 cm)")
if bad:
    sys.exit("; ".join(bad) + f" (plot: {out}/eval.png)")
PYTHON
  fail "a result is not good enough to report" "$LOGS/6-check.log"
sed 's/^/   /' "$LOGS/6-check.log"
finish

echo
echo "== Results"
cat "$LOGS/6-check.log"
echo
echo "Steps (wall time on this machine; total $(elapsed) s):"
printf '  %s\n' "${STEP_TIMES[@]}"
echo
echo "demo-site: done in $(elapsed) s; everything is in $OUT/."
