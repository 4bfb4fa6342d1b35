#!/bin/bash
# Review 12, finding 3: GuaranteeRegion's exact band test (HoldsCoveredSurface) costs O(B^3) per cell for B bands whose
# edges fall inside one cell: 2 x 1600 thin bands tiling one 5 mm row take seconds, 2 x 3200 about a minute, at every
# check-scene and aggregator load. Also runs the cell-rule edge cases that held (bands on grid lines +-1e-9, grid
# values at 0 and the extent, reversed/NaN bands). Exit 1 while one check takes more than 2 s.
H=$(cd "$(dirname "$0")" && pwd); "$H/build_probes.sh" >/dev/null || exit 2
out=$(timeout 300 /tmp/r12_probe_cells 1600); rc=$?; echo "$out"
[ $rc = 0 ] || { echo "an edge case went wrong"; exit 1; }
t=$(echo "$out" | tail -1 | grep -o '[0-9.]* s' | cut -d' ' -f1)
awk -v t="$t" 'BEGIN { exit !(t > 2.0) }' && { echo "REPRODUCES: ${t} s for one region check"; exit 1; }
echo "fixed"; exit 0
