#!/usr/bin/env python3
# Review 13 (adapted from tests/review10/match.sh): match the aggregator's latches to a gen_pair.py scenario's cases.
# For each case (a hard press, maybe with a light touch 0.3 s before it; or a light touch alone): the state when
# the light touch comes on (must be CLEAR), a latch (a contact cause or a FAULT) before the hard press
# ("light first"), and one from the hard press's start to the end of its release + 0.3 s.
# Usage: match.py RUNDIR SCENARIO [MINFORCE]   prints one line per case and a summary; "MISS" = hard press
# (>= MINFORCE, default 5 N) that started from CLEAR with no latch.
import re, sys, datetime
D, SC = sys.argv[1], sys.argv[2]; minf = float(sys.argv[3]) if len(sys.argv) > 3 else 5.0
t0 = int(re.search(r"sample 0 is at Unix time (\d+)", open(D + "/sim/err").read()).group(1)) / 1e9
ev = []  # (t, type, state, cause, patch, force)
for l in open(D + "/agg/err"):
    if "safety_event" not in l: continue
    m = re.match(r"\[(\S+ \S+)\]", l)
    ts = datetime.datetime.strptime(m.group(1), "%Y-%m-%d %H:%M:%S.%f").timestamp() - t0
    kv = dict(re.findall(r"(\w+)=(\S+)", l.split("safety_event", 1)[1]))
    ev.append((ts, kv.get("type"), kv.get("state"), kv.get("cause"), kv.get("patch"), kv.get("force_n")))
def state_at(t):
    s = "?"
    for e in ev:
        if e[0] <= t: s = e[2]
    return s
def latch(e): return e[1] not in ("reset_accepted", "reset_refused") and (e[3] == "contact" or e[2] == "fault")
pr = []
for l in open(SC):
    m = re.search(r"t_s: ([\d.]+), patch: (\w+), y_mm: ([-\d.]+), r_deg: ([-\d.]+), force_n: ([\d.]+), ramp_s: ([\d.]+), hold_s: ([\d.]+)", l)
    if m: pr.append((float(m.group(1)), m.group(2), float(m.group(3)), float(m.group(4)), float(m.group(5)), float(m.group(7))))
cases = []; i = 0
while i < len(pr):
    a = pr[i]
    if a[4] < 2 and i + 1 < len(pr) and pr[i + 1][4] >= 2 and min(abs(pr[i + 1][0] - a[0] - 0.3), abs(pr[i + 1][0] - a[0])) < 1e-6:
        cases.append((a, pr[i + 1])); i += 2
    elif a[4] < 2: cases.append((a, None)); i += 1
    else: cases.append((None, a)); i += 1
miss = n = lightfirst = notclear = 0; lines = []
for light, hard in cases:
    start = (light or hard)[0]
    th = hard[0] if hard else light[0]
    end = th + 0.6 + (hard or light)[5] + 0.3
    st = state_at(start - 0.01)
    before = [e for e in ev if start - 0.01 <= e[0] < th - 0.05 and latch(e)] if hard else []
    during = [e for e in ev if th - 0.05 <= e[0] <= end and latch(e)]
    desc = ("hard %-11s Y %6.1f R %6.1f F %5g" % (hard[1], hard[2], hard[3], hard[4])) if hard else "hard -" + " " * 33
    desc += ("  light Y %5.1f R %5.1f F %4.2f" % (light[2], light[3], light[4])) if light else "  light -" + " " * 23
    if st != "clear": res = "NOT FROM CLEAR (%s)" % st; notclear += 1
    elif before: res = "LIGHT FIRST: %s %s %s %s" % before[0][2:6]; lightfirst += 1
    elif during: res = "latched: %s %s %s %s" % during[0][2:6]
    else: res = "NO STOP/FAULT"
    if hard and hard[4] >= minf and st == "clear" and not before:
        n += 1
        if not during: miss += 1; res = "MISS " + res
    print("%7.1f %s : %s" % (th, desc, res))
print("hard presses >= %g N judged from CLEAR: %d, MISSED (no STOP, no FAULT): %d; light touch latched first: %d; not from CLEAR: %d" % (minf, n, miss, lightfirst, notclear))
