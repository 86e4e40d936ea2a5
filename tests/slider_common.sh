# Shared by the tests on ECD slider_depth (tests/slider_*_test.sh); sourced, not run.
#   source slider_common.sh BUILD_DIR NAME
# Sets build_dir, source_dir, data (the slider_depth folder) and out (a fresh temporary folder
# evloc-slider-NAME.XXXXXX); exits 77 (skipped, with the reason) without the data or COLMAP.
# Defines fail MESSAGE, and build_slider_map DIR and make_slider_events DIR, the map from the
# frames at the slider poses and the events made from the frames that both tests use.
# Env: EVLOC_DATA_DIR (default: the shared data folder beside the project root).

build_dir=$(cd "${1:?usage: $(basename "$0") BUILD_DIR}" && pwd)
source_dir=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
data=${EVLOC_DATA_DIR:-$(dirname "$source_dir")/shared/data}/ecd/slider_depth
if [[ ! -f "$data/images.txt" ]]; then
  echo "SKIPPED: ECD slider_depth not found in $data (set EVLOC_DATA_DIR to the data folder)"
  exit 77
fi
if ! command -v colmap >/dev/null 2>&1; then
  echo "SKIPPED: colmap is not installed (scripts/install-deps.sh installs it)"
  exit 77
fi

out=$(mktemp -d "${TMPDIR:-/tmp}/evloc-slider-$2.XXXXXX")
fail() {
  echo "FAIL: $*; outputs kept in $out"
  exit 1
}

# build_slider_map DIR: the map from the 87 frames at the slider poses, in a fresh COLMAP
# workspace (DIR.colmap-workspace).
build_slider_map() {
  "$build_dir/mapper/evloc-mapper" build --images "$data" --images-list "$data/images.txt" \
    --calib "$data/calib.txt" --known-poses "$data/groundtruth.txt" --out "$1" --quiet ||
    fail "evloc-mapper build $1"
}

# make_slider_events DIR: events made from the frames (ESIM contrast 0.5, docs/simulator.md).
make_slider_events() {
  "$build_dir/tools/sim/evloc-sim" events-from-frames --in "$data" --out "$1" \
    --contrast 0.5 --force >"$1.log" || fail "evloc-sim events-from-frames"
}
