#!/usr/bin/env bash
# `ruffini coverage-targets` (docs/coverage.md, "Targets") on coarse grids of the cobot scene's upper_arm_a:
# - presses of 0 N never stop: every point clean, 0 presses stop, nothing stops in the untouched starts;
# - presses of 5 N in the interior (30 mm from every edge, where the sensitivity map needs at most 2.25 N)
#   always stop: no point clean, every press stops, the causes add up to the presses; every slow press to 3 N
#   there stops during its ramp, and the report's counts add up to the points;
# - the report and its figures are written (each figure's title names the patch);
# - pairs (a hard press with a light touch held elsewhere): 50 and 200 N in the interior stop whenever judged,
#   0.01 N with a light touch of 0 N never does, and the covered counts add up;
# - bad input (a scene without thresholds and no --level-n, a slow press that cannot leave the band, a bad
#   pair option) is refused.
# Usage: coverage_targets_test.sh RUFFINI SCENE WORK
set -u
ruffini=$1; scene=$2; work=$3
rm -rf "$work"; mkdir -p "$work"
fail=0
check() {  # NAME CONDITION-RESULT (0 ok)
  if [ "$2" -ne 0 ]; then echo "FAIL: $1"; fail=1; else echo "ok: $1"; fi
}
# A row "| LABEL | VALUE |" of the report: VALUE.
row() { grep -F "| $1" "$2" | head -1 | awk -F'|' '{print $3}'; }

"$ruffini" coverage-targets --scene "$scene" --patch upper_arm_a --target light --force-n 0 --step-mm 40 --presses 2 \
  --threads 2 >"$work/zero.md" 2>"$work/zero.err" || { echo "FAIL: zero-force run"; cat "$work/zero.err"; exit 1; }
pts=$(grep -o 'At each of [0-9]* grid points' "$work/zero.md" | awk '{print $4}')
clean=$(row "points with no STOP in any press" "$work/zero.md")
stops=$(row "presses that STOP" "$work/zero.md")
start=$(row "points with a STOP in the untouched start" "$work/zero.md")
echo "zero force: $pts points; clean: $clean; stops: $stops; start: $start"
[ -n "$pts" ] && [ "$pts" -gt 0 ]; check "zero force: a grid" $?
[ "$(awk '{print $1, $3}' <<<"$clean")" = "$pts $pts" ]; check "zero force: every point clean" $?
[ "$(awk '{print $1, $3}' <<<"$stops")" = "0 $((pts * 2))" ]; check "zero force: no press stops" $?
[ "$(tr -d ' ' <<<"$start")" = "0" ]; check "zero force: nothing stops in the starts" $?

"$ruffini" coverage-targets --scene "$scene" --patch upper_arm_a --force-n 5 --edge-mm 30 --step-mm 30 \
  --slow-step-mm 30 --presses 2 --threads 2 --report "$work/report" >"$work/hard.md" 2>"$work/hard.err" \
  || { echo "FAIL: interior run"; cat "$work/hard.err"; exit 1; }
pts=$(grep -o 'At each of [0-9]* grid points' "$work/hard.md" | head -1 | awk '{print $4}')
clean=$(row "points with no STOP in any press" "$work/hard.md")
stops=$(row "presses that STOP" "$work/hard.md")
causes=$(row "of them by cause" "$work/hard.md")
echo "5 N interior: $pts points; clean: $clean; stops: $stops; causes: $causes"
[ -n "$pts" ] && [ "$pts" -gt 0 ]; check "5 N: a grid" $?
[ "$(awk '{print $1}' <<<"$clean")" = "0" ]; check "5 N interior: no point clean" $?
[ "$(awk '{print $1, $3}' <<<"$stops")" = "$((pts * 2)) $((pts * 2))" ]; check "5 N interior: every press stops" $?
[ "$(tr -d ' ' <<<"$causes" | awk -F/ '{print $1 + $2 + $3 + $4}')" = "$((pts * 2))" ]; check "5 N interior: the causes add up" $?

slow_pts=$(grep -o 'At each of [0-9]* grid points' "$work/hard.md" | sed -n 2p | awk '{print $4}')
within=$(row "points whose first STOP is within the band" "$work/hard.md")
split=$(row "first STOP below the band" "$work/hard.md")
slow_causes=$(row "first STOP by cause" "$work/hard.md")
echo "slow interior: $slow_pts points; within: $within; early/late/release/none: $split; causes: $slow_causes"
[ -n "$slow_pts" ] && [ "$slow_pts" -gt 0 ]; check "slow: a grid" $?
w=$(awk '{print $1}' <<<"$within")
[ "$(tr -d ' ' <<<"$split" | awk -F/ -v w="$w" '{print w + $1 + $2 + $3 + $4}')" = "$slow_pts" ]; check "slow: the counts add up" $?
[ "$(tr -d ' ' <<<"$split" | awk -F/ '{print $3 + $4}')" = "0" ]; check "slow interior: every press stops in its ramp" $?
[ "$(tr -d ' ' <<<"$slow_causes" | awk -F/ '{print $1 + $2 + $3 + $4}')" = "$slow_pts" ]; check "slow: the causes add up" $?
grep -Eq '\| true force at the first STOP, p5 / p50 / p95 \(the '"$slow_pts"' points stopped in the ramp\) \| [0-9.]+ / [0-9.]+ / [0-9.]+ N' "$work/hard.md"
check "slow: the distribution over every point" $?

# Pairs: a hard press with a light touch elsewhere. In the interior 50 and 200 N stop every time they are judged
# (a press whose light touch alone stopped first is not); 0.01 N with a light touch of 0 N never stops, and every
# press is judged. Row: "| FORCE | pass of covered (..) | missed of judged | covered unjudged | pass of all (..) |"
"$ruffini" coverage-targets --scene "$scene" --patch upper_arm_a --target pair --pair-at all --edge-mm 30 --step-mm 30 \
  --pair-forces-n 50 200 --pair-presses 1 --threads 2 --report "$work/pair" >"$work/pair.md" 2>"$work/pair.err" \
  || { echo "FAIL: pair run"; cat "$work/pair.err"; exit 1; }
for f in 50 200; do
  for sec in 1 2; do  # the grid points, then the cell centres
    r=$(grep "^| $f | " "$work/pair.md" | sed -n ${sec}p)
    echo "pair $f N (section $sec): $r"
    ok=$(awk -F'|' '{split($3, a, " "); split($4, b, " "); u = $5 + 0; print (a[3] > 0 && a[1] + u == a[3] && b[1] == 0 && b[3] == a[3] - u && b[3] > 0) ? 0 : 1}' <<<"$r")
    [ "$ok" = "0" ]; check "pair $f N interior (section $sec): every judged press stops" $?
  done
done
# The border section (the third): points 0.5 mm inside the bands, every one covered; its counts add up.
for f in 50 200; do
  r=$(grep "^| $f | " "$work/pair.md" | sed -n 3p)
  echo "pair $f N (border): $r"
  ok=$(awk -F'|' '{split($3, a, " "); split($4, b, " "); split($6, d, " "); u = $5 + 0; print (a[3] > 20 && a[3] == d[3] && b[3] == a[3] - u && a[1] <= a[3] - u) ? 0 : 1}' <<<"$r")
  [ "$ok" = "0" ]; check "pair $f N border: every point covered, the counts add up" $?
done
grep -q "points on the border of the covered surface" "$work/pair.md"; check "pair: the border section is there" $?
"$ruffini" coverage-targets --scene "$scene" --patch upper_arm_a --target pair --pair-at grid --edge-mm 30 --step-mm 30 \
  --pair-forces-n 0.01 --pair-light-n 0 0 --pair-presses 2 --threads 2 >"$work/pair0.md" 2>"$work/pair0.err" \
  || { echo "FAIL: zero pair run"; cat "$work/pair0.err"; exit 1; }
r=$(grep "^| 0.01 | " "$work/pair0.md")
echo "pair 0.01 N: $r"
ok=$(awk -F'|' '{split($3, a, " "); split($4, b, " "); print (a[1] == 0 && a[3] > 0 && b[1] == b[3] && b[3] == 2 * a[3] && $5 + 0 == 0) ? 0 : 1}' <<<"$r")
[ "$ok" = "0" ]; check "pair 0.01 N: no press stops, every covered press judged" $?
grep -q "The light touch alone stopped before the hard press (not judged) in 0 of" "$work/pair0.md"; check "pair: a 0 N light touch never stops" $?
for f in upper_arm_a-pair.svg upper_arm_a-pair-centres.svg; do
  grep -q '^<svg ' "$work/pair/$f"; check "report: $f is an SVG" $?
done

# Bad input: a clear error, no report.
out=$("$ruffini" coverage-targets --scene "$scene" --target pair --pair-at edges 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "pair-at must be grid, centres, border or all (got 'edges')" <<<"$out"; check "a bad --pair-at is refused" $?
for opts in "--pair-forces-n 5 nan" "--pair-forces-n inf" "--pair-light-n 1 nan" "--force-n nan" "--jitter-mm nan"; do
  out=$("$ruffini" coverage-targets --scene "$scene" --target pair $opts 2>&1); rc=$?
  [ $rc -ne 0 ] && grep -Eq "must be a finite number|not in range" <<<"$out"; check "$opts is refused (review 13: CLI11's Range passes NaN)" $?
done
out=$("$ruffini" coverage-targets --scene "$scene" --target pair --pair-light-n 2 1 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "pair-light-n: the light touch's range" <<<"$out"; check "a reversed light range is refused" $?
out=$("$ruffini" coverage-targets --scene "$(dirname "$scene")/forearm.yaml" --target light 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q 'forearm.yaml has no safety section: give --level-n' <<<"$out"; check "a scene without thresholds needs --level-n" $?
out=$("$ruffini" coverage-targets --scene "$scene" --target slow --slow-top-n 1.6 2>&1); rc=$?
[ $rc -ne 0 ] && grep -q "slow-top-n (1.60 N) must lie above the band's top (1.72 N)" <<<"$out"; check "a slow press that cannot leave the band is refused" $?

for f in upper_arm_a.md upper_arm_a-light.svg upper_arm_a-slow.svg upper_arm_a-slow-sorted.svg; do
  [ -s "$work/report/$f" ]; check "report: $f written" $?
done
for f in light slow slow-sorted; do
  grep -q '^<svg ' "$work/report/upper_arm_a-$f.svg"; check "report: upper_arm_a-$f.svg is an SVG" $?
done
grep -q '>upper_arm_a: presses of 5.00 N that STOP' "$work/report/upper_arm_a-light.svg"; check "light figure titled" $?
grep -q '>upper_arm_a: slow press' "$work/report/upper_arm_a-slow.svg"; check "slow figure titled" $?
cmp -s "$work/hard.md" "$work/report/upper_arm_a.md"; check "the report file is what was printed" $?
exit $fail
