#!/usr/bin/env bash
# Runs every Google Benchmark executable built in a build directory and prints its table.
# Usage: scripts/run-benchmarks.sh [BUILD_DIR] [extra Google Benchmark flags...]
# Each benchmark is pinned to one core when `taskset` is available (figures are per core).
# Figures and the machines they were measured on are recorded in docs/benchmarks.md.
set -euo pipefail

build_dir="${1:-build}"
shift || true
if [[ ! -d "${build_dir}" ]]; then
  echo "run-benchmarks: build directory '${build_dir}' does not exist; run 'make build' first" >&2
  exit 1
fi

pin=()
if command -v taskset >/dev/null 2>&1; then
  pin=(taskset -c 0)
fi

mapfile -t benchmarks < <(find "${build_dir}" -type f -name '*_benchmark' -perm -u+x | sort)
if [[ ${#benchmarks[@]} -eq 0 ]]; then
  echo "run-benchmarks: no *_benchmark executables in '${build_dir}' (EVLOC_BUILD_BENCH=OFF?)" >&2
  exit 1
fi

status=0
for benchmark in "${benchmarks[@]}"; do
  echo "== ${benchmark#"${build_dir}"/}"
  if ! "${pin[@]}" "${benchmark}" --benchmark_counters_tabular=true "$@"; then
    echo "run-benchmarks: ${benchmark} failed" >&2
    status=1
  fi
  echo
done
exit "${status}"
