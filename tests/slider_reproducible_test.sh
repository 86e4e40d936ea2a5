#!/usr/bin/env bash
# Reproducible maps on real frames (docs/mapper.md, "Reproducible maps"): the ECD slider_depth map
# (87 DAVIS240C frames at the slider poses) built twice in fresh workspaces has one
# content_crc32c, and the events made from the frames tracked against either map give
# byte-identical trajectories; the trajectory error stays within 1 cm (0.37 cm measured).
#
# Usage: tests/slider_reproducible_test.sh BUILD_DIR   (ctest: evloc_slider_reproducible_test)
# Env: EVLOC_DATA_DIR (default: the shared data folder beside the project root).
# Exit codes: 0 pass, 1 fail, 77 skipped (no slider_depth data, or COLMAP not installed).
set -euo pipefail

build_dir=$(cd "${1:?usage: slider_reproducible_test.sh BUILD_DIR}" && pwd)
source_dir=$(cd "$(dirname "$0")/.." && pwd)
data=${EVLOC_DATA_DIR:-$(dirname "$source_dir")/shared/data}/ecd/slider_depth
if [[ ! -f "$data/images.txt" ]]; then
  echo "SKIPPED: ECD slider_depth not found in $data (set EVLOC_DATA_DIR to the data folder)"
  exit 77
fi
if ! command -v colmap >/dev/null 2>&1; then
  echo "SKIPPED: colmap is not installed (scripts/install-deps.sh installs it)"
  exit 77
fi

out=$(mktemp -d "${TMPDIR:-/tmp}/evloc-slider-repro.XXXXXX")
fail() {
  echo "FAIL: $*; outputs kept in $out"
  exit 1
}

crcs=()
for run in 1 2; do
  # Each build gets its own fresh COLMAP workspace (MAPDIR.colmap-workspace).
  "$build_dir/mapper/evloc-mapper" build --images "$data" --images-list "$data/images.txt" \
    --calib "$data/calib.txt" --known-poses "$data/groundtruth.txt" --out "$out/map$run" \
    --quiet || fail "evloc-mapper build $run"
  crcs+=("$("$build_dir/mapper/evloc-mapper" info "$out/map$run" |
    sed -n 's/^content CRC32C: *//p')")
done
echo "content_crc32c: ${crcs[0]} ${crcs[1]}"
[[ -n "${crcs[0]}" && "${crcs[0]}" == "${crcs[1]}" ]] || fail "the two maps differ"

"$build_dir/tools/sim/evloc-sim" events-from-frames --in "$data" --out "$out/events" \
  --contrast 0.5 --force >"$out/events.log" || fail "evloc-sim events-from-frames"
for run in 1 2; do
  "$build_dir/localizer/offline/evloc-track" --map "$out/map$run" --dataset "$out/events" \
    --out "$out/est$run.txt" --quiet || fail "evloc-track $run"
done
cmp "$out/est1.txt" "$out/est2.txt" || fail "the two trajectories differ"
echo "trajectories identical: $(wc -l <"$out/est1.txt") lines"

"$build_dir/tools/eval/evloc-eval" --gt "$data/groundtruth.txt" --est "$out/est1.txt" \
  --align none --json "$out/eval.json" >/dev/null || fail "evloc-eval"
ate=$(sed -n 's/.*"ate_t_rmse_cm": *\([0-9.eE+-]*\).*/\1/p' "$out/eval.json")
echo "ATE translation RMSE: $ate cm"
awk -v ate="$ate" 'BEGIN { exit !(ate != "" && ate <= 1.0) }' || fail "ATE $ate cm above 1 cm"
rm -rf "$out"
echo "PASS"
