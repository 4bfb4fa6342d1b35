#!/bin/bash
# Review 11, finding 1 (blocker): the rest file does not stop a held press from becoming the rest when the press
# moves no grating by more than 6 pm after the common mode. 5 N / 10 N / 5 N / 2.25 N held on the covered surface
# (sites from probe_shift.cpp), each STOPs at onset; the four decoders (with --rest-file, files present) are
# restarted under the presses, accept the capture, and the operator's reset at t 17 s is accepted: CLEAR under
# the presses. Run from the repository root (a checkout with build/release/bin); ~60 s.
# Exit 1 while it reproduces.
set -u; D=${D:-/tmp/r11/f1}; export REST=1
H=$(dirname "$0")
RESTART="10 12 upper_arm_a forearm_a upper_arm_b forearm_b" RESETS="17 20 23 26 29" \
  timeout 200 tests/review10/e2e_restart.sh config/scenes/cobot.yaml $H/weak-restart.yaml 32 $D >/dev/null 2>&1
grep -h "rest file" $D/dec2-*.err | sed 's/^.*\] //'
echo "stops at onset:"; grep "cause=contact" $D/agg/err | sed 's/^.*type=/type=/' | cut -c1-90
cat $D/resets
bad=$(awk '/^== reset at t/{t=$5} /reset accepted/{ if (t < 33) print t }' $D/resets)
if [ -n "$bad" ]; then echo "REPRODUCED: reset accepted (CLEAR) at scenario t $bad s while the presses were held (8.3-33.3 s)"; exit 1; fi
echo "not reproduced"; exit 0
