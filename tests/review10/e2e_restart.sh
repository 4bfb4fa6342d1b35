#!/bin/bash
# As e2e.sh, plus: RESTART="T_KILL T_START PATCH..." kills those patches' decoders (SIGTERM, by pid) at scenario time
# T_KILL and starts them again at T_START; RESETS="t..." an operator's reset at those scenario times.
# Usage (from the repository root): RESTART=... RESETS=... tests/review10/e2e_restart.sh SCENE SCENARIO SECONDS OUTDIR
B=${B:-build/release/bin}; S=$1; SC=$2; T=$3; D=$4
rm -rf $D; mkdir -p $D/agg $D/sim
pids=()
cleanup() { for f in $D/*.pid; do [ -f $f ] && pids+=($(cat $f)); done
            for p in "${pids[@]}"; do kill -TERM $p 2>/dev/null; done; sleep 1; for p in "${pids[@]}"; do kill -KILL $p 2>/dev/null; done; }
trap cleanup EXIT
waitport() { for i in $(seq 1 150); do grep -q "^$2 " $1 2>/dev/null && { awk -v k=$2 '$1==k{print $2}' $1; return; }; sleep 0.1; done; echo 0; }
at() { python3 -c "import time; print(max(0, ($1 + $2*1e9 - time.time_ns())/1e9))"; }
decoder() {  # patch tag
  $B/ruffini-decoder --insecure --scene $S --patch $1 --interrogator 127.0.0.1:$SP --aggregator 127.0.0.1:$AP ${REST:+--rest-file $D/rest-$1.txt} \
     --metrics 127.0.0.1:0 --rate-hz 1000 --silence-ms 100 --freshness-budget-ms 200 > $D/$2-$1.out 2> $D/$2-$1.err &
  echo $! > $D/$2-$1.pid
}
$B/ruffini-aggregator --insecure --scene $S --listen 127.0.0.1:0 --metrics 127.0.0.1:0 --patch-silence-ms 200 \
   --joint-max-age-ms 500 --ports-file $D/agg/ports > $D/agg/out 2> $D/agg/err & pids+=($!)
AP=$(waitport $D/agg/ports grpc); MP=$(waitport $D/agg/ports metrics); echo "agg grpc $AP metrics $MP" > $D/ports
[ "$AP" = 0 ] && { echo "aggregator did not start:"; tail -5 $D/agg/err; exit 1; }
$B/ruffini-controller --insecure --aggregator 127.0.0.1:$AP --robot cobot --amplitude-rad 0 --heartbeat-timeout-ms 1000 \
   --freshness-budget-ms 1000 > $D/ctl.out 2> $D/ctl.err & pids+=($!)
$B/ruffini-sim --scene $S --scenario $SC --rate-hz 1000 --command-port 0 --stream-port 0 --ports-file $D/sim/ports \
   > $D/sim/out 2> $D/sim/err & pids+=($!)
SP=$(waitport $D/sim/ports stream)
PATCHES=$(awk '/^patches:/{f=1;next} f&&/^  - name:/{print $3} /^[a-z]/&&!/^patches/{f=0}' $S)
for p in $PATCHES; do decoder $p dec; done
sleep 4
$B/ruffini reset --aggregator 127.0.0.1:$AP --insecure --wait-s 2 --operator ${OPERATOR:-review10} > $D/reset1 2>&1
t0=$(grep -o "sample 0 is at Unix time [0-9]*" $D/sim/err | awk '{print $NF}')
if [ -n "$RESTART" ]; then
  set -- $RESTART; tk=$1; ts=$2; shift 2; rp="$*"
  ( sleep $(at $t0 $tk); for p in $rp; do kill -TERM $(cat $D/dec-$p.pid); echo "killed $p at $(date +%s.%N)" >> $D/restarts; done
    sleep $(at $t0 $ts); for p in $rp; do decoder $p dec2; echo "started $p at $(date +%s.%N)" >> $D/restarts; done ) &
fi
if [ -n "$RESETS" ]; then
  ( for r in $RESETS; do sleep $(at $t0 $r)
      echo "== reset at t $r (wall $(python3 -c "import time; print(round(time.time_ns()/1e9 - $t0/1e9, 2))"))" >> $D/resets
      $B/ruffini reset --aggregator 127.0.0.1:$AP --insecure --operator ${OPERATOR:-review10} >> $D/resets 2>&1
    done ) & pids+=($!)
fi
sleep $T
curl -s 127.0.0.1:$MP/metrics > $D/metrics
