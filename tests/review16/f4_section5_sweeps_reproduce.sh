#!/bin/bash
# Review 16, finding 4 (figures reproduce): docs/experiments/pair.md section 5's sweep rows (validation: 5 N + 0.5 N,
# seed 2; held out: 5 / 3 / 10 / 20 N + 0.4 N and 20 N + 1.0 N, seed 1, the four corners), old vs new files, both
# upper arms. Exit 1 when a count differs from the page. About 2-3 min on 2 cores.
set -u; . "$(dirname "$0")/lib.sh"; make_configs
J=${J:-2}; mkdir -p $OUT/f4
for p in upper_arm_a upper_arm_b; do for v in old new; do
  for pt in "25.5 23.5" "119.5 23.5" "119.5 122" "35.5 122"; do for fl in "5 0.4" "3 0.4" "10 0.4" "20 0.4" "20 1.0"; do
    echo "$v $p $pt $fl 1.5 1"; done; done
  for pt in "119.5 23.5" "119.5 122"; do echo "$v $p $pt 5 0.5 1.5 2"; done
done; done | xargs -P$J -L1 sh -c "nice -n 10 $B/pair_sweep $OUT/\$0/scenes/cobot-field.yaml \"\$@\" > $OUT/f4/\$0_\$1_\$2_\$3_\$4_\$5_\$7.txt"
python3 - "$OUT/f4" <<'PY'
import re, sys
D = sys.argv[1]
def miss(v, p, y, r, f, l, s):
    t = open(f"{D}/{v}_{p}_{y}_{r}_{f}_{l}_{s}.txt").read()
    return int(re.search(r"placements without a stop: (\d+) of", t).group(1))
C = [("25.5", "23.5"), ("119.5", "23.5"), ("119.5", "122"), ("35.5", "122")]
page = {  # pair.md section 5: (patch, row) -> (old, new)
    ("upper_arm_a", "5 0.4 corners"): ([0, 4, 5, 1], [0, 1, 5, 1]), ("upper_arm_b", "5 0.4 corners"): ([0, 5, 3, 0], [0, 1, 1, 0]),
    ("upper_arm_a", "3 0.4 corners"): ([0, 10, 10, 4], [0, 10, 10, 3]), ("upper_arm_b", "3 0.4 corners"): ([0, 9, 7, 3], [0, 9, 4, 3]),
    ("upper_arm_a", "10 0.4 sum"): (2, 1), ("upper_arm_b", "10 0.4 sum"): (2, 1),
    ("upper_arm_a", "20 0.4 sum"): (0, 0), ("upper_arm_b", "20 0.4 sum"): (0, 0),
    ("upper_arm_a", "20 1.0 sum"): (1, 1), ("upper_arm_b", "20 1.0 sum"): (1, 0),
    ("upper_arm_a", "validation 5 0.5"): ([7, 6], [1, 5]), ("upper_arm_b", "validation 5 0.5"): ([6, 2], [1, 1]),
}
bad = 0
for (p, row), want in page.items():
    got = []
    for v in ("old", "new"):
        if row.endswith("corners"):
            f, l = row.split()[:2]; got.append([miss(v, p, y, r, f, l, 1) for y, r in C])
        elif row.endswith("sum"):
            f, l = row.split()[:2]; got.append(sum(miss(v, p, y, r, f, l, 1) for y, r in C))
        else:
            got.append([miss(v, p, "119.5", r, "5", "0.5", 2) for r in ("23.5", "122")])
    ok = tuple(got) == want; bad += not ok
    print(f"{p:12s} {row:18s} page {want[0]} -> {want[1]}; measured {got[0]} -> {got[1]} {'ok' if ok else 'DIFFERS'}")
sys.exit(1 if bad else 0)
PY
