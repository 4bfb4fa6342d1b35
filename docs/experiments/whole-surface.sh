#!/usr/bin/env bash
# The whole-surface experiment of docs/experiments/whole-surface.md (issue 16, section 2): coverage data on the
# cobot scene's upper_arm_a (every edge free), a model trained with the whole-surface grids, calibrated on
# validation data, scored beside the shipped forearm.rmodel on the same test data, and its sensitivity map.
# Run from the repository root after `cmake --workflow --preset release`.
# Usage: docs/experiments/whole-surface.sh [RUFFINI_BINARY] [OUT_DIR]
#   (about 90 min on 2 busy cores: three trainings of 10-15 min, two sensitivity maps of about 9 min)
set -euo pipefail
B=${1:-build/release/bin/ruffini}
out=${2:-whole-surface-experiment}
mkdir -p "$out"
cov=(--scene config/scenes/cobot.yaml --patch upper_arm_a --protocol coverage)
knobs=(--folds 0 --window 16 --optimizer adam --force-loss l1 --label-sigma-mm 3 --lr-schedule cosine --epochs 20
       --frames-per-epoch 150000 --threads 2)

# Data. Seed 1 trains (5400 presses: the paper's density over twice its area), 2 is validation (calibration
# and every choice), 3 is the test, scored once at the end. The paper protocol's seeds 2 and 3 (the paper
# scene) check the paper's figures; field seed 10 gives the thermal ratios as for the shipped model.
$B simulate "${cov[@]}" --seed 1 --indentations 5400 --out "$out/coverage_seed1.h5"
$B simulate "${cov[@]}" --seed 1 --indentations 5400 --force-min-n 1 --out "$out/coverage_f1_seed1.h5"
$B simulate "${cov[@]}" --seed 2 --out "$out/coverage_seed2.h5"
$B simulate "${cov[@]}" --seed 3 --out "$out/coverage_seed3.h5"
$B simulate --protocol paper --seed 2 --out "$out/paper_seed2.h5"
$B simulate --protocol paper --seed 3 --out "$out/paper_seed3.h5"
$B simulate --scene config/scenes/forearm-field.yaml --protocol field --seed 10 --out "$out/field_s10.h5"

# The models: the shipped knobs (config/models/README.md) without cross-validation; the whole-surface grids;
# the paper's grids on the same data (an ablation); peaks from 1 N (the variant chosen on seed 2).
$B train --data "$out/coverage_seed1.h5" --out "$out/whole_w16.rmodel" --area whole "${knobs[@]}"
$B train --data "$out/coverage_seed1.h5" --out "$out/indented_cov_w16.rmodel" --area indented "${knobs[@]}"
$B train --data "$out/coverage_f1_seed1.h5" --out "$out/whole_f1_w16.rmodel" --area whole "${knobs[@]}"
for m in whole indented_cov whole_f1; do
  $B calibrate --model "$out/${m}_w16.rmodel" --data "$out/coverage_seed2.h5" --indentations 0 --no-gains \
    --field-data "$out/field_s10.h5" --no-creep --out "$out/$m.rmodel"
done

# Validation (seed 2): the choice between the candidates.
for m in whole indented_cov whole_f1; do
  for d in coverage paper; do
    $B evaluate --model "$out/$m.rmodel" --data "$out/${d}_seed2.h5" --report "$out/val-$m-$d" | grep -E '^(honest|pressed)'
  done
done

# Test (seed 3), once: the candidate and the shipped model on the same data.
for m in "$out/whole.rmodel" "$out/whole_f1.rmodel" config/models/forearm.rmodel; do
  n=$(basename "$m" .rmodel)
  for d in coverage paper; do
    $B evaluate --model "$m" --data "$out/${d}_seed3.h5" --report "$out/test-$n-$d" | grep -E '^(honest|pressed)'
  done
done

# The sensitivity maps where the shipped one was measured (docs/coverage.md); whole_f1 is the candidate.
for m in whole whole_f1; do
  $B sensitivity --scene config/scenes/cobot.yaml --patch upper_arm_a --model "$out/$m.rmodel" \
    --out "$out/$m-map.rmodel" --report "$out/sens-$m" --threads 2
done
