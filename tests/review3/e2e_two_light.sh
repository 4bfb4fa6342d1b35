#!/bin/bash
# Bounded end-to-end run on loopback: aggregator, controller, sim, 4 decoders; stops what it started by pid.
B=${B:-build/release/bin}; S=${S:-config/scenes/cobot.yaml}; D=${D:-/tmp/r3/e2e}   # run from the repository root
rm -rf $D/agg $D/sim; mkdir -p $D/agg $D/sim
pids=()
cleanup() { for p in "${pids[@]}"; do kill -TERM $p 2>/dev/null; done; sleep 1; for p in "${pids[@]}"; do kill -KILL $p 2>/dev/null; done; }
trap cleanup EXIT
waitport() { for i in $(seq 1 150); do grep -q "^$2 " $1 2>/dev/null && { awk -v k=$2 '$1==k{print $2}' $1; return; }; sleep 0.1; done; echo 0; }
$B/ruffini-aggregator --insecure --scene $S --listen 127.0.0.1:0 --metrics 127.0.0.1:0 --patch-silence-ms 200 --joint-max-age-ms 500 --ports-file $D/agg/ports > $D/agg/out 2> $D/agg/err & pids+=($!)
sleep 0.5; cat $D/agg/ports 2>/dev/null
AP=$(waitport $D/agg/ports grpc); MP=$(waitport $D/agg/ports metrics); echo "agg grpc $AP metrics $MP"
$B/ruffini-controller --insecure --aggregator 127.0.0.1:$AP --robot cobot --amplitude-rad 0 --heartbeat-timeout-ms 1000 --freshness-budget-ms 1000 > $D/ctl.out 2> $D/ctl.err & pids+=($!)
$B/ruffini-sim --scene $S --scenario tests/review3/two-light.yaml --rate-hz 1000 --command-port 0 --stream-port 0 --ports-file $D/sim/ports > $D/sim/out 2> $D/sim/err & pids+=($!)
SP=$(waitport $D/sim/ports stream); echo "sim stream $SP"
for p in forearm_a forearm_b upper_arm_a upper_arm_b; do
  $B/ruffini-decoder --insecure --scene $S --patch $p --interrogator 127.0.0.1:$SP --aggregator 127.0.0.1:$AP --metrics 127.0.0.1:0 --rate-hz 1000 --silence-ms 100 --freshness-budget-ms 200 > $D/dec-$p.out 2> $D/dec-$p.err & pids+=($!)
done
sleep 5
$B/ruffini reset --aggregator 127.0.0.1:$AP --insecure --wait-s 2 --operator review3 2>&1 | tail -2
sleep 16
curl -s 127.0.0.1:$MP/metrics | grep -i "seam\|contacts_total\|transitions" | head -20
