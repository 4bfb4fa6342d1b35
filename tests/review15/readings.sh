#!/bin/bash
# Reproduce pair.md section 4's first table: the decoder's reading of each press alone, seeds 1-5.
cd "$(dirname "$0")/../.." || exit 2
B=build/release/bin
for p in "119.5 23.5 5" "119.5 23.5 3" "117.5 47 0.75" "116 48.5 0.5" "119.5 122 5" "119 101 0.75" "118.5 47.6 0.76"; do
  for s in 1 2 3 4 5; do
    echo "seed $s: $(nice -n 10 $B/pair_sweep config/scenes/cobot.yaml upper_arm_a $p 0.1 1.5 $s | head -1)"
  done
done
