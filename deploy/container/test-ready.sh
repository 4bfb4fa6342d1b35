#!/usr/bin/env bash
# Test of deploy/container/ruffini-ready, the decoders' readiness and liveness check (Kubernetes exec probes,
# compose healthchecks), against real processes on loopback (ports chosen by the kernel, reported in ports
# files; every process stopped by pid on exit):
#   1. nothing listening: not alive, not ready;
#   2. sim, aggregator and a decoder for forearm_a of config/scenes/cobot.yaml: ready within 20 s;
#   3. the aggregator killed: alive, not ready, and the reason names ruffini_decoder_aggregator_connected;
#   4. the sim killed: the reason names ruffini_decoder_interrogator_connected.
# Usage: deploy/container/test-ready.sh BIN_DIR     Exit 0 pass, 1 fail, 2 usage.
set -uo pipefail
bin=${1:?usage: $0 BIN_DIR}
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
ready=$repo/deploy/container/ruffini-ready
scene=$repo/config/scenes/cobot.yaml
work=$(mktemp -d)
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null; done; wait 2>/dev/null; rm -rf "$work"; }
trap cleanup EXIT
fails=0
check() { if "$@"; then echo "ok: ${desc}"; else echo "FAIL: ${desc}"; fails=$((fails + 1)); fi; }
port_of() {  # port_of FILE NAME: waits up to 10 s for "NAME P" in a ports file
  for _ in $(seq 100); do
    [[ -s $1 ]] && awk -v n="$2" '$1 == n {print $2; f=1} END {exit !f}' "$1" && return 0
    sleep 0.1
  done
  return 1
}

# 1. Nothing there: port 1 on loopback refuses.
desc="nothing listening: not alive"; check bash -c "! '$ready' --alive 1 >/dev/null"
desc="nothing listening: not ready"; check bash -c "! '$ready' 1 >/dev/null"

# 2. The chain.
"$bin/ruffini-aggregator" --scene "$scene" --listen 127.0.0.1:0 --metrics 127.0.0.1:0 --insecure \
  --ports-file "$work/agg.ports" >"$work/agg.log" 2>&1 &
agg=$!; pids+=("$agg")
"$bin/ruffini-sim" --scene "$scene" --scenario "$repo/config/scenarios/cobot-demo.yaml" --rate-hz 1000 \
  --stream-port 0 --command-port 0 --ports-file "$work/sim.ports" >"$work/sim.log" 2>&1 &
sim=$!; pids+=("$sim")
agg_port=$(port_of "$work/agg.ports" grpc) || { echo "FAIL: the aggregator reported no port"; cat "$work/agg.log"; exit 1; }
sim_port=$(port_of "$work/sim.ports" stream) || { echo "FAIL: the sim reported no port"; cat "$work/sim.log"; exit 1; }
"$bin/ruffini-decoder" --scene "$scene" --patch forearm_a --interrogator "127.0.0.1:$sim_port" \
  --aggregator "127.0.0.1:$agg_port" --metrics 127.0.0.1:0 --insecure --ports-file "$work/dec.ports" >"$work/dec.log" 2>&1 &
dec=$!; pids+=("$dec")
m=$(port_of "$work/dec.ports" metrics) || { echo "FAIL: the decoder reported no metrics port"; cat "$work/dec.log"; exit 1; }

became_ready() { for _ in $(seq 200); do "$ready" "$m" >/dev/null && return 0; sleep 0.1; done; "$ready" "$m"; return 1; }
desc="decoder connected to sim and aggregator: ready within 20 s"; check became_ready
desc="decoder up: alive"; check "$ready" --alive "$m"

# 3. The aggregator gone.
kill "$agg"; wait "$agg" 2>/dev/null
not_ready_for() {  # not_ready_for METRIC: within 5 s, not ready and the reason names METRIC
  local out
  for _ in $(seq 50); do
    out=$("$ready" "$m") || { grep -q "$1" <<<"$out" && { echo "  ($out)" | head -n 3; return 0; }; }
    sleep 0.1
  done
  echo "  last: ${out:-ready}"; return 1
}
desc="aggregator killed: not ready, naming aggregator_connected"; check not_ready_for ruffini_decoder_aggregator_connected
desc="aggregator killed: still alive"; check "$ready" --alive "$m"

# 4. The interrogator gone.
kill "$sim"; wait "$sim" 2>/dev/null
desc="sim killed: not ready, naming interrogator_connected"; check not_ready_for ruffini_decoder_interrogator_connected

if ((fails)); then echo "test-ready: $fails check(s) failed; decoder log:"; tail -n 20 "$work/dec.log"; exit 1; fi
echo "test-ready: all checks passed"
