#!/bin/bash
# Review 14: review 13's end-to-end pair run (tests/review10/e2e_restart.sh: ruffini-sim, one ruffini-decoder per
# patch with its rest file, ruffini-aggregator, ruffini-controller on loopback; operator resets by `ruffini reset`)
# on cobot.yaml's upper_arm_a, which since stop 33 names cobot-upper_arm.rmodel. Cases: tests/review14/gen_focus.py.
# SCENE=... to run another scene (e.g. tests/review14/out/cobot-forearm.yaml, forearm.rmodel on the upper arms).
# About 100 s per repeat set. Run from the repository root; exit 1 while a >= 5 N press from CLEAR is missed.
set -u; B=${B:-build/release/bin}; export B
SCENE=${SCENE:-config/scenes/cobot.yaml}; D=${D:-tests/review14/out/e2e-$(basename $SCENE .yaml)}; REPS=${REPS:-2}
mkdir -p tests/review14/out; SC=tests/review14/out/focus-$(basename $SCENE .yaml).yaml
R=$(python3 tests/review14/gen_focus.py $SC $REPS)
RESETS="${R% *}" REST=1 OPERATOR=review14 nice -n 5 timeout 400 tests/review10/e2e_restart.sh $SCENE $SC $(( ${R##* } + 3 )) $D >/dev/null 2>&1
out=$(python3 tests/review13/match.py $D $SC 5); echo "$out" | tee $D/match.txt
miss=$(echo "$out" | grep -c "MISS ")
[ "$miss" -gt 0 ] && { echo "REPRODUCED: $miss hard presses (>= 5 N) on the covered surface of upper_arm_a without STOP/FAULT"; exit 1; }
echo "not reproduced"; exit 0
