#!/bin/bash
# Finding 5 (minor): `--pair-forces-n nan` is accepted (CLI11's Range lets NaN through), the run exits 0 and
# writes a report row "| - | 0 of 9 ..." with a NaN press. Every other bad pair option tried is refused.
# Run from the repository root; ~10 s. Exit 1 while NaN is accepted.
set -u; B=${B:-build/release/bin}; O=tests/review13/out; mkdir -p $O
C="coverage-targets --scene config/scenes/cobot.yaml --patch upper_arm_a --target pair --pair-at grid --edge-mm 30 --step-mm 30 --threads 1"
bad=0
for opts in "--pair-forces-n nan" "--pair-forces-n 5 nan" "--pair-forces-n -5" "--pair-forces-n 0" "--pair-forces-n inf" \
            "--pair-light-n 2 1" "--pair-light-n -1 1" "--pair-light-n 1 nan" "--pair-light-n nan 1" "--pair-light-n 1" \
            "--pair-presses 0" "--pair-presses -1" "--pair-forces-n"; do
  timeout 120 $B/ruffini $C $opts > $O/f5.out 2> $O/f5.err; rc=$?
  echo "$opts: exit $rc $(grep -m1 '^| \(-\|nan\) ' $O/f5.out)"
  case "$opts" in *nan*) [ $rc -eq 0 ] && grep -q '^| - ' $O/f5.out && bad=$((bad + 1));; esac
done
[ $bad -gt 0 ] && { echo "REPRODUCED: $bad runs with a NaN hard force accepted (exit 0)"; exit 1; }
echo "not reproduced"; exit 0
