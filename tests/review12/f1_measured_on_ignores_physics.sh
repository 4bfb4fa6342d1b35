#!/bin/bash
# Review 12, finding 1: a map's binding (measured_on) records the spec, the cast SEED and the four edge kinds only.
# Every other input of the twin it was measured on (the skin-sample parameters other than the seed, gain spread,
# noise, irregular gratings, stiffening, temperature, creep, faults, edge zone/gain, the probe) can change and the
# map is still "measured here". Shows: (1) check-scene GUARANTEES cobot.yaml copies whose cast parameters or
# interrogator noise differ; (2) the same tool, measuring a coarse map on those scenes with the same seeds, finds
# covered interior points that now need more than 2.25 N; (3) a map measured on the changed scene is accepted as
# bound on the original scene (same measured_on).
# Exit 1 while it reproduces. Run from anywhere; ~10 s.
H=$(cd "$(dirname "$0")" && pwd); B=$H/../../build/release/bin; cd "$H"; mkdir -p out
repro=0
for s in other-cast noise1; do
  echo "== scenes/cobot-$s.yaml (diff against cobot.yaml's copy):"; diff scenes/cobot-copy.yaml scenes/cobot-$s.yaml | grep '^[<>]'
  if $B/ruffini check-scene scenes/cobot-$s.yaml | tail -1 | grep -q '^ok:'; then echo "check-scene: GUARANTEED (exit 0)"; repro=1; fi
done
# Coarse maps (step 20 mm, ladder 2.25 / 200 N, same held-out seeds) on the original copy and the changed scenes.
for s in copy other-cast noise1; do
  $B/ruffini sensitivity --scene scenes/cobot-$s.yaml --patch upper_arm_a --model ../../config/models/forearm.rmodel \
    --out out/f1-$s.rmodel --report out/f1-$s --step-mm 20 --forces 2.25 200 --presses 20 --threads 2 >/dev/null 2>&1 || echo "sensitivity failed on $s"
done
python3 - <<'PY'
import re
def grid(s):
    t=open(f"out/f1-{s}/upper_arm_a.md").read().split("| Y \\ R |")[1].strip().splitlines()
    rs=[float(x) for x in t[0].strip('| ').split('|')]; out={}
    for line in t[2:]:
        if not line.startswith('|'): break
        c=[x.strip() for x in line.strip('|').split('|')]; y=float(c[0])
        for r,v in zip(rs,c[1:]): out[(y,r)]=float(v)
    return out
base=grid("copy")
for s in ("other-cast","noise1"):
    g=grid(s)
    # covered surface of cobot.yaml: Y 25..120 less Y25..35 x R>=114.5, R 23..122.5 (strictly inside the bands)
    worse=[(y,r,base[(y,r)],g[(y,r)]) for (y,r) in base if 25<y<120 and 23<r<122.5 and not (y<=35 and r>=114.5) and base[(y,r)]<=2.25<g[(y,r)]]
    print(f"{s}: covered interior points reliable at 2.25 N on the shipped scene but not on this one: {len(worse)}", worse)
PY
# The map measured on the changed scene binds to the ORIGINAL scene: same measured_on, no 'maps not used' line.
sed -e 's#../../../config/models/forearm.rmodel#../out/f1-other-cast.rmodel#' scenes/cobot-copy.yaml > scenes/f1-bound.yaml
if $B/ruffini check-scene scenes/f1-bound.yaml 2>&1 | grep -q "maps not used"; then echo "map from the changed scene: refused as measured elsewhere"; else echo "map measured on cobot-other-cast.yaml is used for cobot.yaml (bound; judged only on its coarse grid)"; repro=1; fi
[ $repro = 1 ] && { echo "REPRODUCES"; exit 1; }; echo "fixed"; exit 0
