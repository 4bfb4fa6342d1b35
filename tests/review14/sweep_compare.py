#!/usr/bin/env python3
"""Sweep a light touch (pair_sweep) around hard presses on upper_arm_a, with the shipped scene
(cobot-upper_arm.rmodel) and a copy naming forearm.rmodel; report placements where the new file
misses a pair that forearm.rmodel stopped (the check makes it WORSE). Outputs under out/sweeps/.
usage: sweep_compare.py [--quick]  (exit 1 if any WORSE placement is found)"""
import itertools, os, re, subprocess, sys
from concurrent.futures import ThreadPoolExecutor
ROOT = "/work/main"
B = ROOT + "/build/release/bin/pair_sweep"
OUT = ROOT + "/tests/review14/out/sweeps"
os.makedirs(OUT, exist_ok=True)
SCENES = {"new": ROOT + "/config/scenes/cobot.yaml", "old": ROOT + "/tests/review14/out/cobot-forearm.yaml"}
quick = "--quick" in sys.argv
points = [(119.5, 23.5), (119.5, 122), (115, 23.5), (110, 23.5)]
forces = [3, 5, 10]
lights = [0.2, 0.4, 0.7, 1.0]
seeds = [1]
if quick:
    points, forces, lights = [(119.5, 23.5), (119.5, 122)], [5], [0.4, 0.7]
jobs = []
for (y, r), f, l, s in itertools.product(points, forces, lights, seeds):
    for k in SCENES:
        jobs.append((k, y, r, f, l, s))

def run(j):
    k, y, r, f, l, s = j
    fn = f"{OUT}/{k}_{y}_{r}_{f}_{l}_{s}.txt"
    if not os.path.exists(fn) or os.path.getsize(fn) == 0 or "placements" not in open(fn).read():
        with open(fn, "w") as fh:
            subprocess.run(["nice", "-n", "10", "timeout", "120", B, SCENES[k], "upper_arm_a", str(y), str(r), str(f), str(l), "1.5", str(s)],
                           stdout=fh, stderr=subprocess.STDOUT)
    return fn

def parse(fn):
    t = open(fn).read()
    m = re.search(r"alone: largest ([\d.]+) N, stops (\w+)", t)
    pl = {}
    for a, b, mx, st, fl in re.findall(r"N at Y\s+([\d.]+) R\s+([\d.]+): largest ([\d.-]+) N, stops (\w+), flagged (\d+)", t):
        pl[(float(a), float(b))] = (float(mx), st == "yes", int(fl))
    return (float(m.group(1)), m.group(2) == "yes") if m else (None, None), pl

with ThreadPoolExecutor(2) as ex:
    list(ex.map(run, jobs))
worse_total = better_total = 0
print("| hard | light | seed | alone new / old | misses new / old | worse (new misses, old stops) | better |")
print("| --- | --- | --- | --- | --- | --- | --- |")
worse_list = []
for (y, r), f, l, s in itertools.product(points, forces, lights, seeds):
    an, pn = parse(f"{OUT}/new_{y}_{r}_{f}_{l}_{s}.txt")
    ao, po = parse(f"{OUT}/old_{y}_{r}_{f}_{l}_{s}.txt")
    mn = sum(1 for v in pn.values() if not v[1]); mo = sum(1 for v in po.values() if not v[1])
    worse = [k for k in pn if not pn[k][1] and po.get(k, (0, False))[1]]
    better = [k for k in pn if pn[k][1] and not po.get(k, (0, True))[1]]
    worse_total += len(worse); better_total += len(better)
    for w in worse:
        worse_list.append((y, r, f, l, s, w, pn[w], po[w]))
    print(f"| {f} N Y {y} R {r} | {l} N | {s} | {an[0]} {an[1]} / {ao[0]} {ao[1]} | {mn} / {mo} of {len(pn)} | {len(worse)} | {len(better)} |")
print(f"\nplacements WORSE with cobot-upper_arm.rmodel: {worse_total}; better: {better_total}")
for w in worse_list:
    print(f"  WORSE: {w[2]} N at Y {w[0]} R {w[1]} + {w[3]} N at Y {w[5][0]} R {w[5][1]} seed {w[4]}: new largest {w[6][0]} N flagged {w[6][2]}; old largest {w[7][0]} N")
sys.exit(1 if worse_total else 0)
