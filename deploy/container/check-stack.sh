#!/usr/bin/env bash
# With the compose demo up (deploy/container/up.sh), checks what an integrator would: the controller receives
# SafetyState heartbeats (it clears after an operator's reset, which takes three CLEAR states in a row on its
# live stream), and a scripted touch (the cobot-demo scenario's hard touches, every 40 s) produces a STOP
# that the controller acts on. Uses the host's `ruffini` (the operator's reset) and the aggregator's metrics
# on 127.0.0.1:9465. Exit 0 when every check passed.
# Usage: deploy/container/check-stack.sh [path/to/ruffini]   (default: build/release/bin/ruffini)
set -uo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
ruffini=${1:-$repo/build/release/bin/ruffini}
export CONTAINERS_CONF=$repo/deploy/container/containers.conf
metric() { curl -s 127.0.0.1:9465/metrics | awk -v m="$1" '$1 == m {print $2}'; }
fail() { echo "check-stack: FAIL: $*"; exit 1; }
[ -x "$ruffini" ] || fail "$ruffini not found (build it, or give its path)"

# 1. Every patch link healthy (LinkState 4), within 60 s.
for _ in $(seq 120); do
  healthy=$(curl -s 127.0.0.1:9465/metrics | awk '/^ruffini_aggregator_patch_link_state\{/ && $2 == 4' | wc -l)
  [ "$healthy" -eq 4 ] && break
  sleep 0.5
done
[ "$healthy" -eq 4 ] || fail "only $healthy of 4 patch links healthy"
echo "check-stack: 4 patch links healthy"
[ "$(metric ruffini_aggregator_safety_subscribers)" -ge 1 ] 2>/dev/null || fail "no WatchSafety subscriber (the controller)"

# 2. The operator clears the start-up FAULT; the controller, receiving heartbeats, clears too.
"$ruffini" reset --aggregator 127.0.0.1:50051 --insecure --wait-s 30 --operator check-stack || fail "reset refused"
for _ in $(seq 40); do
  podman logs ruffini_controller_1 2>/dev/null | grep -q " CLEAR " && break
  sleep 0.25
done
podman logs ruffini_controller_1 2>/dev/null | grep -q " CLEAR " || fail "the controller never cleared (no heartbeats?)"
echo "check-stack: the controller receives SafetyState heartbeats (it cleared after the reset)"

# 3. A scripted touch: STOP within one scenario loop (40 s), and the controller halts on it.
stops=$(metric ruffini_aggregator_stops_total); stops=${stops:-0}
for _ in $(seq 100); do
  now=$(metric ruffini_aggregator_stops_total)
  awk -v a="${now:-0}" -v b="$stops" 'BEGIN {exit !(a > b)}' && break
  sleep 0.5
done
awk -v a="${now:-0}" -v b="$stops" 'BEGIN {exit !(a > b)}' || fail "no STOP within 50 s"
for _ in $(seq 20); do
  podman logs ruffini_controller_1 2>/dev/null | grep -q "HALT STOP" && break
  sleep 0.25
done
podman logs ruffini_controller_1 2>/dev/null | grep "HALT STOP" | tail -1 || fail "the controller did not halt on the STOP"
echo "check-stack: a scripted touch produced a STOP and the controller halted"
echo "check-stack: all checks passed"
