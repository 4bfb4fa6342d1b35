#!/usr/bin/env bash
# The scene guarantee between the sensitivity map's grid points (docs/coverage.md, "Between the grid points"):
# per patch, `ruffini coverage-targets --target firm` presses the scene's press_factor x its region threshold at
# the centre of every cell of the map's 5 mm grid (20 presses each, the map's press shape, seeds
# DeriveSeed(1102, point): held out) and counts the covered cell centres not reliably stopped. The lab scene
# (cobot.yaml, 2.25 N) and the field scene (cobot-field.yaml, each cast its own model, 4 N).
# Run from the repository root after `cmake --workflow --preset release`.
# Usage: docs/experiments/firm.sh [BUILD_BIN_DIR] [OUT_DIR]   (about 3 min a patch on 2 idle cores)
set -euo pipefail
bin=${1:-build/release/bin}
out=${2:-docs/experiments/firm}
mkdir -p "$out/lab" "$out/field"
for p in upper_arm_a:config/models/forearm.rmodel forearm_a:config/models/cobot-forearm_a.rmodel \
         forearm_b:config/models/cobot-forearm_b.rmodel; do
  "$bin/ruffini" coverage-targets --scene config/scenes/cobot.yaml --patch "${p%%:*}" --model "${p#*:}" \
    --target firm --report "$out/lab" --threads 2 >/dev/null
done
for p in forearm_a forearm_b upper_arm_a upper_arm_b; do
  "$bin/ruffini" coverage-targets --scene config/scenes/cobot-field.yaml --patch "$p" \
    --model "config/models/cobot-field-$p.rmodel" --target firm --report "$out/field" --threads 2 >/dev/null
done
grep -H "covered cell centres (outside" "$out"/lab/*.md "$out"/field/*.md
