#!/usr/bin/env bash
# Hard presses with a light second touch (review 10 finding 2; docs/experiments/pair.md): per patch,
# `ruffini coverage-targets --target pair` presses 5, 20, 50 and 200 N at every point of the sensitivity map's
# 5 mm grid and at every cell centre (3 presses per force), each while a light touch of 0.5-1.2 N is held at a
# random point of the same patch at least 30 mm away (seeds DeriveSeed(1103, point) and DeriveSeed(1104, point):
# held out), and counts the hard presses on the covered surface that do not stop. The lab scene (cobot.yaml:
# upper_arm_a's cobot-upper_arm.rmodel and forearm_a's file, both with the two-touch check since stop 33) and the
# field scene (cobot-field.yaml, each cast its own model; its upper arms with the check since stop 35).
# Run from the repository root after `cmake --workflow --preset release`.
# Usage: docs/experiments/pair.sh [BUILD_BIN_DIR] [OUT_DIR]   (about 9 min a patch on 2 idle cores)
set -euo pipefail
bin=${1:-build/release/bin}
out=${2:-docs/experiments/pair}
mkdir -p "$out/lab" "$out/field"
for p in upper_arm_a forearm_a; do
  "$bin/ruffini" coverage-targets --scene config/scenes/cobot.yaml --patch "$p" --target pair --report "$out/lab" \
    --threads 2 >/dev/null
done
for p in upper_arm_a forearm_a; do
  "$bin/ruffini" coverage-targets --scene config/scenes/cobot-field.yaml --patch "$p" --target pair \
    --report "$out/field" --threads 2 >/dev/null
done
grep -H "^| 5 \|^| 20 \|^| 50 \|^| 200 " "$out"/lab/*.md "$out"/field/*.md
