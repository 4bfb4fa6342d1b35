#!/usr/bin/env bash
# Builds the images when missing and starts the demo topology (compose.yaml) with podman-compose; waits until
# every decoder reports ready (ruffini-ready inside each decoder container: connected and healthy), then prints
# the aggregator's safety state from its metrics (127.0.0.1:9465).
# Usage: deploy/container/up.sh [--down]
# podman-compose has no --runtime option, so CONTAINERS_CONF (containers.conf here) selects runc and the
# open-files limit for every podman call it makes.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
export CONTAINERS_CONF=$here/containers.conf
compose=(podman-compose -f "$here/compose.yaml" -p ruffini)
if [[ "${1:-}" == "--down" ]]; then
  "${compose[@]}" down
  podman network rm ruffini_default >/dev/null 2>&1 || true   # podman-compose 1.0.3 leaves its network behind
  exit 0
fi

if ! podman image exists localhost/ruffini/ruffini:dev || ! podman image exists localhost/ruffini/prometheus:dev; then
  "$here/build.sh" --prometheus
fi
"${compose[@]}" up -d
for d in forearm-a forearm-b upper-arm-a upper-arm-b; do
  name=ruffini_decoder-${d}_1
  for _ in $(seq 60); do
    podman exec "$name" /usr/local/bin/ruffini-ready 9464 >/dev/null 2>&1 && break
    sleep 0.5
  done
  podman exec "$name" /usr/local/bin/ruffini-ready --verbose 9464 || { echo "up: $name is not ready"; exit 1; }
done
echo "up: 4 decoders ready (connected and healthy); the aggregator's safety state:"
exec 3<>/dev/tcp/127.0.0.1/9465 && printf 'GET /metrics HTTP/1.0\r\n\r\n' >&3 && grep '^ruffini_aggregator_safety_state' <&3 || true
