#!/usr/bin/env bash
# Time and memory of the chunked build against the photo count (docs/mapper.md, "Chunked build";
# docs/benchmarks.md): the first N photos of one car-park survey (evloc-sim survey, exact poses)
# built into a site, for each N: with --known-poses, or with POSES=estimated by COLMAP's mapping
# per chunk and --align-to the survey's poses (the merged camera centres' RMS after that Sim(3) is
# the centre_rms_m column). Per run: wall seconds, the build's CPU seconds
# (report.json: mapper and COLMAP), the peak RSS of the largest process (/usr/bin/time) and of the
# whole process tree (sum over the mapper, its workers and COLMAP, sampled every 0.5 s).
#
# Usage: scripts/bench-chunked-build.sh SURVEY OUT BUILD_DIR "250 500 1000 2000" [BUILD FLAGS...]
#   SURVEY: an evloc-sim survey folder (images/, images.txt, calib.yaml, groundtruth.txt)
# Prints one table row per N and writes OUT/N/ (site), OUT/N.time, OUT/N.rss, OUT/results.tsv.
set -euo pipefail
survey=$(cd "${1:?usage: bench-chunked-build.sh SURVEY OUT BUILD_DIR COUNTS [FLAGS...]}" && pwd)
out=${2:?}
build_dir=$(cd "${3:?}" && pwd)
counts=${4:?}
shift 4
mkdir -p "$out"
out=$(cd "$out" && pwd)

# Sum of the RSS (KiB) of process $1 and all its descendants.
tree_rss() {
  ps -eo pid=,ppid=,rss= | awk -v root="$1" '
    { parent[$1] = $2; rss[$1] = $3 }
    END { for (p in rss) { q = p; while (q != "" && q != 0 && q != root) q = parent[q];
                           if (q == root) total += rss[p] } print total + 0 }'
}

poses=${POSES:-known}
case "$poses" in
  known) pose_flag=--known-poses ;;
  estimated) pose_flag=--align-to ;;
  *) echo "POSES must be known or estimated, not '$poses'" >&2; exit 2 ;;
esac
printf "photos\tchunks\twall_s\tcpu_s\tpeak_process_mb\tpeak_tree_mb\tpoints\ttiles\tcentre_rms_m\n" >"$out/results.tsv"
for n in $counts; do
  rm -rf "${out:?}/$n" "$out/$n.chunks"
  # In the survey folder: its lines name images relative to the list.
  head -n "$n" "$survey/images.txt" >"$survey/images_first_$n.txt"
  echo "uptime before $n: $(uptime)"
  start=$(date +%s.%N)
  /usr/bin/time -v -o "$out/$n.time" "$build_dir/mapper/evloc-mapper" build \
    --images "$survey/images" --images-list "$survey/images_first_$n.txt" --calib "$survey/calib.yaml" \
    "$pose_flag" "$survey/groundtruth.txt" --out "$out/$n" --chunked --quiet "$@" \
    >"$out/$n.out" 2>"$out/$n.err" &
  pid=$!
  peak=0
  while kill -0 "$pid" 2>/dev/null; do
    rss=$(tree_rss "$pid")
    ((rss > peak)) && peak=$rss
    echo "$rss" >>"$out/$n.rss"
    sleep 0.5
  done
  wait "$pid" || { echo "build of $n photos failed:"; cat "$out/$n.err"; exit 1; }
  wall=$(echo "$(date +%s.%N) - $start" | bc)
  process_kb=$(sed -n 's/.*Maximum resident set size (kbytes): //p' "$out/$n.time")
  /usr/bin/python3 - "$out/$n/report.json" "$n" "$wall" "$process_kb" "$peak" >>"$out/results.tsv" <<'PY'
import json, sys
report = json.load(open(sys.argv[1]))
cpu = sum(t["cpu_seconds"] for t in report["timings"])
chunks = report["chunking"]["chunks"]
alignment = report.get("alignment")
print("\t".join([sys.argv[2], str(len(chunks)), "%.0f" % float(sys.argv[3]), "%.0f" % cpu,
                 "%.0f" % (int(sys.argv[4]) / 1024), "%.0f" % (int(sys.argv[5]) / 1024),
                 str(report["points"]), str(report["site"]["tiles"]),
                 "%.4f" % alignment["rms_m"] if alignment else "-"]))
PY
  tail -n 1 "$out/results.tsv"
  echo "uptime after $n: $(uptime)"
done
cat "$out/results.tsv"
