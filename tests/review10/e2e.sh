#!/bin/bash
# Bounded end-to-end run on loopback (review 10): aggregator, controller, ruffini-sim with a scenario, one decoder
# per patch; kills what it started, by pid. Usage (from the repository root):
#   tests/review10/e2e.sh SCENE SCENARIO SECONDS OUTDIR
# Prints the aggregator's latch lines. B= the binaries (default build/release/bin, from the repository root).
B=${B:-build/release/bin}; S=$1; SC=$2; T=$3; D=$4
rm -rf $D; mkdir -p $D/agg $D/sim
pids=()
cleanup() { for p in "${pids[@]}"; do kill -TERM $p 2>/dev/null; done; sleep 1; for p in "${pids[@]}"; do kill -KILL $p 2>/dev/null; done; }
trap cleanup EXIT
waitport() { for i in $(seq 1 150); do grep -q "^$2 " $1 2>/dev/null && { awk -v k=$2 '$1==k{print $2}' $1; return; }; sleep 0.1; done; echo 0; }
$B/ruffini-aggregator --insecure --scene $S --listen 127.0.0.1:0 --metrics 127.0.0.1:0 --patch-silence-ms 200 \
   --joint-max-age-ms 500 --ports-file $D/agg/ports > $D/agg/out 2> $D/agg/err & pids+=($!)
AP=$(waitport $D/agg/ports grpc); MP=$(waitport $D/agg/ports metrics); echo "agg grpc $AP metrics $MP" > $D/ports
[ "$AP" = 0 ] && { echo "aggregator did not start:"; tail -5 $D/agg/err; exit 1; }
$B/ruffini-controller --insecure --aggregator 127.0.0.1:$AP --robot cobot --amplitude-rad 0 --heartbeat-timeout-ms 1000 \
   --freshness-budget-ms 1000 > $D/ctl.out 2> $D/ctl.err & pids+=($!)
$B/ruffini-sim --scene $S --scenario $SC --rate-hz 1000 --command-port 0 --stream-port 0 --ports-file $D/sim/ports \
   > $D/sim/out 2> $D/sim/err & pids+=($!)
SP=$(waitport $D/sim/ports stream)
for p in $(awk '/^patches:/{f=1;next} f&&/^  - name:/{print $3} /^[a-z]/&&!/^patches/{f=0}' $S); do
  $B/ruffini-decoder --insecure --scene $S --patch $p --interrogator 127.0.0.1:$SP --aggregator 127.0.0.1:$AP \
     --metrics 127.0.0.1:0 --rate-hz 1000 --silence-ms 100 --freshness-budget-ms 200 > $D/dec-$p.out 2> $D/dec-$p.err & pids+=($!)
done
sleep 4
$B/ruffini reset --aggregator 127.0.0.1:$AP --insecure --wait-s 2 --operator review10 > $D/reset1 2>&1
# RESETS="t1 t2 ...": an operator's reset at those scenario times (s after the sim's sample 0), each logged.
if [ -n "$RESETS" ]; then
  t0=$(grep -o "sample 0 is at Unix time [0-9]*" $D/sim/err | awk '{print $NF}')
  ( for r in $RESETS; do
      now=$(date +%s%N); w=$(python3 -c "print(max(0, ($t0 + $r*1e9 - $now)/1e9))"); sleep $w
      echo "== reset at t $r" >> $D/resets; $B/ruffini reset --aggregator 127.0.0.1:$AP --insecure --operator review10 >> $D/resets 2>&1
    done ) & pids+=($!)
fi
sleep $T
curl -s 127.0.0.1:$MP/metrics > $D/metrics
