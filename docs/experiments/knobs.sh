#!/usr/bin/env bash
# The knob experiments of docs/experiments/knobs.md: one knob at a time at the shipped model's budget
# (W = 8, Adam, 20 epochs of 150 000 samples, seed 1), without cross-validation, on the twin's paper dataset.
# Usage: docs/experiments/knobs.sh [RUFFINI_BINARY] [DATASET] [OUT_DIR]
#   DATASET defaults to paper_seed1.h5, made by `ruffini simulate --protocol paper --seed 1 --out paper_seed1.h5`.
set -euo pipefail
bin=${1:-build/release/bin/ruffini}
data=${2:-paper_seed1.h5}
out=${3:-knobs}
mkdir -p "$out"
base=(--epochs 20 --frames-per-epoch 150000 --optimizer adam --folds 0 --threads 2)
runs=(
  "mse_raw:"
  "mse_unit:--location-input unit"
  "l1_raw:--force-loss l1"
  "l1_unit:--force-loss l1 --location-input unit"
  "l1_s4:--force-loss l1 --label-sigma-mm 4"
  "l1_s6:--force-loss l1 --label-sigma-mm 6"
  "cos_s4:--force-loss l1 --label-sigma-mm 4 --lr-schedule cosine"
  "cos_s3:--force-loss l1 --label-sigma-mm 3 --lr-schedule cosine"
  "cos_s3_w4:--force-loss l1 --label-sigma-mm 3 --lr-schedule cosine --window 4"
  "cos_s3_w16:--force-loss l1 --label-sigma-mm 3 --lr-schedule cosine --window 16"
  "cos_s3_w32:--force-loss l1 --label-sigma-mm 3 --lr-schedule cosine --window 32"
)
for spec in "${runs[@]}"; do
  name=${spec%%:*}
  read -r -a args <<< "${spec#*:}"
  [[ " ${args[*]} " == *" --window "* ]] || args+=(--window 8)
  "$bin" train --data "$data" --out "$out/$name.rmodel" "${base[@]}" "${args[@]}"
  "$bin" evaluate --model "$out/$name.rmodel" --data "$data" --report "$out/${name}_report"
done
# long_l1_s4: 5-fold CV, a longer force budget, no decay (26 min):
"$bin" train --data "$data" --out "$out/long_l1_s4.rmodel" --window 8 --optimizer adam --force-loss l1 \
  --label-sigma-mm 4 --epochs 40 --epochs-location 20 --frames-per-epoch 200000 --threads 2
"$bin" evaluate --model "$out/long_l1_s4.rmodel" --data "$data" --report "$out/long_l1_s4_report"
