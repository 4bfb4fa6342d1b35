#!/usr/bin/env bash
# Issue 16's targets table on the cobot scene (docs/experiments/targets.md): per patch, the light-press and
# slow-press targets (`ruffini coverage-targets`, one command per patch) and the hard-press rows
# (build/release/bin/hard_press_grid, forces 5..200 N). Run from the repository root after
# `cmake --workflow --preset release` (hard_press_grid is a test executable of tests/decode).
# Usage: docs/experiments/targets.sh [BUILD_BIN_DIR] [OUT_DIR]
#   (about 15 min on 2 busy cores; the presses are deterministic, the thread count does not change them)
set -euo pipefail
bin=${1:-build/release/bin}
out=${2:-docs/experiments/targets}
mkdir -p "$out"
scene=config/scenes/cobot.yaml
# Light presses: 0.75 N (0.5 x the cobot's 1.5 N), 20 per point, on sensitivity's 5 mm grid (seeds
# DeriveSeed(1100, point)); slow presses: 0 -> 3 N at 0.15 N/s on a 10 mm grid (seeds DeriveSeed(1101, point)).
for p in upper_arm_a:config/models/forearm.rmodel forearm_a:config/models/cobot-forearm_a.rmodel \
         forearm_b:config/models/cobot-forearm_b.rmodel; do
  "$bin/ruffini" coverage-targets --scene "$scene" --patch "${p%%:*}" --model "${p#*:}" --report "$out" --threads 2 \
    >/dev/null
done
# Hard presses: one per point of a 10 mm grid (+2 mm from each edge) per force, the patch's own model (the scene's);
# HARD_PRESS_VERBOSE lists every point without a stop.
for i in 2 0 1; do  # upper_arm_a, forearm_a, forearm_b
  HARD_PRESS_VERBOSE=1 "$bin/hard_press_grid" "$scene" "$i" 1.5 5 20 50 200 >"$out/hard-press-$i.txt"
done
