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

# shellcheck source=tests/slider_common.sh
source "$(dirname "$0")/slider_common.sh" "${1:-}" repro

crcs=()
for run in 1 2; do
  # Each build gets its own fresh COLMAP workspace (MAPDIR.colmap-workspace).
  build_slider_map "$out/map$run"
  crcs+=("$("$build_dir/mapper/evloc-mapper" info "$out/map$run" |
    sed -n 's/^content CRC32C: *//p')")
done
echo "content_crc32c: ${crcs[0]} ${crcs[1]}"
[[ -n "${crcs[0]}" && "${crcs[0]}" == "${crcs[1]}" ]] || fail "the two maps differ"

make_slider_events "$out/events"
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
