#!/bin/bash
# Finding 1 (blocker): a decoder restarted while a press is held captures its baseline under the press; the
# patch is then healthy and out of contact, the operator's reset is accepted and the aggregator is CLEAR while
# 20 N (upper_arm_a) and 5 N (forearm_a) are still held on the covered interior (Y 60, R 70) for ~14 s.
# On release the forearm decoder reads a phantom ~6.5 N contact that keeps the STOP (reset refused).
# Run from the repository root; about 60 s. Exit 1 when the finding reproduces.
# Since stop 30 the decoders run as deployed, with --rest-file (REST=1, the default here); REST= (empty) runs them
# without, as the review did, and reproduces the finding.
set -u; D=${D:-/tmp/r10/f1}; export REST=${REST-1}
RESTART="10 12 upper_arm_a forearm_a" RESETS="17 20 23 26 29 36 39" \
  timeout 200 tests/review10/e2e_restart.sh config/scenes/cobot.yaml tests/review10/held-restart.yaml 38 $D >/dev/null 2>&1
cat $D/restarts $D/resets
# the presses are held from t 8.3 to 33.3 (scenario time); a reset accepted before 33 is a CLEAR under the press
bad=$(awk '/^== reset at t/{t=$5} /reset accepted/{ if (t < 33) print t }' $D/resets)
if [ -n "$bad" ]; then echo "REPRODUCED: reset accepted (CLEAR) at scenario t $bad s while 20 N and 5 N were held"; exit 1; fi
echo "not reproduced"; exit 0
