#!/bin/bash
# Findings 6-7 (minor):
#  6. press_factor 100 (the top of its allowed range) makes GetStatus/log state "guaranteed threshold 0.02 N" for a
#     1.5 N region (stop force / press factor): a figure that reads as far better than the scene's real claim.
#  7. one band accepting every patch whole: check-scene says "GUARANTEED ... ok: every region's threshold is
#     guaranteed" for a skin that covers 0 of 1240 map points (documented as "nothing is promised").
set -u; B=${B:-build/release/bin}
$B/ruffini check-scene tests/review10/scenes/r10-pf-100.yaml | grep "^region"
$B/ruffini check-scene tests/review10/scenes/r10-all-accepted.yaml | grep "^region\|^ok"
