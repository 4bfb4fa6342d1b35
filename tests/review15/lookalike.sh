#!/bin/bash
# Finding 1: builds lookalike.cpp against build/release's libraries and runs it. Exits 1 while the look-alikes of
# docs/experiments/pair.md section 4 are separable on one noisy frame (d' >= 3), i.e. while "no decoder of these
# 16 shifts can" tell them apart is false in the twin.
set -u
cd "$(dirname "$0")/../.." || exit 2
R=build/release
OUT=${TMPDIR:-/tmp}/review15_lookalike
LIBS=$(awk '/^build bin\/pair_sweep:/{f=1} f && /LINK_LIBRARIES =/{sub(/^ *LINK_LIBRARIES = /,""); print; exit}' $R/build.ninja)
(cd $R && nice -n 10 /usr/bin/c++ -DRUFFINI_HAS_OVER_RANGE=1 -I/work/main/tests/decode -I/work/main/patches/link/include \
  -I/work/main/patches/decode/include -I/work/main/patches/core/include -I/work/main/build/release/proto \
  -I/work/main/patches/ingest/include -I/work/main/patches/twin/include -I/work/main/patches/sim/include \
  -I/work/main/patches/dataset/include -I/work/main/patches/robot/include -isystem /usr/include/eigen3 -O2 -std=c++20 \
  /work/main/tests/review15/lookalike.cpp -o "$OUT" $LIBS) || exit 2
"$OUT"
