#!/usr/bin/env bash
# The chunked build resumes after a kill (docs/mapper.md, "Chunked build"): car-park survey photos
# (evloc-sim survey, 240x180, exact poses) built into a site in chunks of 12 photos twice: once in
# one go with two worker processes, once in this process killed (SIGKILL) as soon as its first
# chunk is finished and then run again. The second run must reuse the finished chunks, and both
# sites must have the same version (the CRC32C of every tile's content checksum, maps/site.h).
# Then the same photos unordered (no image list, poses by name) cut by image retrieval, once with
# two worker processes (which read the plan the first process wrote) and once in one process:
# the same site.
#
# Usage: tests/chunked_resume_test.sh BUILD_DIR   (ctest: evloc_chunked_resume_test)
# Exit codes: 0 pass, 1 fail, 77 skipped (COLMAP not installed).
set -euo pipefail

build_dir=${1:?usage: chunked_resume_test.sh BUILD_DIR}
build_dir=$(cd "$build_dir" && pwd)
mapper=$build_dir/mapper/evloc-mapper
sim=$build_dir/tools/sim/evloc-sim
out=$(mktemp -d "${TMPDIR:-/tmp}/evloc-chunked-resume.XXXXXX")
pid=""
cleanup() {
  if [[ -n "$pid" ]] && kill -0 "$pid" 2>/dev/null; then kill -9 "$pid" 2>/dev/null || true; fi
}
trap cleanup EXIT
fail() {
  echo "FAIL: $*" >&2
  exit 1
}
if ! command -v colmap >/dev/null; then
  echo "SKIP: COLMAP is not installed (apt-get install colmap)"
  exit 77
fi

"$sim" survey --out "$out/photos" --camera davis240 --max-photos 36 --spacing 1.5 --force \
  >/dev/null || fail "evloc-sim survey"
photos=$out/photos
build_args=(build --images "$photos/images" --images-list "$photos/images.txt"
  --calib "$photos/calib.yaml" --known-poses "$photos/groundtruth.txt" --chunked
  --chunk-size 12 --chunk-overlap 3 --no-relocalization --max-features 1024 --tile-size 20
  --tile-overlap 4 --quiet)

# A: in one go, two worker processes.
"$mapper" "${build_args[@]}" --out "$out/A" --workers 2 >"$out/A.txt" || fail "build A"
version_a=$(sed -n 's/.*(version \([0-9a-f]*\)).*/\1/p' "$out/A.txt")
chunks=$(sed -n 's/.* \([0-9]*\) chunks by position.*/\1/p' "$out/A.txt")
echo "A: $(cat "$out/A.txt")"
[[ -n "$version_a" && "$chunks" -ge 3 ]] || fail "build A wrote no site of >= 3 chunks"
ls "$out/A.chunks/logs/chunk_0000.log" >/dev/null || fail "build A ran no worker process"

# B: in this process, killed once its first chunk is finished.
"$mapper" "${build_args[@]}" --out "$out/B" >"$out/B1.txt" 2>&1 &
pid=$!
for _ in $(seq 1 1200); do
  [[ -f "$out/B.chunks/chunk_0000/inputs.txt" ]] && break
  kill -0 "$pid" 2>/dev/null || fail "build B ended before it was killed: $(cat "$out/B1.txt")"
  sleep 0.25
done
[[ -f "$out/B.chunks/chunk_0000/inputs.txt" ]] || fail "no chunk finished in 300 s"
kill -9 "$pid"
wait "$pid" 2>/dev/null || true
pid=""
[[ ! -e "$out/B/site.manifest" ]] || fail "the killed build left a site"
finished=$(find "$out/B.chunks" -maxdepth 2 -name inputs.txt | wc -l)
echo "killed with $finished of $chunks chunks finished"
[[ "$finished" -lt "$chunks" ]] || fail "every chunk was finished before the kill; nothing to resume"

"$mapper" "${build_args[@]}" --out "$out/B" >"$out/B2.txt" || fail "build B (resumed)"
echo "B: $(cat "$out/B2.txt")"
reused=$(sed -n 's/.* computed, \([0-9]*\) reused.*/\1/p' "$out/B2.txt")
[[ "$reused" -ge "$finished" ]] || fail "the resumed build reused $reused chunks, $finished were done"
version_b=$(sed -n 's/.*(version \([0-9a-f]*\)).*/\1/p' "$out/B2.txt")
echo "site versions: $version_a $version_b"
[[ "$version_a" == "$version_b" ]] || fail "the resumed site differs from the one built in one go"
# C and D: unordered photos cut by retrieval; C with two workers, D in one process.
awk 'NR == FNR { if ($1 !~ /^#/) pose[$1] = $2 " " $3 " " $4 " " $5 " " $6 " " $7 " " $8; next }
     { name = $2; sub(/^images\//, "", name); print name, pose[$1] }' \
  "$photos/groundtruth.txt" "$photos/images.txt" >"$out/poses_by_name.txt"
retrieval_args=(build --images "$photos/images" --calib "$photos/calib.yaml"
  --known-poses "$out/poses_by_name.txt" --chunked --chunk-by retrieval --chunk-size 12
  --chunk-overlap-photos 3 --no-relocalization --max-features 1024 --tile-size 20 --tile-overlap 4
  --quiet)
"$mapper" "${retrieval_args[@]}" --out "$out/C" --workers 2 >"$out/C.txt" || fail "build C"
echo "C: $(cat "$out/C.txt")"
"$mapper" "${retrieval_args[@]}" --out "$out/D" >"$out/D.txt" || fail "build D"
echo "D: $(cat "$out/D.txt")"
retrieval_chunks=$(sed -n 's/.* \([0-9]*\) chunks by retrieval.*/\1/p' "$out/C.txt")
[[ -n "$retrieval_chunks" && "$retrieval_chunks" -ge 3 ]] || fail "build C wrote no site of >= 3 chunks by retrieval"
grep -q '"method": "retrieval"' "$out/C.chunks/plan.json" || fail "build C's plan.json is not by retrieval"
version_c=$(sed -n 's/.*(version \([0-9a-f]*\)).*/\1/p' "$out/C.txt")
version_d=$(sed -n 's/.*(version \([0-9a-f]*\)).*/\1/p' "$out/D.txt")
echo "retrieval site versions: $version_c $version_d"
[[ -n "$version_c" && "$version_c" == "$version_d" ]] || fail "the retrieval sites built with and without workers differ"
rm -rf "$out"
echo "PASS"
