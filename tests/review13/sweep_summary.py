#!/usr/bin/env python3
# Summarise a probe run of sweep.py's cases: per hard press, how many light placements (at least 30 mm away) hide
# it (no stop), split by whether that light touch alone stops, and by where the light touch is (covered or a band).
import re, sys, collections
def band(y, r): return not (25 < y < 120 and 23 < r < 122.5) or (25 <= y <= 35 and r >= 114.5)
alone, rows = {}, collections.defaultdict(list); single = {}
for l in open(sys.argv[1]):
    m = re.match(r"(\S+) (\d+) (.*) : stops (yes|NO), largest ([\d.-]+)", l)
    if not m: continue
    v = [float(x) for x in m.group(3).split()]; st = m.group(4) == "yes"
    if len(v) == 3 and v[2] < 2: alone[(v[0], v[1])] = st
    elif len(v) == 3: single[tuple(v)] = (st, m.group(5))
    else: rows[tuple(v[:3])].append((v[3], v[4], st))
print("light touch alone stops at %d of %d placements" % (sum(alone.values()), len(alone)))
for k, lst in rows.items():
    hid = [(y, r) for y, r, s in lst if not s]
    hid_q = [(y, r) for (y, r) in hid if not alone.get((y, r), False)]
    cnt_alone_stop = sum(1 for y, r, s in lst if alone.get((y, r), False))
    print("%5g N at Y %5.1f R %5.1f (alone: %s, %s N): hidden by %d of %d placements (%d where the light alone does not stop; in bands %d); light alone stops at %d of them"
          % (k[2], k[0], k[1], "stops" if single.get(k, (None,))[0] else "NO", single.get(k, (0, "?"))[1], len(hid), len(lst), len(hid_q),
             sum(1 for (y, r) in hid_q if band(y, r)), cnt_alone_stop))
