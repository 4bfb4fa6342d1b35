#!/bin/bash
# Review 14: is cobot-upper_arm.rmodel's sensitivity map bound to its patch? `ruffini check-scene` on the shipped
# cobot.yaml (must pass), on a copy whose forearm_a names cobot-upper_arm.rmodel (swap A) and one whose upper arms
# name cobot-forearm_a.rmodel (swap B): both must be refused. Also flags the refusal's report printing
# "maps of level nan N; guaranteed threshold inf N" for a region left without a usable map (cosmetic).
# About 20 s. Run from the repository root; exit 1 while a swap is accepted, the shipped scene refused, or nan printed.
set -u; B=${B:-build/release/bin}; O=tests/review14/out/binding; mkdir -p $O; bad=0
sed -e "s#\.\./#$PWD/config/#g" config/scenes/cobot.yaml > $O/abs.yaml
sed -e "0,/cobot-forearm_a.rmodel/s//cobot-upper_arm.rmodel/" $O/abs.yaml > $O/swap_A.yaml
sed -e "s#models/cobot-upper_arm.rmodel#models/cobot-forearm_a.rmodel#" $O/abs.yaml > $O/swap_B.yaml
nice -n 10 timeout 120 $B/ruffini check-scene config/scenes/cobot.yaml > $O/shipped.txt 2>&1; rc=$?; echo "shipped: rc $rc"; [ $rc = 0 ] || bad=1
for s in swap_A swap_B; do nice -n 10 timeout 120 $B/ruffini check-scene $O/$s.yaml > $O/$s.txt 2>&1; rc=$?
  echo "$s: rc $rc; $(grep -c 'is not used' $O/$s.txt) 'map not used' lines"; [ $rc = 0 ] && bad=1
  grep -q "level nan N" $O/$s.txt && { echo "  $s prints: $(grep -o 'maps of level nan N; guaranteed threshold inf N[^:]*' $O/$s.txt | head -1)"; bad=1; }
done
[ $bad = 1 ] && { echo "REPRODUCED (see above)"; exit 1; }; echo "not reproduced"; exit 0
