#!/usr/bin/env bash
# Vendors the live viewer's front-end library (docs/viewer.md): three.js from the npm registry at
# the version pinned by localizer/service/viewer/package-lock.json (npm ci checks its integrity
# hash), copied into OUT: three.module.min.js and OrbitControls.js. The build embeds OUT's files
# into evloc-localizer (localizer/service/CMakeLists.txt runs this script when they are missing);
# nothing is fetched at run time.
# Usage: scripts/build-viewer.sh [OUT]   (default: build/viewer-vendor)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
out="${1:-$root/build/viewer-vendor}"
if ! command -v npm >/dev/null 2>&1; then
  echo "build-viewer: error: npm not found; run scripts/install-deps.sh (it installs npm)" >&2
  exit 2
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cp "$root/localizer/service/viewer/package.json" "$root/localizer/service/viewer/package-lock.json" \
  "$work/"
if ! (cd "$work" && npm ci --ignore-scripts --no-audit --no-fund --loglevel=error >/dev/null); then
  echo "build-viewer: error: 'npm ci' of three.js failed (no access to the npm registry and an" \
    "empty npm cache?)" >&2
  exit 1
fi
mkdir -p "$out"
staging="$(mktemp -d "$out/.staging.XXXXXX")"
cp "$work/node_modules/three/build/three.module.min.js" \
  "$work/node_modules/three/examples/jsm/controls/OrbitControls.js" \
  "$work/node_modules/three/LICENSE" "$staging/"
for file in three.module.min.js OrbitControls.js LICENSE; do
  mv -f "$staging/$file" "$out/$file"
done
rmdir "$staging"
echo "build-viewer: three.js $(sed -n 's/.*"version": "\(.*\)",/\1/p' "$work/node_modules/three/package.json" | head -1) in $out"
