#!/usr/bin/env bash
# Installs what the deployment checks and the scale-out test need, beyond scripts/install-deps.sh
# (docs/deploy.md): Debian packages haproxy (the gRPC proxy of scripts/scale-out-test.sh),
# the shellcheck linter, nodejs and npm; then the npm packages pinned in deploy/tools/package-lock.json
# (Kubernetes schema validation, a Dockerfile linter) into deploy/tools/node_modules (ignored by
# git). Idempotent. Usage: scripts/install-deploy-tools.sh [--check]
#   --check  only report what is missing (exit 1 if anything is)
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
TOOLS="$ROOT/deploy/tools"
PACKAGES=(haproxy shellcheck nodejs npm)

missing=()
for pkg in "${PACKAGES[@]}"; do
  # nodejs and npm may come from another source than Debian (e.g. a newer nodejs that bundles
  # npm): a working command is enough.
  case "$pkg" in
    nodejs) command -v node >/dev/null 2>&1 && continue ;;
    npm) command -v npm >/dev/null 2>&1 && continue ;;
  esac
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$pkg")
  fi
done
node_modules_ok=true
[[ -d "$TOOLS/node_modules/kubernetes-models" && -x "$TOOLS/node_modules/.bin/dockerfile-utils" ]] ||
  node_modules_ok=false

if [[ "${1:-}" == "--check" ]]; then
  status=0
  if [[ ${#missing[@]} -gt 0 ]]; then
    echo "install-deploy-tools: missing Debian packages: ${missing[*]}"
    status=1
  fi
  if [[ "$node_modules_ok" != true ]]; then
    echo "install-deploy-tools: deploy/tools/node_modules is not installed"
    status=1
  fi
  [[ $status -eq 0 ]] && echo "install-deploy-tools: everything is installed."
  exit $status
fi

if [[ ${#missing[@]} -gt 0 ]]; then
  echo "install-deploy-tools: installing Debian packages: ${missing[*]}"
  if ! command -v apt-get >/dev/null 2>&1; then
    echo "install-deploy-tools: error: apt-get not found (Debian 12 expected); install: ${missing[*]}" >&2
    exit 2
  fi
  if [[ "$(id -u)" -ne 0 ]]; then
    echo "install-deploy-tools: error: installing packages needs root; run: sudo $0" >&2
    exit 2
  fi
  export DEBIAN_FRONTEND=noninteractive
  if ! apt-cache show "${missing[0]}" >/dev/null 2>&1; then
    apt-get update -q ||
      { echo "install-deploy-tools: error: 'apt-get update' failed" >&2; exit 2; }
  fi
  apt-get install -y -q --no-install-recommends "${missing[@]}" ||
    { echo "install-deploy-tools: error: 'apt-get install' failed for: ${missing[*]}" >&2; exit 2; }
fi

if [[ "$node_modules_ok" != true ]]; then
  echo "install-deploy-tools: installing the npm packages of deploy/tools/package-lock.json"
  (cd "$TOOLS" && npm ci --no-audit --no-fund --loglevel=error) ||
    { echo "install-deploy-tools: error: 'npm ci' failed in deploy/tools (network? npm registry?)" >&2; exit 2; }
fi
echo "install-deploy-tools: done."
