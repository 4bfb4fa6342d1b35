#!/usr/bin/env bash
# Builds the images when missing and starts the demo topology (compose.yaml) with podman-compose; waits until
# every decoder reports ready (ruffini-ready: connected and healthy) and the aggregator serves metrics.
# Usage: deploy/container/up.sh [--down]
# podman-compose has no --runtime option, so CONTAINERS_CONF (containers.conf here) selects runc and the
# open-files limit for every podman call it makes.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
export CONTAINERS_CONF=$here/containers.conf
compose=(podman-compose -f "$here/compose.yaml" -p ruffini)
if [[ "${1:-}" == "--down" ]]; then "${compose[@]}" down; exit 0; fi

if ! podman image exists localhost/ruffini/ruffini:dev || ! podman image exists localhost/ruffini/prometheus:dev; then
  "$here/build.sh" --prometheus
fi
"${compose[@]}" up -d
for port in 9464 9466 9467 9468; do
  for _ in $(seq 60); do
    "$here/ruffini-ready" "$port" >/dev/null && break
    sleep 0.5
  done
  "$here/ruffini-ready" --verbose "$port" || { echo "up: the decoder on metrics port $port is not ready"; exit 1; }
done
echo "up: 4 decoders ready; aggregator state:"
curl -s 127.0.0.1:9465/metrics | grep '^ruffini_aggregator_safety_state' || true
