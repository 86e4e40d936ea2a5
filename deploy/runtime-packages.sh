#!/usr/bin/env bash
# Prints the Debian packages that provide the shared libraries the given binaries load directly
# (their ELF NEEDED entries, resolved by ldd, owner found with dpkg -S), one per line, sorted.
# apt brings in what those libraries need in turn. deploy/Dockerfile's runtime package lists
# are this output for the built binaries; deploy/check.sh compares the two.
# Usage: deploy/runtime-packages.sh BINARY...
set -euo pipefail

if [[ $# -eq 0 ]]; then
  echo "usage: $0 BINARY..." >&2
  exit 2
fi
for tool in objdump ldd dpkg; do
  command -v "$tool" >/dev/null 2>&1 || { echo "$0: '$tool' is not installed" >&2; exit 2; }
done

for binary in "$@"; do
  [[ -x "$binary" ]] || { echo "$0: '$binary' is not an executable" >&2; exit 2; }
  resolved=$(ldd "$binary")
  for soname in $(objdump -p "$binary" | awk '/^ *NEEDED/ {print $2}'); do
    # "libx.so.1 => /path (addr)", or "/path/ld-linux-x86-64.so.2 (addr)" for the loader.
    path=$(awk -v so="$soname" '$1 == so && $3 ~ /^\// {print $3; exit}
                                $1 ~ /^\// && $1 ~ ("/" so "$") {print $1; exit}' <<<"$resolved")
    [[ -n "$path" ]] || { echo "$0: $binary needs $soname, which ldd cannot find" >&2; exit 1; }
    real=$(readlink -f "$path")
    # dpkg knows the path it installed: /lib/... on merged-/usr systems, or the real path.
    owner=$(dpkg -S "$path" 2>/dev/null || dpkg -S "$real" 2>/dev/null || \
            dpkg -S "${real#/usr}" 2>/dev/null || true)
    [[ -n "$owner" ]] || { echo "$0: no Debian package owns $real ($soname)" >&2; exit 1; }
    echo "${owner%%:*}"
  done
done | sort -u
