#!/usr/bin/env bash
# A shortened `make demo-site` (scripts/demo-site.sh, docs/demo.md "A site"): 40 survey photos,
# the chunked build into a geo-referenced site, 2 s of the vehicle through the service with WGS84
# poses, 5 photos located with a GNSS fix, the checks. Fails when the demo fails or an output it
# promises is missing.
#
# Usage: tests/demo_site_test.sh BUILD_DIR   (ctest: evloc_demo_site_test)
# Exit codes: 0 pass, 1 fail, 77 skipped (COLMAP not installed: the build extracts the photos'
# features with it for the relocalization data).
set -euo pipefail

build_dir=$(cd "${1:?usage: demo_site_test.sh BUILD_DIR}" && pwd)
source_dir=$(cd "$(dirname "$0")/.." && pwd)
if ! command -v colmap >/dev/null 2>&1; then
  echo "SKIPPED: colmap is not installed (scripts/install-deps.sh installs it)"
  exit 77
fi

out=$(mktemp -d "${TMPDIR:-/tmp}/evloc-demo-site-test.XXXXXX")
status=0
(cd "$source_dir" && BUILD_DIR="$build_dir" EVLOC_DEMO_SITE_OUT="$out/demo-site-out" \
  EVLOC_DEMO_SITE_PHOTOS=40 EVLOC_DEMO_SITE_START_M=30 EVLOC_DEMO_SITE_DURATION=2 \
  EVLOC_DEMO_SITE_QUERIES=5 scripts/demo-site.sh) || status=$?
if ((status != 0)); then
  echo "FAIL: scripts/demo-site.sh exited with status $status; outputs kept in $out"
  exit 1
fi

missing=()
for file in maps/carpark/site.manifest maps/carpark/report.json trajectory.txt \
  trajectory_wgs84.txt eval.json eval.png located.jsonl replay.json logs/server.log; do
  [[ -s "$out/demo-site-out/$file" ]] || missing+=("$file")
done
if ((${#missing[@]} > 0)); then
  echo "FAIL: the demo-site did not write: ${missing[*]}; outputs kept in $out"
  exit 1
fi
echo "PASS: the demo-site ran end to end"
rm -rf "$out"
