#!/usr/bin/env bash
# Checks the deployment files as far as a machine without a container engine or a cluster allows
# (docs/deploy.md, "What was validated"):
#   1. deploy/Dockerfile: linted (dockerfile-utils), and the policy of docs/deploy.md (Debian 12
#      base, a non-root numeric USER and a gRPC HEALTHCHECK in the final stage; its default
#      command serves with TLS and tokens, never --insecure, and metrics on loopback);
#   2. Kubernetes manifests: every file under deploy/k8s parses and passes the Kubernetes JSON
#      schemas with no unknown field (deploy/tools/validate-k8s.mjs); the base passes the security
#      policy (TLS, tokens, no --insecure, a NetworkPolicy, readiness on evloc.api.Localizer and
#      liveness on the overall health; validate-k8s.mjs --policy secure);
#      with kubectl present, every kustomization is rendered and its output validated the same
#      way, with the policy dev-insecure for overlays/dev-insecure only and secure for the rest;
#   3. deploy/systemd: systemd-analyze verify, with the unit pointing at a built evloc-localizer;
#   4. deploy/runtime-packages.sh (which the Dockerfile's build stage runs) on the built binaries;
#   5. the shell scripts: shellcheck, when installed;
#   6. deploy/haproxy: TLS on the frontend and verified TLS to every replica, and haproxy -c when
#      haproxy is installed.
# Usage: deploy/check.sh [BUILD_DIR]   (BUILD_DIR holds the built evloc-localizer; default build)
# Exit status: 0 passed, 1 a check failed, 77 the tools are not installed (run
# scripts/install-deploy-tools.sh); ctest reports 77 as skipped.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD_DIR=${1:-$ROOT/build}
# Absolute: the systemd unit's ExecStart must be an absolute path.
if [[ -d "$BUILD_DIR" ]]; then BUILD_DIR=$(cd "$BUILD_DIR" && pwd); fi
TOOLS="$ROOT/deploy/tools"
failures=0

fail() {
  echo "check: FAILED: $*" >&2
  failures=$((failures + 1))
}

if ! command -v node >/dev/null 2>&1 || [[ ! -d "$TOOLS/node_modules/kubernetes-models" ]] ||
   [[ ! -x "$TOOLS/node_modules/.bin/dockerfile-utils" ]]; then
  echo "check: SKIPPED: the checkers are not installed (node and deploy/tools/node_modules);" \
       "run scripts/install-deploy-tools.sh" >&2
  exit 77
fi

# 1. The container build file.
echo "check: linting deploy/Dockerfile (dockerfile-utils)"
lint=$("$TOOLS/node_modules/.bin/dockerfile-utils" lint "$ROOT/deploy/Dockerfile" 2>&1) || true
if [[ -n "$lint" ]]; then
  echo "$lint" >&2
  fail "dockerfile-utils reports problems in deploy/Dockerfile"
fi
# The final stage, with continuation lines joined.
final_stage=$(awk '/\\$/ {sub(/\\$/, ""); held = held $0; next}
                   {line = held $0; held = ""}
                   line ~ /^FROM / {stage = ""}
                   {stage = stage line "\n"}
                   END {printf "%s", stage}' "$ROOT/deploy/Dockerfile")
grep -Eq '^FROM debian:12(-slim)?( |$)' <<<"$final_stage" ||
  fail "the final stage of deploy/Dockerfile is not based on debian:12"
user=$(grep -E '^USER ' <<<"$final_stage" | tail -1 | awk '{print $2}')
[[ "$user" =~ ^[1-9][0-9]*(:[1-9][0-9]*)?$ ]] ||
  fail "the final stage of deploy/Dockerfile must run as a numeric non-root USER (got '${user}')"
grep -q 'HEALTHCHECK.*--health-check' <<<"$final_stage" ||
  fail "the final stage of deploy/Dockerfile has no gRPC HEALTHCHECK"
# The default command of the image: secure (docs/deploy.md, "Secure defaults").
command_line=$(grep -E '^CMD ' <<<"$final_stage" | tail -1)
for flag in --tls-cert --tls-key --auth-tokens; do
  grep -q -- "\"$flag\"" <<<"$command_line" ||
    fail "the default CMD of deploy/Dockerfile has no $flag (the image must serve with TLS and tokens)"
done
grep -q -- '--insecure' <<<"$command_line" && fail "the default CMD of deploy/Dockerfile has --insecure"
grep -Eq -- '"--metrics", "(127\.[0-9.]+:)?[0-9]+"' <<<"$command_line" ||
  fail "the default CMD of deploy/Dockerfile must serve metrics on loopback (--metrics 127.0.0.1:PORT)"
grep -q 'HEALTHCHECK.*--tls-ca' <<<"$final_stage" ||
  fail "the HEALTHCHECK of deploy/Dockerfile must speak TLS (--tls-ca) to the TLS server"
while read -r stage; do
  grep -Eq "^FROM debian:12(-slim)? AS ${stage}\$" "$ROOT/deploy/Dockerfile" ||
    fail "stage '${stage}' of deploy/Dockerfile is not based on debian:12"
done < <(awk '/^FROM /{print $NF}' "$ROOT/deploy/Dockerfile")

# 2. The Kubernetes manifests, file by file and as kustomize renders them.
echo "check: validating the Kubernetes manifests (kubernetes-models schemas, unknown fields)"
mapfile -t manifests < <(find "$ROOT/deploy/k8s" -name '*.yaml' | sort)
node "$TOOLS/validate-k8s.mjs" "${manifests[@]}" || fail "Kubernetes manifests"
echo "check: the security policy of deploy/k8s/base (TLS, tokens, NetworkPolicy)"
mapfile -t base_manifests < <(find "$ROOT/deploy/k8s/base" -name '*.yaml' ! -name kustomization.yaml | sort)
node "$TOOLS/validate-k8s.mjs" --policy secure "${base_manifests[@]}" || fail "security policy of deploy/k8s/base"
[[ -f "$ROOT/deploy/k8s/overlays/dev-insecure/kustomization.yaml" ]] ||
  fail "deploy/k8s/overlays/dev-insecure is missing (the only place plaintext is allowed)"
if command -v kubectl >/dev/null 2>&1; then
  while read -r kustomization; do
    dir=$(dirname "$kustomization")
    if grep -q '^kind: Component' "$kustomization"; then continue; fi
    policy=secure
    [[ "$(basename "$dir")" == dev-insecure ]] && policy=dev-insecure
    echo "check: rendering ${dir#"$ROOT"/} (kubectl kustomize; policy $policy)"
    if rendered=$(kubectl kustomize "$dir" 2>&1); then
      node "$TOOLS/validate-k8s.mjs" --policy "$policy" - <<<"$rendered" || fail "rendered ${dir#"$ROOT"/}"
    else
      echo "$rendered" >&2
      fail "kubectl kustomize ${dir#"$ROOT"/}"
    fi
  done < <(find "$ROOT/deploy/k8s" -name kustomization.yaml | sort)
else
  echo "check: kubectl is not installed: the kustomizations were not rendered (files checked one" \
       "by one only)"
fi

# 3. The systemd unit, pointed at a built binary (verify needs ExecStart to exist).
if command -v systemd-analyze >/dev/null 2>&1 && [[ -x "$BUILD_DIR/localizer/service/evloc-localizer" ]]; then
  echo "check: verifying deploy/systemd/evloc-localizer.service (systemd-analyze verify)"
  unit_dir=$(mktemp -d)
  trap 'rm -rf "$unit_dir"' EXIT
  sed "s|/usr/local/bin/evloc-localizer|$BUILD_DIR/localizer/service/evloc-localizer|" \
    "$ROOT/deploy/systemd/evloc-localizer.service" > "$unit_dir/evloc-localizer.service"
  verify=$(systemd-analyze verify "$unit_dir/evloc-localizer.service" 2>&1) || true
  if [[ -n "$verify" ]]; then
    echo "$verify" >&2
    fail "systemd-analyze verify reports problems in deploy/systemd/evloc-localizer.service"
  fi
else
  echo "check: systemd unit not verified (needs systemd-analyze and $BUILD_DIR/localizer/service/evloc-localizer)"
fi

# 4. The runtime package derivation the Dockerfile runs, on the binaries built here.
binaries=()
for binary in localizer/service/evloc-localizer tools/replay/evloc-replay mapper/evloc-mapper; do
  [[ -x "$BUILD_DIR/$binary" ]] && binaries+=("$BUILD_DIR/$binary")
done
if [[ ${#binaries[@]} -gt 0 ]]; then
  echo "check: deriving the runtime packages of ${#binaries[@]} built binaries (deploy/runtime-packages.sh)"
  if packages=$("$ROOT/deploy/runtime-packages.sh" "${binaries[@]}"); then
    echo "check: runtime packages: $(tr '\n' ' ' <<<"$packages")"
  else
    fail "deploy/runtime-packages.sh on ${binaries[*]}"
  fi
else
  echo "check: no built binaries in $BUILD_DIR: runtime package derivation not exercised"
fi

# 5. The shell scripts of deploy/ and the scale-out test.
if command -v shellcheck >/dev/null 2>&1; then
  echo "check: shellcheck of the deployment scripts"
  shellcheck "$ROOT/deploy/check.sh" "$ROOT/deploy/runtime-packages.sh" \
    "$ROOT/scripts/install-deploy-tools.sh" "$ROOT/scripts/scale-out-test.sh" || fail "shellcheck"
else
  echo "check: shellcheck is not installed: scripts not checked"
fi

# 6. The HAProxy configuration: TLS towards the clients and verified TLS towards the replicas.
haproxy_cfg="$ROOT/deploy/haproxy/evloc-localizer.cfg"
grep -Eq '^\s*bind .* ssl crt ' "$haproxy_cfg" || fail "deploy/haproxy: the frontend does not bind with TLS (ssl crt)"
grep -Eq '^\s*default-server .*ssl verify required ca-file ' "$haproxy_cfg" ||
  fail "deploy/haproxy: the replicas are not reached over verified TLS (default-server ssl verify required)"
if grep -Eq '^\s*server .*(verify none|no-ssl)' "$haproxy_cfg"; then
  fail "deploy/haproxy: a server line turns TLS or its verification off"
fi
if command -v haproxy >/dev/null 2>&1 && command -v openssl >/dev/null 2>&1; then
  echo "check: haproxy -c deploy/haproxy/evloc-localizer.cfg"
  pki=$(mktemp -d)
  openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 1 \
    -subj /CN=localhost -keyout "$pki/key.pem" -out "$pki/cert.pem" > /dev/null 2>&1
  cat "$pki/cert.pem" "$pki/key.pem" > "$pki/proxy.pem"
  if ! result=$(EVLOC_PROXY_BIND=127.0.0.1:50999 EVLOC_PROXY_CERT="$pki/proxy.pem" \
       EVLOC_BACKEND_CA="$pki/cert.pem" EVLOC_BACKEND_SERVER_NAME=localhost \
       EVLOC_BACKEND_1=127.0.0.1:1 EVLOC_BACKEND_2=127.0.0.1:2 EVLOC_BACKEND_3=127.0.0.1:3 \
       haproxy -c -f "$haproxy_cfg" 2>&1); then
    echo "$result" >&2
    fail "haproxy -c deploy/haproxy/evloc-localizer.cfg"
  fi
  rm -rf "$pki"
else
  echo "check: haproxy or openssl is not installed: deploy/haproxy not checked with haproxy -c"
fi

if [[ $failures -gt 0 ]]; then
  echo "check: $failures check(s) failed" >&2
  exit 1
fi
echo "check: all deployment checks passed"
