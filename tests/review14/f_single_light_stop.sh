#!/bin/bash
# Review 14: a single light touch of 0.5 N (a third of the 1.5 N threshold) at Y 100 R 85 on upper_arm_a (covered
# surface, inside the indented area) stops on every one of 10 noise seeds with cobot-upper_arm.rmodel (stop 33's
# two-touch check), none with forearm.rmodel (the same networks without it). Through the unit tests' rig
# (tests/decode/hard_press.h) via review 13's probe.cpp. About 30 s. Run from the repository root; exit 1 while a
# 0.5 N single touch stops with the shipped file on at least half the seeds.
set -eu; O=tests/review14/out; tests/review14/build_probe.sh
[ -f $O/cobot-forearm.yaml ] || { sed -e "s#\.\./#$PWD/config/#g" -e "s#cobot-upper_arm.rmodel#forearm.rmodel#g" config/scenes/cobot.yaml > $O/cobot-forearm.yaml; }
for s in $(seq 1 10); do echo "upper_arm_a $s 100 85 0.5"; done > $O/single_cases.txt
nice -n 10 timeout 120 $O/probe config/scenes/cobot.yaml < $O/single_cases.txt > $O/single_new.txt
nice -n 10 timeout 120 $O/probe $O/cobot-forearm.yaml < $O/single_cases.txt > $O/single_old.txt
n=$(grep -c "stops yes" $O/single_new.txt || true); o=$(grep -c "stops yes" $O/single_old.txt || true)
echo "0.5 N alone at Y 100 R 85: cobot-upper_arm.rmodel stops $n/10 (largest $(grep -o 'largest [0-9.]*' $O/single_new.txt | sort -k2 -n | tail -1 | cut -d' ' -f2) N); forearm.rmodel $o/10 (largest $(grep -o 'largest [0-9.]*' $O/single_old.txt | sort -k2 -n | tail -1 | cut -d' ' -f2) N)"
[ "$n" -ge 5 ] && { echo "REPRODUCED: a single 0.5 N touch stops with the two-touch check"; exit 1; }
echo "not reproduced"; exit 0
