#!/bin/bash
# Review 16, finding 5: the real processes (ruffini-sim, one ruffini-decoder per patch with its rest file,
# ruffini-aggregator, ruffini-controller on loopback; an operator's reset before each case: tests/review10/
# e2e_restart.sh, judged by tests/review13/match.py) on cobot-field.yaml with the upper arms' old and new files.
# Cases (tests/review16/gen_field.py): 5 N at the wrist-end corners with a 0.4 N touch held where pair_sweep (seed 1)
# says old and/or new miss, 2.25-4 N controls, the light touch alone. About 4 x 60 s; run alone on the host.
# Exit 1 while the new files let any judged hard press (>= 2.25 N, from CLEAR) pass without STOP or FAULT.
set -u; . "$(dirname "$0")/lib.sh"; make_configs; export B
H=$(cd "$(dirname "$0")" && pwd); miss_new=0
for p in upper_arm_a upper_arm_b; do for v in old new; do
  D=$OUT/f5/$p-$v; rm -rf $D; mkdir -p $D; SC=$D/scenario.yaml
  R=$(PATCH=$p python3 $H/gen_field.py $SC 1)
  RESETS="${R% *}" REST=1 OPERATOR=review16 nice -n 5 timeout 400 $ROOT/tests/review10/e2e_restart.sh \
    $OUT/$v/scenes/cobot-field.yaml $SC $(( ${R##* } + 3 )) $D/run > /dev/null 2>&1
  echo "== $p, $v files"; python3 $ROOT/tests/review13/match.py $D/run $SC 2.25 | tee $D/match.txt | grep -v '^ *$'
  m=$(grep -o 'MISSED (no STOP, no FAULT): [0-9]*' $D/match.txt | awk '{print $NF}')
  [ "$v" = new ] && miss_new=$((miss_new + ${m:-99}))
done; done
[ $miss_new -gt 0 ] && { echo "PROBLEM: with the new files $miss_new judged hard presses passed without STOP/FAULT"; exit 1; }
echo ok; exit 0
