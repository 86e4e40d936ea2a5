#!/usr/bin/env bash
# Maps a synthetic evloc-sim sequence from its frames at the known poses and measures the map
# against the exact scene (docs/mapper.md, "Accuracy on synthetic sequences").
#
# Usage: scripts/accuracy/mapper_synthetic.sh [DATASET] [MAPDIR] [BUILD_DIR]
#   DATASET    evloc-sim dataset; rendered with `evloc-sim render --motion mid --duration 2`
#              when missing (default /tmp/demo1)
#   MAPDIR     map to build (default DATASET_map; replaced; its COLMAP workspace is reused when
#              the inputs match)
#   BUILD_DIR  build tree with evloc-mapper, evloc-mapper-accuracy, evloc-sim (default build)
# Extra evloc-mapper build flags can be passed in MAPPER_FLAGS.
# Prints the build summary, the per-stage timings (report.json) and the accuracy JSON; exits
# non-zero when a step fails.
set -euo pipefail

dataset=${1:-/tmp/demo1}
map=${2:-${dataset%/}_map}
build=${3:-build}

if [[ ! -f "$dataset/images.txt" ]]; then
  "$build/tools/sim/evloc-sim" render --out "$dataset" --motion mid --duration 2
fi
rm -rf "$map"
start=$(date +%s.%N)
# shellcheck disable=SC2086
"$build/mapper/evloc-mapper" build --images "$dataset/images" \
  --images-list "$dataset/images.txt" --calib "$dataset/calib.yaml" \
  --known-poses "$dataset/groundtruth.txt" --out "$map" ${MAPPER_FLAGS:-}
end=$(date +%s.%N)
echo "evloc-mapper build wall time: $(echo "$end - $start" | bc) s"
echo "stage timings (report.json):"
sed -n '/"timings"/,/]/p' "$map/report.json" | tr -d '\n ' | sed 's/},{/}\n{/g'
echo
echo "accuracy against $dataset (depth maps, gt_map):"
"$build/mapper/evloc-mapper-accuracy" --map "$map" --dataset "$dataset"
