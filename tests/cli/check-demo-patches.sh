#!/bin/sh
# Checks the per-patch table of a `ruffini demo` report on config/scenes/cobot-field.yaml (ctest cli.demo):
# one row per patch of the scene, each its own cast (distinct skin samples), a model calibrated on at most 100
# presses of that cast, and both FAULT times as numbers (with a present cause, without one).
# Usage: check-demo-patches.sh REPORT.md PATCH...
set -u
report=$1
shift
grep -q '| FAULT with a present cause (s) | FAULT without one (s) |$' "$report" || {
  echo "$report: no per-patch table with both FAULT times"; exit 1; }
casts=""
for p in "$@"; do
  rows=$(grep -cE "^\| $p \| " "$report")
  [ "$rows" -eq 1 ] || { echo "$report: $rows rows for patch $p, expected 1"; exit 1; }
  row=$(grep -E "^\| $p \| " "$report")
  echo "$row"
  cast=$(echo "$row" | sed -nE 's/^\| [^|]+ \| skin sample ([0-9]+) \|.*/\1/p')
  [ -n "$cast" ] || { echo "$p: no cast of its own"; exit 1; }
  n=$(echo "$row" | sed -nE 's/.*\| ([0-9]+) presses of `[^`]+`.*/\1/p')
  [ -n "$n" ] && [ "$n" -ge 20 ] && [ "$n" -le 100 ] || { echo "$p: model not calibrated on 20..100 presses of its cast"; exit 1; }
  echo "$row" | grep -qE '\| [1-9][0-9]* presses: [0-9.]+ → [0-9.]+ mN, [0-9.]+ → [0-9.]+ mm \|' || {
    echo "$p: no held-out figures of its calibration"; exit 1; }
  echo "$row" | grep -qE '\| [0-9]+\.[0-9]{2} \| [0-9]+\.[0-9]{2} \|$' || { echo "$p: FAULT times missing"; exit 1; }
  casts="$casts $cast"
done
distinct=$(echo $casts | tr ' ' '\n' | sort -u | wc -l)
[ "$distinct" -eq "$#" ] || { echo "casts:$casts: not one per patch"; exit 1; }
echo "ok: $# patches, casts$casts"
