#!/usr/bin/env python3
"""Review 14, finding on false stops: single light touches (0.5-1.2 N) on upper_arm_a's covered surface
(Y 30-110 mm, R 25-115 deg: 9 x 10 points), seed 1, pressed through the unit tests' rig
(tests/review14/out/probe, review 13's probe.cpp) with the shipped scene (cobot-upper_arm.rmodel) and a copy naming
forearm.rmodel. Prints stops per force for both, and the presses that stop only with the new file.
Exit 1 when the new file stops more single light touches (<= 1.2 N) than forearm.rmodel did."""
import os, subprocess, sys
ROOT = "/work/main"; O = ROOT + "/tests/review14/out"
subprocess.run([ROOT + "/tests/review14/build_probe.sh"], cwd=ROOT, check=True)
SC = {"new": ROOT + "/config/scenes/cobot.yaml", "old": O + "/cobot-forearm.yaml"}
forces = [0.5, 0.7, 0.9, 1.1, 1.2]
cases = [f"upper_arm_a {s} {y} {r} {f}" for s in (1,) for f in forces for y in range(30, 116, 10) for r in range(25, 121, 10)]
res = {}
def run(k):
    fn = f"{O}/light_{k}.txt"
    p = subprocess.Popen(["nice", "-n", "10", "timeout", "900", O + "/probe", SC[k]], stdin=subprocess.PIPE, stdout=open(fn, "w"), text=True)
    return p, fn
procs = {k: run(k) for k in SC}
for k, (p, fn) in procs.items():
    p.stdin.write("\n".join(cases) + "\n"); p.stdin.close()
for k, (p, fn) in procs.items():
    p.wait()
    res[k] = {}
    for l in open(fn):
        c, rest = l.split(" : ")
        res[k][c.strip()] = ("stops yes" in rest, rest.strip())
print(f"{len(cases)} single presses per file (9 x 10 grid on the covered surface, 5 forces, seed 1)")
print("| force | new stops | old stops | new only | old only |\n| --- | --- | --- | --- | --- |")
tn = to = 0; only_new = []
for f in forces:
    cs = [c for c in cases if c.endswith(f" {f}")]
    n = sum(res["new"][c][0] for c in cs); o = sum(res["old"][c][0] for c in cs)
    on = [c for c in cs if res["new"][c][0] and not res["old"][c][0]]
    oo = [c for c in cs if res["old"][c][0] and not res["new"][c][0]]
    only_new += on; tn += n; to += o
    print(f"| {f} N | {n} / {len(cs)} | {o} / {len(cs)} | {len(on)} | {len(oo)} |")
print(f"total: new {tn}, old {to}")
for c in only_new[:40]:
    print("  new only:", c, "|", res["new"][c][1], "| old:", res["old"][c][1])
sys.exit(1 if tn > to else 0)
