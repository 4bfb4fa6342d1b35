#!/bin/bash
# Review 14: forces the stop-33 sweeps did not try. With the shipped cobot.yaml (upper_arm_a: cobot-upper_arm.rmodel,
# the two-touch check on), pair_sweep (the light touch on a 20 mm x 20 deg grid, >= 30 mm away, seed 1) finds
#  - 3 N (above the 2.25 N the scene guarantees alone, press factor 1.5) at the covered corner Y 119.5 R 23.5 hidden
#    by a 0.4 N touch at 14 of 42 placements (forearm.rmodel: 14 too; the check changes none);
#  - 10 N hidden at Y 115 R 23.5 by 0.2 N at Y 90 R 70, by 0.7 N at 2 places; at Y 119.5 R 122 by 0.7 N / 1.0 N.
# Every hidden placement is flagged `multiple` on (nearly) every hold frame. About 20 s. Run from the repository
# root; exit 1 while any of these placements hides the press (no stop).
set -u; B=${B:-build/release/bin}; O=tests/review14/out/hidden; mkdir -p $O; total=0
run() { nice -n 10 timeout 120 $B/pair_sweep config/scenes/cobot.yaml upper_arm_a "$@" 1.5 1 > $O/$(echo "$@" | tr ' ' _).txt
        m=$(grep -o "without a stop: [0-9]*" $O/$(echo "$@" | tr ' ' _).txt | awk '{print $NF}'); echo "$1 $2 $3 N + $4 N: $m placements hide it ($(head -1 $O/$(echo "$@" | tr ' ' _).txt))"; total=$((total + m)); }
run 119.5 23.5 3 0.4
run 119.5 23.5 3 0.7
run 115 23.5 10 0.2
run 115 23.5 10 0.7
run 119.5 122 10 0.7
run 119.5 122 10 1.0
[ "$total" -gt 0 ] && { echo "REPRODUCED: $total placements of a light touch hide 3 N / 10 N presses on the covered surface"; exit 1; }
echo "not reproduced"; exit 0
