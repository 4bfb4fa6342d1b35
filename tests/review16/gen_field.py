#!/usr/bin/env python3
# Review 16: hard press + light touch on the field scene's upper_arm_a, each from CLEAR (reset 2.5 s before),
# in tests/review13/match.py's format. Usage: gen_field.py OUT.yaml REPEATS
import sys
out, reps = sys.argv[1], int(sys.argv[2])
import os
P = os.environ.get("PATCH", "upper_arm_a")
L = ["# Review 16: hard press + light touch on " + P + " of cobot-field.yaml, each from CLEAR.",
     "loop: false", "duration_s: 0", "seed: 16", "presses:"]
base_a = [
    ((119.5, 23.5, 5), (130, 70, 0.4)),    # the new test's pair: old reads 0.70 N (no stop), new 2.34 N
    ((119.5, 23.5, 5), (110, 70, 0.4)),    # pair_sweep seed 1: new still misses (1.20 N)
    ((119.5, 122.0, 5), (110, 70, 0.4)),   # pair_sweep seed 1: both miss
    ((119.5, 23.5, 5), None),              # control: the press alone
    ((70, 70, 2.25), None),                # a single 2.25 N press mid-patch
    ((115, 30, 4), (60, 100, 1.0)),        # 4 N (the press factor) near the wrist-end corner with 1 N held
    (None, (130, 70, 0.4)),                # control: the light touch alone
]
base_b = [  # upper_arm_b, pair_sweep seed 1: old misses 1, 3, 4 and 5; new misses 2 and 4
    ((119.5, 23.5, 5), (130, 70, 0.4)),
    ((119.5, 23.5, 5), (110, 70, 0.4)),
    ((119.5, 122.0, 5), (110, 70, 0.4)),
    ((119.5, 122.0, 5), (70, 90, 0.4)),
    ((119.5, 23.5, 5), (90, 70, 0.4)),
    ((70, 70, 2.25), None),
    (None, (70, 90, 0.4)),
]
base = base_b if P == "upper_arm_b" else base_a
cases = [c for _ in range(reps) for c in base]
t = 9.0; resets = []
def press(y, r, f, at, hold, ramp=0.3):
    L.append("  - {t_s: %.1f, patch: %s, y_mm: %.2f, r_deg: %.2f, force_n: %g, ramp_s: %g, hold_s: %g, release_s: %g}" % (at, P, y, r, f, ramp, hold, ramp))
for c in cases:
    hard, light = c[0], c[-1]
    resets.append(t - 2.5)
    if light: press(light[0], light[1], light[2], t - 0.3, 1.9 if hard else 1.0)
    if hard: press(hard[0], hard[1], hard[2], t, 1.0)
    t += 5.5
L[2] = "duration_s: %d" % (t + 5)
open(out, "w").write("\n".join(L) + "\n")
print(" ".join("%.1f" % r for r in resets), "%.0f" % t)
