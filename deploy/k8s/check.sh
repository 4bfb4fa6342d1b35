#!/usr/bin/env bash
# Renders every overlay in deploy/k8s/overlays with `kubectl kustomize` and checks the objects with
# deploy/k8s/check-manifests.js: the Kubernetes schemas (npm kubernetes-models), and that images, commands,
# flags, ports, probes, ConfigMap keys and the scene's patches match what the executables accept (their
# --help); and the compose demo's commands (deploy/container/compose.yaml) against the same --help. kubernetes-models and yaml come from npm into the git-ignored tools folder (<repo>/.tools/k8s;
# RUFFINI_TOOLS_DIR overrides <repo>/.tools), installed on first use, as deploy/lint-proto.sh does for buf.
# Usage: deploy/k8s/check.sh [--bin DIR]   (DIR: the built executables; default <repo>/build/release/bin)
# Exit codes: 0 clean; 1 findings (printed); 2 usage; 77 could not run (no kubectl, node or npm, or the npm
# install failed): SKIPPED and why (ctest reports the test as skipped).
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
bin=$repo/build/release/bin
if [[ "${1:-}" == "--bin" && -n "${2:-}" ]]; then bin=$2
elif (($# > 0)); then echo "usage: $0 [--bin DIR]" >&2; exit 2; fi

if ! command -v kubectl >/dev/null 2>&1; then
  echo "k8s-check: SKIPPED: kubectl is not installed (Debian: apt-get install kubernetes-client)"; exit 77
fi
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  echo "k8s-check: SKIPPED: node or npm is not available (Debian: apt-get install npm)"; exit 77
fi
tools=${RUFFINI_TOOLS_DIR:-$repo/.tools}/k8s
if [[ ! -f "$tools/node_modules/kubernetes-models/package.json" || ! -f "$tools/node_modules/yaml/package.json" ]]; then
  echo "k8s-check: installing kubernetes-models and yaml into $tools"
  mkdir -p "$tools"
  if ! timeout 150 npm install --no-save --no-audit --no-fund --fetch-retries=1 --fetch-timeout=30000 \
      --prefix "$tools" kubernetes-models yaml >"$tools/npm-install.log" 2>&1 \
      || [[ ! -f "$tools/node_modules/kubernetes-models/package.json" ]]; then
    echo "k8s-check: SKIPPED: npm could not install kubernetes-models (log: $tools/npm-install.log)"
    tail -n 5 "$tools/npm-install.log" || true
    exit 77
  fi
fi

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for exe in ruffini-sim ruffini-decoder ruffini-aggregator ruffini-controller; do
  if [[ -x "$bin/$exe" ]]; then "$bin/$exe" --help >"$work/$exe.help" 2>&1 || true; fi
done
echo "k8s-check: $(kubectl version --client 2>/dev/null | head -n 1); kubernetes-models $(node -p "require('$tools/node_modules/kubernetes-models/package.json').version")"

status=0
for overlay in "$repo"/deploy/k8s/overlays/*/; do
  name=$(basename "$overlay")
  if ! kubectl kustomize "$overlay" >"$work/$name.yaml" 2>"$work/$name.err"; then
    echo "k8s-check: FAIL: kubectl kustomize $overlay"; cat "$work/$name.err"; status=1; continue
  fi
  NODE_PATH=$tools/node_modules node "$repo/deploy/k8s/check-manifests.js" --rendered "$work/$name.yaml" \
    --help-dir "$work" --repo "$repo" --overlay "$name" --compose "$repo/deploy/container/compose.yaml" || status=1
done
exit "$status"
