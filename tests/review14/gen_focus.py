#!/usr/bin/env python3
# Review 14: a ruffini-sim scenario for upper_arm_a of cobot.yaml (now cobot-upper_arm.rmodel): hard presses at the
# covered wrist-end corners with a light touch held elsewhere (0.3 s before, or together), each from CLEAR (an
# operator's reset 2.5 s before), in the format tests/review13/match.py reads. Usage: gen_focus.py OUT.yaml REPEATS
import sys
out, reps = sys.argv[1], int(sys.argv[2])
L = ["# Review 14 (tests/review14/gen_focus.py): hard press + light touch on upper_arm_a, each from CLEAR.",
     "loop: false", "duration_s: 0", "seed: 14", "presses:"]
P = "upper_arm_a"
base = [
    ((119.5, 23.5, 5), (130, 70, 0.55)),   # review 13's worst: claimed fixed by stop 33
    ((119.5, 122.0, 5), (130, 70, 0.55)),  # review 13: missed 2/2
    ((119.5, 23.5, 5), (90, 70, 0.6)),     # review 13: missed 2/2
    ((119.5, 23.5, 5), (110, 70, 0.4)),    # stop 33's DISABLED test (read <= 1.07 N)
    ((119.5, 23.5, 5), (70, 90, 0.4)),     # pair_sweep seed 1 placement without a stop
    ((119.5, 23.5, 20), "same", (130, 70, 1.0)),  # together (review 13: missed 2/2)
    ((119.5, 23.5, 5), None),              # control: the press alone
    (None, (110, 70, 0.4)),                # control: the light touch alone
]
cases = [c for _ in range(reps) for c in base]
t = 9.0; resets = []
def press(y, r, f, at, hold, ramp=0.3):
    L.append("  - {t_s: %.1f, patch: %s, y_mm: %.2f, r_deg: %.2f, force_n: %g, ramp_s: %g, hold_s: %g, release_s: %g}" % (at, P, y, r, f, ramp, hold, ramp))
for c in cases:
    hard, light = c[0], c[-1]
    resets.append(t - 2.5)
    if len(c) == 3: press(light[0], light[1], light[2], t, 1.0)
    elif light: press(light[0], light[1], light[2], t - 0.3, 1.9 if hard else 1.0)
    if hard: press(hard[0], hard[1], hard[2], t, 1.0)
    t += 5.5
L[2] = "duration_s: %d" % (t + 5)
open(out, "w").write("\n".join(L) + "\n")
print(" ".join("%.1f" % r for r in resets), "%.0f" % t)
