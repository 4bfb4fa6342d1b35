#!/bin/bash
# Bounded end-to-end run on loopback (review 10): aggregator, controller, ruffini-sim with a scenario, one decoder
# per patch; kills what it started, by pid. Usage (from the repository root):
#   tests/review10/e2e.sh SCENE SCENARIO SECONDS OUTDIR
# RESETS="t..." as in e2e_restart.sh. It is e2e_restart.sh with no restart (one harness, not two copies).
RESTART= exec "$(dirname "$0")/e2e_restart.sh" "$@"
