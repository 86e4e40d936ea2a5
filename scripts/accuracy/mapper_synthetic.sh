#!/usr/bin/env bash
# Maps a synthetic evloc-sim sequence from its frames and measures the map against the exact scene
# (docs/mapper.md, "Synthetic room"): with the known poses, or with COLMAP's poses aligned to the
# ground-truth poses (--align-to).
#
# Usage: scripts/accuracy/mapper_synthetic.sh [DATASET] [MAPDIR] [BUILD_DIR]
#   DATASET    evloc-sim dataset; rendered with `evloc-sim render --motion mid --duration 2`
#              when missing (default /tmp/demo1). The circling room path of docs/mapper.md:
#              scripts/accuracy/mapper_circle_trajectory.py > circle.txt;
#              evloc-sim render --out DATASET --trajectory circle.txt --fps 5
#   MAPDIR     map to build (default DATASET_map; replaced)
#   BUILD_DIR  build tree with evloc-mapper, evloc-mapper-accuracy, evloc-sim (default build)
# Env: POSES=known (default) or estimated (COLMAP mapper, then --align-to groundtruth.txt);
#      WORKSPACE: COLMAP workspace (default MAPDIR.colmap-workspace; give both runs the same one
#      and the features and matches are computed once); MAPPER_FLAGS: extra evloc-mapper flags.
# Prints the build summary, the per-stage timings (report.json: wall and CPU seconds), the
# alignment residuals (estimated poses) and the accuracy JSON; exits non-zero when a step fails.
set -euo pipefail

dataset=${1:-/tmp/demo1}
map=${2:-${dataset%/}_map}
build=${3:-build}
poses=${POSES:-known}
workspace=${WORKSPACE:-${map%/}.colmap-workspace}

if [[ ! -f "$dataset/images.txt" ]]; then
  "$build/tools/sim/evloc-sim" render --out "$dataset" --motion mid --duration 2
fi
case $poses in
  known) pose_flags=(--known-poses "$dataset/groundtruth.txt") ;;
  estimated) pose_flags=(--align-to "$dataset/groundtruth.txt") ;;
  *) echo "POSES must be known or estimated, not '$poses'" >&2; exit 2 ;;
esac
rm -rf "$map"
start=$(date +%s.%N)
# shellcheck disable=SC2086
"$build/mapper/evloc-mapper" build --images "$dataset/images" \
  --images-list "$dataset/images.txt" --calib "$dataset/calib.yaml" "${pose_flags[@]}" \
  --out "$map" --colmap-workspace "$workspace" ${MAPPER_FLAGS:-}
end=$(date +%s.%N)
echo "evloc-mapper build wall time: $(echo "$end - $start" | bc) s"
/usr/bin/python3 - "$map/report.json" <<'EOF'
import json, sys
report = json.load(open(sys.argv[1]))
print("stage timings (report.json): stage  wall s  CPU s")
for timing in report["timings"]:
    print(f"  {timing['stage']:22s} {timing['seconds']:8.2f} {timing['cpu_seconds']:8.2f}"
          + ("  (reused)" if timing["reused"] else ""))
print(f"  COLMAP {report['colmap_seconds']:.1f} s wall, {report['colmap_cpu_seconds']:.1f} s CPU; "
      f"semi-dense {report['semidense_seconds']:.1f} s wall, "
      f"{report['semidense_cpu_seconds']:.1f} s CPU")
print(f"images {report['images_registered']}/{report['images']} registered, "
      f"{report['keyframes']} keyframes, {report['sparse_points']} sparse points "
      f"(mean reprojection error {report['colmap_mean_reprojection_error_px']:.3f} px), "
      f"{report['points']} map points")
alignment = report["alignment"]
if alignment:
    print(f"COLMAP camera centres vs ground truth after the Sim(3) alignment: RMS "
          f"{alignment['rms_m'] * 100:.2f} cm, max {alignment['max_m'] * 100:.2f} cm; "
          f"orientations RMS {alignment['rotation_rms_deg']:.3f} deg, max "
          f"{alignment['rotation_max_deg']:.3f} deg")
EOF
echo "accuracy against $dataset (depth maps, gt_map):"
"$build/tools/map_accuracy/evloc-mapper-accuracy" --map "$map" --dataset "$dataset"
