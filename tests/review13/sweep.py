#!/usr/bin/env python3
# Review 13: the light touch's placement swept over the patch (a 10 mm x 10 deg grid, at least 30 mm from the hard
# press), for hard presses at the covered border and at the nearest points `coverage-targets --target pair` measures.
# Writes cases for tests/review13/out/probe.  Usage: sweep.py PATCH LIGHT_N SEED [FORCES e.g. 5,20] [HARD e.g. "119.5 23.5;117.5 26.8"] > cases
import math, sys
patch, lf, seed = sys.argv[1], float(sys.argv[2]), int(sys.argv[3])
mmdeg = 37.4 * math.pi / 180
hards = [(119.5, 23.5), (119.5, 122.0), (25.5, 23.5), (35.5, 122.0), (117.5, 26.8), (115.0, 30.6)]
forces = [float(x) for x in sys.argv[4].split(",")] if len(sys.argv) > 4 else [5, 20]
if len(sys.argv) > 5: hards = [tuple(float(v) for v in h.split()) for h in sys.argv[5].split(";")]
lights = [(y, r) for y in range(5, 150, 10) for r in range(5, 145, 10)]
for ly, lr in lights: print(patch, seed, ly, lr, lf)
for f in forces:
    for y, r in hards:
        print(patch, seed, y, r, "%g" % f)
        for ly, lr in lights:
            if math.hypot(ly - y, (lr - r) * mmdeg) >= 30: print(patch, seed, y, r, "%g" % f, ly, lr, lf)
