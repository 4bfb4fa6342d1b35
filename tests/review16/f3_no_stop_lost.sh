#!/bin/bash
# Review 16, finding 3 (no regression found): presses the OLD upper-arm file stops and the NEW one does not.
# (a) hard_press_grid, single presses at 176 points (edges included) x 1.5-200 N, both upper arms, old vs new;
# (b) pair_sweep old vs new: hard presses at the covered corners, the interior and the edges, 2.25-20 N, with a
#     0.4 N and a 1.0 N touch swept over 40-42 places, noise seed SEEDS (default 1), both upper arms.
# Exit 1 when any press (or placement) stops with the old file and not with the new one, or the new file reads any
# press's largest force lower. Run under nice; about 10 min on 2 idle cores (SEEDS="1 2" doubles (b)).
set -u; . "$(dirname "$0")/lib.sh"; make_configs
SEEDS=${SEEDS:-1}; J=${J:-2}
# (a)
for p in 2 3; do for v in old new; do echo "$v $p"; done; done | xargs -P$J -L1 sh -c \
  "HARD_PRESS_VERBOSE=1 nice -n 10 $B/hard_press_grid $OUT/\$0/scenes/cobot-field.yaml \$1 1.5 1.5 2.25 3 4 5 10 20 50 200 > $OUT/f3-hpg-\$0-\$1.txt 2>&1"
# (b)
mkdir -p $OUT/f3
for p in upper_arm_a upper_arm_b; do for pt in "25.5 23.5" "119.5 23.5" "119.5 122" "35.5 122" "70 72" "110 97" "2 72" "148 72" "75 2" "75 143"; do
  for f in 2.25 3 5 10 20; do for l in 0.4 1.0; do for s in $SEEDS; do for v in old new; do
    echo "$v $p $pt $f $l 1.5 $s"; done; done; done; done; done; done |
  xargs -P$J -L1 sh -c "nice -n 10 $B/pair_sweep $OUT/\$0/scenes/cobot-field.yaml \"\$@\" > $OUT/f3/\$0_\$1_\$2_\$3_\$4_\$5_\$7.txt" 
python3 - "$OUT" <<'PY'
import glob, os, re, sys
out = sys.argv[1]; bad = 0
# (a)
for p in "23":
    def nostop(v):
        d, pend = {}, []
        for l in open(f"{out}/f3-hpg-{v}-{p}.txt"):
            m = re.match(r"  no stop at Y ([\d.]+) R ([\d.]+)", l)
            if m: pend.append((m.group(1), m.group(2)))
            m = re.match(r"\s+([\d.]+)\s+176\s", l)
            if m: d[m.group(1)] = set(pend); pend = []
        return d
    o, n = nostop("old"), nostop("new")
    for f in o:
        lost = sorted(n[f] - o[f])
        bad += len(lost)
        print(f"single presses, patch {p}, {f} N: no stop old {len(o[f])}, new {len(n[f])}; stopped by old only: {lost}")
# (b)
line = re.compile(r"([\d.]+) N at Y\s+([\d.]+) R\s+([\d.]+): largest ([\d.\-]+) N, stops (yes|NO)")
alone = re.compile(r"alone: largest ([\d.\-]+) N, stops (yes|NO)")
pairs = lost = gained = lower = 0
for f in glob.glob(f"{out}/f3/old_*.txt"):
    g = f.replace("/old_", "/new_")
    po, pn = open(f).read(), open(g).read()
    o = {(m.group(2), m.group(3)): (float(m.group(4)), m.group(5)) for m in line.finditer(po)}
    n = {(m.group(2), m.group(3)): (float(m.group(4)), m.group(5)) for m in line.finditer(pn)}
    a, b = alone.search(po), alone.search(pn)
    o["alone"], n["alone"] = (float(a.group(1)), a.group(2)), (float(b.group(1)), b.group(2))
    for k in o:
        pairs += 1
        if o[k][1] == "yes" and n[k][1] == "NO": lost += 1; print("STOP LOST:", os.path.basename(f), k, o[k], n[k])
        if o[k][1] == "NO" and n[k][1] == "yes": gained += 1
        if n[k][0] < o[k][0] - 0.005: lower += 1; print("read lower:", os.path.basename(f), k, o[k], n[k])
print(f"pair_sweep: {pairs} presses compared; stopped by old only {lost}, by new only {gained}; read lower by new {lower}")
bad += lost + lower
print("PROBLEM" if bad else "ok: no press the old file stops is lost with the new one")
sys.exit(1 if bad else 0)
PY
