#!/bin/bash
# Finding 4 (minor): the new unit test TwoTouches.ALightTouchDoesNotHideFiftyOrTwoHundredNewtonsAtTheCoveredCorners
# holds its 1 N light touch at three places; at one of them (Y 130 R 70) the 1 N touch ALONE stops (read
# 1.6-2.0 N), so 16 of its 48 cases pass whatever the hard press does. The DISABLED test uses the same place: it
# reproduces a miss only because both touches come on together (the rig ramps them together); held first, that
# 1 N touch stops the arm by itself. Lighter touches there (0.5-0.9 N) hide 5 N at the corner, alone not stopping
# for some seeds. Uses tests/review13/out/probe (build_probe.sh: the unit tests' own rig, tests/decode/hard_press.h,
# seed 1 as the tests). Run from the repository root; ~10 s. Exit 1 while a light placement of the test stops alone.
set -u; tests/review13/build_probe.sh || exit 2
out=$(for p in upper_arm_a forearm_a; do for l in "90 70" "130 70" "60 100"; do echo "$p 1 $l 1.0"; done
      echo "$p 1 119.5 23.5 20"; echo "$p 1 119.5 23.5 20 130 70 1.0"
      for s in 1 2 3; do echo "$p $s 130 70 0.6"; echo "$p $s 119.5 23.5 5"; echo "$p $s 119.5 23.5 5 130 70 0.6"; done; done \
      | tests/review13/out/probe config/scenes/cobot.yaml 2>/dev/null)
echo "$out"
n=$(echo "$out" | grep -E "^[a-z_]+ 1 (90 70|130 70|60 100) 1.0 : stops yes" | wc -l)
[ "$n" -gt 0 ] && { echo "REPRODUCED: $n of the unit test's 6 light placements (2 patches x 3) stop alone"; exit 1; }
echo "not reproduced"; exit 0
