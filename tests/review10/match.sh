#!/bin/bash
# Match the aggregator's contact latches (STOP epochs) to a scenario's presses: prints each press and whether a
# contact cause on its patch was latched between its start and 0.6 s after it (the sim's sample 0 = t 0).
# Usage: tests/review10/match.sh RUNDIR SCENARIO
D=$1; SC=$2
t0=$(grep -o "sample 0 is at Unix time [0-9]*" $D/sim/err | awk '{print $NF}')
grep "safety_event" $D/agg/err | grep -v "type=reset" | while read -r day tm rest; do
  s=$(date -d "$day ${tm%]}" +%s.%N 2>/dev/null || date -d "${day#[} ${tm%]}" +%s.%N); echo "$s $(echo "$rest" | grep -o 'state=[a-z]* .*cause=[a-z_]* patch=[^ ]* force_n=[^ ]*')"
done > $D/events.txt
python3 - "$t0" "$D/events.txt" "$SC" <<'PY'
import sys, re
t0 = int(sys.argv[1]) / 1e9
ev = []
for l in open(sys.argv[2]):
    p = l.split(None, 1); ev.append((float(p[0]) - t0, p[1].strip()))
hit = 0; n = 0
for l in open(sys.argv[3]):
    m = re.search(r"t_s: ([\d.]+),\s+patch: (\w+), y_mm: ([-\d.]+), r_deg: ([-\d.]+), force_n: ([\d.]+)", l)
    if not m: continue
    t = float(m.group(1)); n += 1
    got = [e for (te, e) in ev if t - 0.05 <= te <= t + 0.8 and ("cause=contact" in e or "state=fault" in e)]
    hit += 1 if got else 0
    print("%6.1f %-12s Y %6s R %7s F %6s : %s" % (t, m.group(2), m.group(3), m.group(4), m.group(5), got[0] if got else "NO STOP/FAULT"))
print("presses %d, with a latch %d" % (n, hit))
PY
