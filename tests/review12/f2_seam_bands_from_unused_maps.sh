#!/bin/bash
# Review 12, finding 2: maps the scene check names "not used" (measured on another mounting) still set the fusion's
# seam bands at aggregator load (SeamsOf reads setup.patches[i].sensitivity = every map of the model, not the bound
# ones). And check-scene says the forearm region has "no patch of the scene" when both its patches are accepted whole.
# Scene: cobot.yaml with the forearm model files swapped (each map measured on the other seam side) and both forearm
# patches accepted whole (so the scene loads). Exit 1 while it reproduces. ~10 s.
H=$(cd "$(dirname "$0")" && pwd); B=$H/../../build/release/bin; cd "$H"; mkdir -p out
repro=0
$B/ruffini check-scene scenes/cobot-swap-accepted.yaml > out/f2-check.txt 2>&1
grep -c "maps not used" out/f2-check.txt | sed 's/^/maps not used lines: /'
if grep -q "region forearm: threshold 1.50 N; no patch of the scene is in this region" out/f2-check.txt; then
  echo "misreport: check-scene says region forearm has no patch (it has forearm_a and forearm_b, both accepted whole)"; repro=1; fi
for s in cobot-copy cobot-swap-accepted; do
  $B/ruffini-aggregator --scene scenes/$s.yaml --listen 127.0.0.1:0 --metrics 127.0.0.1:0 --insecure > out/f2-agg-$s.log 2>&1 &
  pid=$!; for i in $(seq 40); do grep -q "seam forearm_a" out/f2-agg-$s.log && break; sleep 0.25; done; kill $pid; wait $pid 2>/dev/null
  echo "$s: $(grep -o 'seam forearm_a[^;]*;' out/f2-agg-$s.log | head -1)"
done
if grep -q "seam forearm_a r_max | forearm_b r_min (bands [0-9.]* / [0-9.]* mm);" out/f2-agg-cobot-swap-accepted.log &&
   ! grep -q "bands 0.00 / 0.00" out/f2-agg-cobot-swap-accepted.log; then
  echo "seam bands set from maps the coverage check did not use (expected: no seam rule, a side has no bound map)"; repro=1; fi
[ $repro = 1 ] && { echo "REPRODUCES"; exit 1; }; echo "fixed"; exit 0
