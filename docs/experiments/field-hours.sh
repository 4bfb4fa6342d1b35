#!/bin/sh
# Issue 17's field-hours figures (docs/experiments/field-hours.md): every run of `ruffini field-hours`, validation
# seeds 801-810 first (every choice), then the held-out seeds 901-910 (scored once). About 45 minutes on 2 cores.
# Usage: docs/experiments/field-hours.sh [BUILD_DIR] [OUT_DIR]
set -eu
B=${1:-build/release}/bin/ruffini
OUT=${2:-field-hours}
M=config/models
S=config/scenes
mkdir -p "$OUT"
# Validation: the shipped field and lab models, the stop rule as the scenes ship it and with sd_k -1, the gate.
$B field-hours --model $M/forearm-field.rmodel --model $M/forearm.rmodel --scene $S/forearm-field.yaml \
  --scene $S/forearm-field-nodrift.yaml --seeds 801-810 --out "$OUT/val"
$B field-hours --model $M/forearm-field.rmodel --model $M/forearm.rmodel --scene $S/forearm-field.yaml \
  --seeds 801-810 --sd-k -1 --out "$OUT/val-sd-1"
for g in 0.05 0.1 0.15 0.2 0.3; do
  $B field-hours --model $M/forearm-field.rmodel --scene $S/forearm-field.yaml --seeds 801-810 --gate-on-n $g \
    --retare --out "$OUT/val-gate$g"
done
# Faint contacts below 1 N refused (the baseline held, its stale clock paused): on in forearm-field.rmodel and
# forearm-embedded.rmodel since stop 27 (Preprocessing.faint_refuse_below_n), so "as shipped" above includes it;
# here every model flag-only, then every model refusing (the lab model's file keeps it off).
$B field-hours --model $M/forearm-field.rmodel --model $M/forearm.rmodel --scene $S/forearm-field.yaml \
  --seeds 801-810 --faint-refuse off --out "$OUT/val-faint-off"
$B field-hours --model $M/forearm-field.rmodel --model $M/forearm.rmodel --scene $S/forearm-field.yaml \
  --seeds 801-810 --faint-refuse on --out "$OUT/val-faint-refuse"
# Refused after a release (stop 30; PipelineConfig::release_*, shipped 0.2 N, tau 10 s): off, and the alternatives.
$B field-hours --model $M/forearm-field.rmodel --scene $S/forearm-field.yaml --seeds 801-810 --release-refuse-n 0 \
  --out "$OUT/val-release-off"
$B field-hours --model $M/forearm-field.rmodel --scene $S/forearm-field.yaml --seeds 801-810 --release-refuse-n 0.1 \
  --out "$OUT/val-release-0.1"
$B field-hours --model $M/forearm-field.rmodel --scene $S/forearm-field.yaml --seeds 801-810 --release-tau-s 5 \
  --out "$OUT/val-release-tau5"
$B field-hours --model $M/forearm-embedded.rmodel --scene $S/forearm-field-embedded.yaml --seeds 801-810 \
  --release-refuse-n 0 --out "$OUT/val-embedded-release-off"
$B field-hours --model $M/forearm-embedded.rmodel --scene $S/forearm-field-gradient.yaml \
  --scene $S/forearm-field-embedded.yaml --seeds 801-810 --faint-refuse off --out "$OUT/val-embedded-faint-off"
$B field-hours --model $M/forearm-embedded.rmodel --scene $S/forearm-field-gradient.yaml \
  --scene $S/forearm-field-embedded.yaml --seeds 801-810 --faint-refuse on --out "$OUT/val-embedded-faint-refuse"
# The demo's four casts, each alone on the bench with its own model, flag-only and refusing (validation only).
for p in forearm_a forearm_b upper_arm_a upper_arm_b; do
  for f in off on; do
    $B field-hours --model $M/cobot-field-$p.rmodel --scene $S/cobot-field.yaml --patch $p --seeds 801-805 \
      --faint-refuse $f --out "$OUT/val-cobot-$p-faint-$f"
  done
done
# The re-tare judge with and without the field separated: the operator under a temperature field (validation),
# and the dry run (a re-tare judged every 10 s, never applied) on five validation hours of the field scene.
$B field-hours --model $M/forearm-embedded.rmodel --scene $S/forearm-field-gradient.yaml --seeds 801-810 --retare \
  --retare-field --out "$OUT/val-gradient-retare-field"
$B field-hours --model $M/forearm-embedded.rmodel --scene $S/forearm-field-gradient.yaml --seeds 801-810 --retare \
  --out "$OUT/val-gradient-retare-plain"
for s in 801 802 803 804 805; do
  $B simulate --scene $S/forearm-field.yaml --protocol field --seed $s --out "$OUT/v$s.h5"
done
R=${1:-build/release}/bin/retare_eval   # built with the tests: cmake --build --preset release --target retare_eval
$R --model $M/forearm-field.rmodel --dry-run "$OUT"/v80[1-5].h5 > "$OUT/dry-run-plain.md"
$R --model $M/forearm-field.rmodel --dry-run --separate-field "$OUT"/v80[1-5].h5 > "$OUT/dry-run-separated.md"
# Held out, once: as shipped, and with the operator's re-tare; the embedded cast (40 pm/C) with and without a field.
$B field-hours --model $M/forearm-field.rmodel --scene $S/forearm-field.yaml --scene $S/forearm-field-nodrift.yaml \
  --seeds 901-910 --release-refuse-n 0 --out "$OUT/test-release-off"
$B field-hours --model $M/forearm-field.rmodel --model $M/forearm.rmodel --scene $S/forearm-field.yaml \
  --scene $S/forearm-field-nodrift.yaml --seeds 901-910 --out "$OUT/test"
$B field-hours --model $M/forearm-field.rmodel --model $M/forearm.rmodel --scene $S/forearm-field.yaml \
  --scene $S/forearm-field-nodrift.yaml --seeds 901-910 --retare --out "$OUT/test-retare"
$B field-hours --model $M/forearm-embedded.rmodel --scene $S/forearm-field-gradient.yaml \
  --scene $S/forearm-field-embedded.yaml --seeds 901-910 --out "$OUT/test-embedded"
$B field-hours --model $M/forearm-embedded.rmodel --scene $S/forearm-field-gradient.yaml \
  --scene $S/forearm-field-embedded.yaml --seeds 901-910 --retare --out "$OUT/test-embedded-retare"
# The same two with the experimental field-separating judge (off in the service: review 6).
$B field-hours --model $M/forearm-field.rmodel --model $M/forearm.rmodel --scene $S/forearm-field.yaml \
  --scene $S/forearm-field-nodrift.yaml --seeds 901-910 --retare --retare-field --out "$OUT/test-retare-field"
$B field-hours --model $M/forearm-embedded.rmodel --scene $S/forearm-field-gradient.yaml \
  --scene $S/forearm-field-embedded.yaml --seeds 901-910 --retare --retare-field --out "$OUT/test-embedded-retare-field"
