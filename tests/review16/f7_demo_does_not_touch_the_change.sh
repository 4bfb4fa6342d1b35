#!/bin/bash
# Review 16, finding 7: "demo unchanged (15 of 15, the same delays)" is true and says little: the demo's scenario
# touches the upper arms once, 2.5 N in the middle of upper_arm_a, alone; no light touch, no pair, no wrist-end
# corner on either upper arm, so the two-touch check of 6d63c0f cannot change any demo event. Exit 1 while the
# default scenario has no upper-arm press other than single presses away from the wrist end.
set -u; . "$(dirname "$0")/lib.sh"
S=$ROOT/config/scenarios/cobot-demo.yaml
grep -E '^\s*- \{t_s' $S | grep upper_arm | sed 's/^/  scripted: /'
python3 - $S <<'PY'
import re, sys, collections
pr = [re.search(r"t_s: ([\d.]+), patch: (\w+), y_mm: ([\d.]+), r_deg: ([\d.]+), force_n: ([\d.]+)", l) for l in open(sys.argv[1])]
pr = [(float(m.group(1)), m.group(2), float(m.group(3)), float(m.group(4)), float(m.group(5))) for m in pr if m]
ua = [p for p in pr if p[1].startswith("upper_arm")]
at = collections.Counter((p[0], p[1]) for p in ua)
pairs = [k for k, n in at.items() if n > 1]
corner = [p for p in ua if p[2] > 110]
light = [p for p in ua if p[4] < 1.5]
print(f"upper-arm presses: {len(ua)}; pairs: {len(pairs)}; near the wrist end (Y > 110): {len(corner)}; light (< 1.5 N): {len(light)}")
blind = not pairs and not corner and not light
print("PROBLEM: the demo cannot show the upper arms' two-touch check either way" if blind else "ok")
sys.exit(1 if blind else 0)
PY
