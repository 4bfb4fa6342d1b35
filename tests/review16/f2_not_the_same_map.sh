#!/bin/bash
# Review 16, finding 2: pair.md section 5, config/models/README.md and the new test's comment say the field upper
# arms "now carry the same map (learned on cast 0's validation recording, as the field forearms' is)". They do not:
# `fit-response --model cobot-field-upper_arm_X.rmodel` prepares the recording with that file's baseline
# (decode::BaselineFor), so each upper arm got its own refit, unlike every other patch's (byte-identical to
# forearm.rmodel's). Exit 1 while the shipped maps differ from the field forearms' and the docs say "the same map".
set -u; . "$(dirname "$0")/lib.sh"
M=$ROOT/config/models
rmodel_response $M/cobot-field-forearm_a.rmodel > $OUT/f2-ref.txt
status=0
for p in upper_arm_a upper_arm_b; do
  rmodel_response $M/cobot-field-$p.rmodel > $OUT/f2-$p.txt
  python3 - $OUT/f2-ref.txt $OUT/f2-$p.txt $p <<'PY' || status=1
import sys
def read(f):
    g = []; st = None
    for l in open(f):
        if 'g_pm_per_n' in l: g.append(float(l.split(':')[1]))
        if 'stiffening' in l: st = float(l.split(':')[1])
    return g, st
(a, sa), (b, sb) = read(sys.argv[1]), read(sys.argv[2])
diff = sum(1 for x, y in zip(a, b) if x != y)
rel = sorted(abs(x - y) / abs(x) for x, y in zip(a, b) if abs(x) > 1)
print(f"{sys.argv[3]}: {diff} of {len(a)} coefficients differ from cobot-field-forearm_a's map; stiffening {sb} vs {sa}; "
      f"relative change at |g| > 1 pm/N: median {rel[len(rel)//2]:.4%}, max {rel[-1]:.4%}")
sys.exit(1 if diff else 0)
PY
done
cmp -s $OUT/f2-upper_arm_a.txt $OUT/f2-upper_arm_b.txt || echo "upper_arm_a's and upper_arm_b's maps differ from each other too"
claim=$(cat $ROOT/docs/experiments/pair.md $ROOT/config/models/README.md $ROOT/tests/decode/two_touch_test.cpp | tr '\n' ' ' |
  grep -oE "They now carry the same map|now carry the same map \(learned|the same response map \(learned on the validation recording" | wc -l)
[ $status -ne 0 ] && [ "$claim" -gt 0 ] && { echo "PROBLEM: $claim doc places say 'the same map'; the maps differ"; exit 1; }
echo ok; exit 0
