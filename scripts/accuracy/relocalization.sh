#!/bin/bash
# Relocalization from events (docs/accuracy.md, "Relocalization from events").
#
# Usage: scripts/accuracy/relocalization.sh BUILD_DIR OUT_DIR
#   BUILD_DIR  a build with evloc-sim, evloc-mapper, evloc-track
#   OUT_DIR    where the datasets, the map and the results go (gigabytes; outside the repository)
# Env: STARTS (default "1 3 5"): --start times of the runs without a pose; BLACKOUT (default
#   "4:4.5"): the blackout of the recovery run on the map's own path (from 1 s), BLACKOUT_OTHER
#   (default "6.5:7") on the other path (from 5 s); CPU (default 1): the core runs are pinned to.
#
# The simulated hand-held room: the mapping frames (10 Hz) of one path, `--motion slow --seed 1`
# (10 s), the events of another, `--motion mid --seed 7` (8 s): a different seed draws other
# sinusoids through the camera region, 0.4-1.3 m from the first path. The map is built by
# evloc-mapper --known-poses from the first; evloc-track --init-pose none runs on the second
# from each start time, then twice with a blackout of events. False
# positives: 60 s of events of another room (scripts/accuracy/foreign_room.json, DAVIS240
# camera) and the ECD snippets of /work/shared/data/ecd/snippets, with --give-up 1 (a search
# episode ends "not_found" after 1 s and a new one starts). Each run prints one JSON line
# (relocalization_eval.py); uptime before and after. Then `evloc-localizer locate` on the frames of
# a third path and of other scenes (locate_eval.py, one JSON line each).
set -euo pipefail
if [ $# -lt 2 ]; then sed -n 2,20p "$0"; exit 2; fi
BUILD=$(realpath "$1"); OUT=$2
HERE=$(cd "$(dirname "$0")" && pwd)
SIM=$BUILD/tools/sim/evloc-sim; MAPPER=$BUILD/mapper/evloc-mapper
TRACK=$BUILD/localizer/offline/evloc-track
SNIPPETS=${SNIPPETS:-/work/shared/data/ecd/snippets}
STARTS=${STARTS:-1 3 5}
BLACKOUT=${BLACKOUT:-4:4.5}
BLACKOUT_OTHER=${BLACKOUT_OTHER:-6.5:7}
CPU=${CPU:-1}
for tool in "$SIM" "$MAPPER" "$TRACK" "$BUILD/localizer/service/evloc-localizer"; do
  [ -x "$tool" ] || { echo "relocalization: $tool is missing; build it first" >&2; exit 1; }
done
mkdir -p "$OUT"

[ -f "$OUT/mapseq/groundtruth.txt" ] ||
  "$SIM" render --out "$OUT/mapseq" --motion slow --seed 1 --duration 10 --fps 10 --force
[ -f "$OUT/evseq/groundtruth.txt" ] ||
  "$SIM" render --out "$OUT/evseq" --motion mid --seed 7 --duration 8 --fps 5 --force
[ -f "$OUT/foreign/groundtruth.txt" ] ||
  "$SIM" render --out "$OUT/foreign" --camera davis240 --scene "$HERE/foreign_room.json" \
    --motion slow --seed 3 --duration 60 --fps 1 --render-motion 6 --force
[ -f "$OUT/map_known/map.evmap" ] ||
  "$MAPPER" build --images "$OUT/mapseq/images" --images-list "$OUT/mapseq/images.txt" \
    --calib "$OUT/mapseq/calib.yaml" --known-poses "$OUT/mapseq/groundtruth.txt" \
    --out "$OUT/map_known" --colmap-workspace "$OUT/map_known.ws"

echo "uptime before: $(uptime)"
track() {  # LABEL DATASET [FLAGS...] -> runs evloc-track pinned, writes OUT/LABEL.{txt,json}
  local label=$1 dataset=$2; shift 2
  taskset -c "$CPU" "$TRACK" --map "$OUT/map_known" --dataset "$dataset" --quiet \
    --init-pose none --out "$OUT/$label.txt" --stats "$OUT/$label.json" "$@"
}
for start in $STARTS; do
  track "start$start" "$OUT/evseq" --start "$start"
  python3 "$HERE/relocalization_eval.py" "$OUT/start$start.json" "$OUT/start$start.txt" \
    "$OUT/evseq/groundtruth.txt" --label "start $start s"
done
# Recovery: on the map's own path (viewpoints in reach) and on the other path from 5 s.
track blackout_own "$OUT/mapseq" --start 1 --blackout "$BLACKOUT"
python3 "$HERE/relocalization_eval.py" "$OUT/blackout_own.json" "$OUT/blackout_own.txt" \
  "$OUT/mapseq/groundtruth.txt" --label "mapseq start 1 blackout $BLACKOUT" \
  --blackout "${BLACKOUT%%:*}" "${BLACKOUT##*:}"
track blackout "$OUT/evseq" --start 5 --blackout "$BLACKOUT_OTHER"
python3 "$HERE/relocalization_eval.py" "$OUT/blackout.json" "$OUT/blackout.txt" \
  "$OUT/evseq/groundtruth.txt" --label "evseq start 5 blackout $BLACKOUT_OTHER" \
  --blackout "${BLACKOUT_OTHER%%:*}" "${BLACKOUT_OTHER##*:}"
track foreign "$OUT/foreign" --give-up 1
python3 "$HERE/relocalization_eval.py" "$OUT/foreign.json" "$OUT/foreign.txt" \
  "$OUT/foreign/groundtruth.txt" --label "foreign room (false positives)"
for snippet in "$SNIPPETS"/*/; do
  name=$(basename "$snippet")
  track "ecd_$name" "$snippet" --ecd-size 240x180 --give-up 1
  python3 -c "
import json, sys
s = json.load(open(sys.argv[1]))
steps = s['per_step']
print(json.dumps({'label': 'ECD ' + sys.argv[2], 'steps': len(steps),
                  'seconds': steps[-1]['t_s'] - steps[0]['t_s'] if steps else 0,
                  'tracking_steps': sum(p['status'] == 'TRACKING' for p in steps)}))
" "$OUT/ecd_$name.json" "$name"
done
# Locating single frames (evloc-localizer locate): a third path, `--motion mid --seed 23`, 0.16-0.66 m
# from the map's path; then frames of scenes not in the map (the foreign room, the real DAVIS frames
# of ECD slider_depth), which must all be NOT_FOUND.
LOCALIZER=$BUILD/localizer/service/evloc-localizer
SLIDER=${SLIDER:-/work/shared/data/ecd/slider_depth}
[ -f "$OUT/locseq/groundtruth.txt" ] ||
  "$SIM" render --out "$OUT/locseq" --motion mid --seed 23 --duration 10 --fps 10 --force
/usr/bin/python3 "$HERE/locate_eval.py" "$LOCALIZER" "$OUT/map_known" --dataset "$OUT/locseq" \
  --label "locate: third path (100 frames)" --details "$OUT/locate_locseq.jsonl"
/usr/bin/python3 "$HERE/locate_eval.py" "$LOCALIZER" "$OUT/map_known" --dataset "$OUT/evseq" \
  --label "locate: the events' path (40 frames)" --details "$OUT/locate_evseq.jsonl"
/usr/bin/python3 "$HERE/locate_eval.py" "$LOCALIZER" "$OUT/map_known" \
  --foreign "$OUT/foreign/calib.yaml" "$OUT/foreign/images/"*.png \
  --label "locate: foreign room (60 frames)" --details "$OUT/locate_foreign.jsonl"
if [ -f "$SLIDER/calib.txt" ]; then
  /usr/bin/python3 "$HERE/locate_eval.py" "$LOCALIZER" "$OUT/map_known" \
    --foreign "$SLIDER/calib.txt" "$SLIDER/images/"*.png \
    --label "locate: ECD slider_depth frames" --details "$OUT/locate_slider.jsonl"
fi
echo "uptime after: $(uptime)"
