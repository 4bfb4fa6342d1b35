#!/usr/bin/env bash
# Proves deploy/k8s/check-manifests.js catches what it claims to: renders the cobot overlay, breaks one thing at
# a time (sed on the rendered YAML) and expects a failure whose message names it; the unbroken render passes.
# Usage: deploy/k8s/test-checker.sh [--bin DIR]   Exit 0 pass; 1 fail; 77 skipped (as deploy/k8s/check.sh).
set -uo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
bin=$repo/build/release/bin
[[ "${1:-}" == "--bin" && -n "${2:-}" ]] && bin=$2
tools=${RUFFINI_TOOLS_DIR:-$repo/.tools}/k8s
# check.sh installs the npm tools (or reports the skip).
"$repo/deploy/k8s/check.sh" --bin "$bin" >/dev/null; rc=$?
if ((rc == 77)); then echo "test-checker: SKIPPED (deploy/k8s/check.sh could not run)"; exit 77; fi
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
for exe in ruffini-sim ruffini-decoder ruffini-aggregator ruffini-controller; do "$bin/$exe" --help >"$work/$exe.help" 2>&1; done
kubectl kustomize "$repo/deploy/k8s/overlays/cobot" >"$work/good.yaml" 2>/dev/null || { echo "FAIL: render"; exit 1; }
run() { NODE_PATH=$tools/node_modules node "$repo/deploy/k8s/check-manifests.js" --rendered "$1" --help-dir "$work" --repo "$repo" --overlay test; }

fails=0
if run "$work/good.yaml" >"$work/out" 2>&1; then echo "ok: the cobot overlay passes"; else echo "FAIL: the cobot overlay"; cat "$work/out"; fails=1; fi
# name | sed expression (applied to the first match only where 0,/re/ is used) | text the failure must contain
cases=(
  "unknown decoder flag|s/- --rate-hz/- --rate-hertz/|does not accept --rate-hertz"
  "--insecure added|0,/- --tls-dir$/s//- --insecure/|plaintext is never deployed"
  "probe on a port the container lacks|0,/port: 50052/s//port: 50053/|is not a container port"
  "containerPort as a string (schema)|0,/containerPort: 9464/s//containerPort: \"metrics\"/|must be integer"
  "writable root filesystem|0,/readOnlyRootFilesystem: true/s//readOnlyRootFilesystem: false/|readOnlyRootFilesystem is not true"
  "privilege escalation|0,/allowPrivilegeEscalation: false/s//allowPrivilegeEscalation: true/|allowPrivilegeEscalation is not false"
  "runs as root|0,/runAsUser: 10001/s//runAsUser: 0/|is not the image's uid"
  "ConfigMap key typo|0,/key: RUFFINI_CHANNEL/s//key: RUFFINI_CHANEL/|has no key RUFFINI_CHANEL"
  "a patch not in the scene|0,/RUFFINI_PATCH: forearm_a/s//RUFFINI_PATCH: forearm_c/|is not a patch of the scene"
  "metrics bound to loopback|0,/- 0.0.0.0:9464/s//- 127.0.0.1:9464/|binds loopback"
  "another image|0,/image: localhost\/ruffini\/ruffini:dev/s//image: docker.io\/library\/debian:12/|is not ruffini/ruffini"
  "executable the image lacks|0,/- \/usr\/local\/bin\/ruffini-decoder$/s//- \/usr\/local\/bin\/ruffini-decode/|not installed by"
  "NetworkPolicy port the pod lacks|0,/- port: 9465/s//- port: 9466/|ingress port 9466"
  "aggregator address on the wrong port|s/RUFFINI_AGGREGATOR: ruffini-aggregator:50051/RUFFINI_AGGREGATOR: ruffini-aggregator:50052/|has no grpc port 50052"
)
for c in "${cases[@]}"; do
  IFS='|' read -r name expr want <<<"$c"
  sed -e "$expr" "$work/good.yaml" >"$work/bad.yaml"
  if cmp -s "$work/good.yaml" "$work/bad.yaml"; then echo "FAIL: $name: the mutation changed nothing"; fails=1; continue; fi
  if run "$work/bad.yaml" >"$work/out" 2>&1; then echo "FAIL: $name: passed"; fails=1
  elif grep -qF -- "$want" "$work/out"; then echo "ok: $name: $(grep -F -m1 -- "$want" "$work/out" | sed 's/^ *//')"
  else echo "FAIL: $name: failed without '$want':"; cat "$work/out"; fails=1; fi
done
exit "$fails"
