#!/usr/bin/env bash
# The field experiments of docs/experiments/field.md: the data, the shipped models' calibration, the
# alternatives measured on validation data (seed 2, field seed 10), and the test runs scored once (seed 3,
# casts 1 and 2, field seed 4). Run from the repository root after `cmake --workflow --preset release`.
# Usage: docs/experiments/field.sh [RUFFINI_BINARY] [OUT_DIR]      (about 40 min on 2 cores, 21 of them training)
set -euo pipefail
B=${1:-build/release/bin/ruffini}
out=${2:-field-experiments}
mkdir -p "$out"
field=config/scenes/forearm-field.yaml
nodrift=config/scenes/forearm-field-nodrift.yaml

# Data: seed 1 trains, 2 and field 10 calibrate (validation), 3 and field 4 test.
for s in 1 2 3; do [[ -f paper_seed$s.h5 ]] || $B simulate --protocol paper --seed $s --out paper_seed$s.h5; done
[[ -f field_s10.h5 ]] || $B simulate --scene $field --protocol field --seed 10 --out field_s10.h5
[[ -f field_s4.h5 ]] || $B simulate --scene $field --protocol field --seed 4 --out field_s4.h5
[[ -f field_nodrift_s4.h5 ]] || $B simulate --scene $nodrift --protocol field --seed 4 --out field_nodrift_s4.h5
$B simulate --protocol paper --skin-sample 1 --seed 6 --indentations 100 --out cast1_cal.h5
$B simulate --protocol paper --skin-sample 1 --seed 7 --indentations 1000 --out cast1_test.h5
$B simulate --protocol paper --skin-sample 2 --seed 9 --indentations 100 --out cast2_cal.h5
$B simulate --protocol paper --skin-sample 2 --seed 8 --indentations 1000 --out cast2_test.h5

# The networks (common mode removed) and the shipped calibrations (config/models/README.md).
[[ -f cm_w16.rmodel ]] || $B train --data paper_seed1.h5 --out cm_w16.rmodel --window 16 --optimizer adam --force-loss l1 \
  --label-sigma-mm 3 --lr-schedule cosine --epochs 20 --frames-per-epoch 150000 --threads 2
$B calibrate --model cm_w16.rmodel --data paper_seed2.h5 --indentations 0 --no-gains --field-data field_s10.h5 --no-creep \
  --out "$out/forearm.rmodel"
$B calibrate --model "$out/forearm.rmodel" --data field_s10.h5 --indentations 0 --no-gains --field-data field_s10.h5 \
  --out "$out/forearm-field.rmodel"

# Alternatives, on validation data only.
run() { $B evaluate --no-inversion "$@" 2>/dev/null | grep honest; }
echo "== field seed 10 (validation)"
echo "common-mode model, no calibration:"; run --model cm_w16.rmodel --data field_s10.h5 --report "$out/v_uncal"
$B calibrate --model cm_w16.rmodel --data paper_seed2.h5 --indentations 0 --no-gains --field-data field_s10.h5 --no-creep \
  --out "$out/thermal_only.rmodel" > /dev/null
echo "+ thermal ratios:"; run --model "$out/thermal_only.rmodel" --data field_s10.h5 --report "$out/v_thermal"
echo "+ creep compensation (shipped field model):"; run --model "$out/forearm-field.rmodel" --data field_s10.h5 --report "$out/v_field"
echo "+ quiet release off:"; run --model "$out/forearm-field.rmodel" --data field_s10.h5 --quiet-release-pm 0 --report "$out/v_field_q0"
for c in 0.03 0.05 0.1; do
  echo "+ contact confirmation $c s:"; run --model "$out/forearm-field.rmodel" --data field_s10.h5 --contact-confirm-s $c --report "$out/v_conf$c"
done
for qd in "1.0 4" "1.0 8" "1.5 4"; do
  set -- $qd
  echo "quiet release $1 pm after a $2x drop (field):"; run --model "$out/forearm-field.rmodel" --data field_s10.h5 --quiet-release-pm $1 --quiet-release-drop $2 --report "$out/v_qd$1_$2_f"
  echo "quiet release $1 pm after a $2x drop (paper seed 2):"; run --model "$out/forearm.rmodel" --data paper_seed2.h5 --quiet-release-pm $1 --quiet-release-drop $2 --report "$out/v_qd$1_$2_p"
done
for q in 1.0 1.5 2.0; do
  echo "+ quiet release $q pm (field):"; run --model "$out/forearm-field.rmodel" --data field_s10.h5 --quiet-release-pm $q --quiet-release-drop 0 --report "$out/v_q${q}_f"
  echo "+ quiet release $q pm (paper seed 2):"; run --model "$out/forearm.rmodel" --data paper_seed2.h5 --quiet-release-pm $q --quiet-release-drop 0 --report "$out/v_q${q}_p"
done
echo "== paper seed 2 (validation): creep compensation where the cover is elastic"
echo "lab model:"; run --model "$out/forearm.rmodel" --data paper_seed2.h5 --report "$out/v_lab_paper"
echo "field model:"; run --model "$out/forearm-field.rmodel" --data paper_seed2.h5 --report "$out/v_field_paper"
echo "== drift augmentation in training (8 epochs of 100 000, no CV: a quick look)"
for s in 0 1 2; do
  $B train --data paper_seed1.h5 --out "$out/aug$s.rmodel" --window 16 --optimizer adam --force-loss l1 --label-sigma-mm 3 \
    --lr-schedule cosine --epochs 8 --frames-per-epoch 100000 --folds 0 --threads 2 --drift-augment-pm $s > /dev/null 2>&1
  echo "sigma $s pm, paper seed 2:"; run --model "$out/aug$s.rmodel" --data paper_seed2.h5 --report "$out/v_aug$s"
  echo "sigma $s pm, field seed 10:"; run --model "$out/aug$s.rmodel" --data field_s10.h5 --report "$out/v_aug${s}_field"
done

# Test runs, scored once (the reports in docs/).
$B evaluate --model "$out/forearm.rmodel" --data paper_seed3.h5 --report "$out/decoder-report" \
  --also cast1=cast1_test.h5 --also cast2=cast2_test.h5
$B evaluate --model "$out/forearm-field.rmodel" --data field_s4.h5 --report "$out/field-report" --also drift-free=field_nodrift_s4.h5
for c in 1 2; do
  $B calibrate --model "$out/forearm.rmodel" --data cast${c}_cal.h5 --indentations 100 --out "$out/cast$c.rmodel" > /dev/null
  echo "cast $c after calibrate:"; run --model "$out/cast$c.rmodel" --data cast${c}_test.h5 --report "$out/cast$c"
done
echo "the shipped model of earlier sessions (raw shifts, shift-driven baseline), field seed 4:"
git show f31ed67:config/models/forearm.rmodel > "$out/old.rmodel"
run --model "$out/old.rmodel" --data field_s4.h5 --no-gate-freeze --report "$out/old_field"
