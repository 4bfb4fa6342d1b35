#!/usr/bin/env bash
# `ruffini reset` against a real ruffini-aggregator on 127.0.0.1 (port 0): in its start-up FAULT (no decoder
# connected) the reset is refused with the cause (exit 4), a wrong epoch is refused, and an unreachable
# aggregator is a clear error (exit 1). The aggregator is stopped by pid.
set -u
bin=$1; scene=$2; work=$3
rm -rf "$work"; mkdir -p "$work"
"$bin/ruffini-aggregator" --scene "$scene" --listen 127.0.0.1:0 --metrics 127.0.0.1:0 --insecure \
  --ports-file "$work/ports" >"$work/agg.log" 2>&1 &
agg=$!
trap 'kill $agg 2>/dev/null; wait $agg 2>/dev/null' EXIT
for _ in $(seq 200); do grep -q '^grpc ' "$work/ports" 2>/dev/null && break; sleep 0.05; done
port=$(awk '/^grpc /{print $2}' "$work/ports")
[ -n "$port" ] || { echo "FAIL: no aggregator port"; cat "$work/agg.log"; exit 1; }
fail=0
out=$("$bin/ruffini" reset --aggregator "127.0.0.1:$port" --insecure); rc=$?
[ $rc -eq 4 ] && grep -q "RESET_REFUSAL_CAUSE_PRESENT.*patch_missing" <<<"$out" || { echo "FAIL: startup reset: rc $rc: $out"; fail=1; }
out=$("$bin/ruffini" reset --aggregator "127.0.0.1:$port" --insecure --epoch 9); rc=$?
[ $rc -eq 4 ] && grep -q "RESET_REFUSAL_WRONG_EPOCH" <<<"$out" || { echo "FAIL: wrong epoch: rc $rc: $out"; fail=1; }
err=$("$bin/ruffini" reset --aggregator "127.0.0.1:1" --insecure 2>&1); rc=$?
[ $rc -eq 1 ] && grep -q "GetStatus failed" <<<"$err" || { echo "FAIL: no aggregator: rc $rc: $err"; fail=1; }
[ $fail -eq 0 ] && echo "reset checks passed"
exit $fail
