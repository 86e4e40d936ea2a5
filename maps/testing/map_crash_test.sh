#!/usr/bin/env bash
# Crash safety of map writing (issue 14, docs/reliability.md §5): kills a map writer with SIGKILL
# at a random one of its write/fsync/rename/close calls (maps/testing/fault_injection_shim.c,
# LD_PRELOAD), RUNS times, and checks after each kill that the map folder still holds a map that
# loads (`evloc-mapper info`: header, checksums, Map::Check) and is either the old or the new
# version (content CRC32C), and that nothing a map folder reader would take for a map is left.
# Every 10th run a clean write follows the kill and must leave no staging file behind.
#
# Writers: `evloc-mapper import-pcd --force` (WriteMapDirectory, the mapper's write path) and,
# when EVLOC_CRASH_UPGRADE_MAP (a map directory) and EVLOC_CRASH_UPGRADE_IMAGES (its keyframe
# images) are set, `evloc-mapper upgrade --force` in place (SaveMap plus the .bak copy of the
# old file), alternating.
#
# Usage: map_crash_test.sh BUILD_DIR SHIM RUNS [SEED]
# Prints one line per outcome count; exits 1 when any map was broken, missing or polluted.
set -euo pipefail

build=$1
shim=$2
runs=$3
seed=${4:-14}
mapper="$build/mapper/evloc-mapper"
source_dir=$(cd "$(dirname "$0")/../.." && pwd)
for file in "$mapper" "$shim"; do
  [[ -e $file ]] || { echo "map_crash_test: missing $file (build evloc-mapper and evloc_fault_injection_shim)" >&2; exit 2; }
done
work=$(mktemp -d "${TMPDIR:-/tmp}/evloc-map-crash.XXXXXX")
trap 'rm -rf "$work"' EXIT

# Two small PCD maps (a 10 x 10 and a 12 x 12 grid of points on a wall with normals).
write_pcd() {  # N OUT
  local n=$1 out=$2
  {
    printf 'VERSION 0.7\nFIELDS x y z normal_x normal_y normal_z\nSIZE 4 4 4 4 4 4\n'
    printf 'TYPE F F F F F F\nCOUNT 1 1 1 1 1 1\nWIDTH %d\nHEIGHT 1\n' $((n * n))
    printf 'VIEWPOINT 0 0 0 1 0 0 0\nPOINTS %d\nDATA ascii\n' $((n * n))
    awk -v n="$n" 'BEGIN { for (i = 0; i < n; ++i) for (j = 0; j < n; ++j)
      printf "%.3f %.3f 2.000 %.3f %.3f 2.000\n", i * 0.05, j * 0.05, i * 0.05 + 0.5, j * 0.05 }'
  } > "$out"
}
write_pcd 10 "$work/old.pcd"
write_pcd 12 "$work/new.pcd"

crc_of() {  # MAP -> content CRC32C, or "broken"
  local out
  if out=$("$mapper" info "$1" 2>/dev/null); then
    awk '/content CRC32C:/ { print $3 }' <<< "$out"
  else
    echo broken
  fi
}

# --- writer 1: import-pcd over an existing map directory -------------------------------------
"$mapper" import-pcd "$work/old.pcd" --out "$work/pristine_pcd/m" > /dev/null
"$mapper" import-pcd "$work/new.pcd" --out "$work/reference_pcd/m" > /dev/null
old_pcd=$(crc_of "$work/pristine_pcd/m")
new_pcd=$(crc_of "$work/reference_pcd/m")

# --- writer 2 (optional): `evloc-mapper upgrade --force` of a map directory with its images -----
# (maps/testdata/v1_small.evmap has no images; give a map made from real photos.)
upgrade_ok=0
images=${EVLOC_CRASH_UPGRADE_IMAGES:-}
if [[ -n ${EVLOC_CRASH_UPGRADE_MAP:-} && -n $images ]]; then
  mkdir -p "$work/pristine_v1"
  cp -a "$EVLOC_CRASH_UPGRADE_MAP" "$work/pristine_v1/m"
  rm -f "$work/pristine_v1/m/"*.bak
  cp -a "$work/pristine_v1" "$work/reference_v1"
  "$mapper" upgrade --map "$work/reference_v1/m" --images "$images" --force > /dev/null
  rm -f "$work/reference_v1/m/"*.bak
  old_v1=$(crc_of "$work/pristine_v1/m")
  new_v1=$(crc_of "$work/reference_v1/m")
  upgrade_ok=1
fi

# Calls counted by the shim in an undisturbed write.
count_calls() {  # WRITER
  rm -rf "$work/count" && cp -a "$work/pristine_$1" "$work/count"
  EVLOC_FAULT_COUNT_FILE="$work/calls" LD_PRELOAD="$shim" run_writer "$1" "$work/count" > /dev/null
  cat "$work/calls"
}
run_writer() {  # WRITER FOLDER
  case $1 in
    pcd) "$mapper" import-pcd "$work/new.pcd" --out "$2/m" --force ;;
    v1) "$mapper" upgrade --map "$2/m" --images "$images" --force ;;
  esac
}
declare -A calls=([pcd]=$(count_calls pcd))
writers=(pcd)
if ((upgrade_ok)); then
  calls[v1]=$(count_calls v1)
  writers+=(v1)
fi

# Failed fsyncs are errors: each fsync of an import made to fail with EIO must fail the write
# (exit 1, "cannot fsync" named) and leave the old map.
rm -rf "$work/count" && cp -a "$work/pristine_pcd" "$work/count"
EVLOC_FAULT_CALLS=fsync EVLOC_FAULT_COUNT_FILE="$work/calls" LD_PRELOAD="$shim" \
  run_writer pcd "$work/count" > /dev/null
fsyncs=$(cat "$work/calls")
failures=0
for ((n = 1; n <= fsyncs; ++n)); do
  rm -rf "$work/eio" && cp -a "$work/pristine_pcd" "$work/eio"
  status=0
  EVLOC_FAULT_CALLS=fsync EVLOC_FAULT_ACTION=eio EVLOC_FAULT_AT=$n LD_PRELOAD="$shim" \
    run_writer pcd "$work/eio" > /dev/null 2> "$work/eio.err" || status=$?
  if [[ $status == 0 ]] || ! grep -q "cannot fsync" "$work/eio.err"; then
    echo "fsync $n of $fsyncs failing with EIO: exit $status, stderr: $(cat "$work/eio.err")" >&2
    failures=$((failures + 1))
  elif [[ $(crc_of "$work/eio/m") != "$old_pcd" && $(crc_of "$work/eio/m") != "$new_pcd" ]]; then
    echo "fsync $n of $fsyncs failing with EIO left a broken map" >&2
    failures=$((failures + 1))
  fi
done
echo "fsync failures: $fsyncs fsyncs per import, each made to fail: $failures not reported"

# The non-hidden entries of a map folder and its map directory, one per line, sorted.
visible_entries() { (cd "$1" && find . -mindepth 1 -not -path '*/.*' | sort); }

RANDOM=$seed
declare -A outcome
start=$(date +%s)
for ((run = 1; run <= runs; ++run)); do
  writer=${writers[$((run % ${#writers[@]}))]}
  folder="$work/run"
  rm -rf "$folder" && cp -a "$work/pristine_$writer" "$folder"
  n=$((RANDOM * 32768 + RANDOM))
  n=$((n % ${calls[$writer]} + 1))
  status=0
  EVLOC_FAULT_AT=$n LD_PRELOAD="$shim" run_writer "$writer" "$folder" > /dev/null 2>&1 || status=$?
  crc=$(crc_of "$folder/m")
  if [[ $writer == pcd ]]; then old=$old_pcd new=$new_pcd; else old=$old_v1 new=$new_v1; fi
  if [[ $crc == "$old" ]]; then result=old
  elif [[ $crc == "$new" ]]; then result=new
  else result=broken
  fi
  # What a map folder reader sees: the non-hidden entries of the folder and of the map
  # directory must be those of the folder before the write (a built map also holds colmap/,
  # preview.png, report.json), plus the backup an in-place upgrade keeps.
  visible=$(visible_entries "$folder" | grep -v '^\./m/map\.evmap\.v[12]\.bak$' || true)
  [[ $visible == "$(visible_entries "$work/pristine_$writer")" ]] || result=polluted
  [[ $status == 137 ]] || result="$result-not-killed"
  outcome["$writer $result"]=$((${outcome["$writer $result"]:-0} + 1))
  if [[ $result != old && $result != new ]]; then
    failures=$((failures + 1))
    echo "run $run: writer $writer killed at call $n of ${calls[$writer]}: $result (crc $crc, exit $status, entries: ${visible//$'\n'/ })" >&2
  fi
  ((run % 100 == 0)) && echo "run $run: $(($(date +%s) - start)) s, $failures failures so far"
  if ((run % 10 == 0)); then
    run_writer "$writer" "$folder" > /dev/null
    leftovers=$(find "$folder" -name '*.staging-*' -o -name '*.tmp-*' | wc -l)
    [[ $(crc_of "$folder/m") == "$new" ]] || { echo "run $run: the clean write after the kill did not give the new map" >&2; failures=$((failures + 1)); }
    if ((leftovers > 0)); then
      echo "run $run: $leftovers staging files left after a clean write" >&2
      failures=$((failures + 1))
    fi
  fi
done
elapsed=$(($(date +%s) - start))
for writer in "${writers[@]}"; do
  echo "writer $writer: ${calls[$writer]} counted calls per write"
done
for key in $(printf '%s\n' "${!outcome[@]}" | tr ' ' '_' | sort); do
  echo "outcome ${key/_/ }: ${outcome[${key/_/ }]}"
done
((upgrade_ok)) || echo "upgrade writer not run (set EVLOC_CRASH_UPGRADE_MAP and EVLOC_CRASH_UPGRADE_IMAGES)"
echo "runs: $runs, failures: $failures, seconds: $elapsed"
((failures == 0))
