#!/bin/bash
# Finding 2: "indented maps byte-identical" is false. Re-fits the shipped upper-arm map from its own recording
# (the model's source: `ruffini fit-response --data paper_seed2.h5 --area indented --multiple-misfit 0.07`; the
# refit reproduces its stiffening to the last digit) and compares the grid with the shipped one, then runs the
# wrist-end sweep of pair.md with each. Exits 1 while the refit's R step differs from the shipped map's.
set -u
cd "$(dirname "$0")/../.." || exit 2
B=build/release/bin
T=${TMPDIR:-/tmp}/review15_fit; mkdir -p "$T"
nice -n 10 $B/ruffini simulate --scene config/scenes/forearm.yaml --protocol paper --seed 2 --out "$T/paper_seed2.h5" >/dev/null 2>&1 || exit 2
nice -n 10 $B/ruffini fit-response --model config/models/cobot-upper_arm.rmodel --data "$T/paper_seed2.h5" --indentations 0 \
  --area indented --out "$T/ua-refit.rmodel" --multiple-misfit 0.07 2>&1 | grep -v warning
tests/review15/mapgrid.sh config/models/cobot-upper_arm.rmodel "$T/ua-refit.rmodel" | tee "$T/grids.txt"
sed -e 's#\.\./#/work/main/config/#g' config/scenes/cobot.yaml > "$T/shipped.yaml"
sed -e 's#\.\./#/work/main/config/#g' -e "s#/work/main/config/models/cobot-upper_arm.rmodel#$T/ua-refit.rmodel#" config/scenes/cobot.yaml > "$T/refit.yaml"
for sc in shipped refit; do
  echo "$sc map, 5 N at Y 119.5 R 23.5 + 0.5 N swept (seed 2): $(nice -n 10 $B/pair_sweep "$T/$sc.yaml" upper_arm_a 119.5 23.5 5 0.5 1.5 2 | tail -1)"
done
a=$(awk 'NR==1{for(i=1;i<=NF;i++) if($i=="dr") print $(i+1)}' "$T/grids.txt")
b=$(awk 'NR==2{for(i=1;i<=NF;i++) if($i=="dr") print $(i+1)}' "$T/grids.txt")
if [ "$a" != "$b" ]; then echo "PROBLEM: the refit indented map's R step $b differs from the shipped map's $a"; exit 1; fi
exit 0
