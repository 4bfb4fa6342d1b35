#!/bin/bash
# Print a model file's response-map grid (y0, r0, dy, dr, ny, nr, last node) with protoc.
# usage: mapgrid.sh FILE.rmodel...
cd "$(dirname "$0")/../.." || exit 2
for f in "$@"; do
  size=$(python3 -c "import sys;b=open('$f','rb').read();print(int.from_bytes(b[8:16],'little'))")
  tail -c +17 "$f" | head -c "$size" | protoc -Iproto --decode=ruffini.v1.DecoderModel proto/ruffini/v1/model.proto 2>/dev/null \
    | awk '/response \{|response_map \{/{on=1} on && /^ *(y0_mm|r0_deg|dy_mm|dr_deg|ny|nr|stiffening|multiple_misfit|source):/{print} on && /^  \}/{on=0}' \
    | grep -v g_pm_per_n > /tmp/mapgrid.$$
  awk -v f="$f" '{v[$1]=$2} END{printf "%s: y0 %s dy %s ny %s -> Y end %.4f; r0 %s dr %.10f nr %s -> R end %.4f\n", f, v["y0_mm:"]+0, v["dy_mm:"], v["ny:"], v["y0_mm:"]+(v["ny:"]-1)*v["dy_mm:"], v["r0_deg:"]+0, v["dr_deg:"], v["nr:"], v["r0_deg:"]+(v["nr:"]-1)*v["dr_deg:"]}' /tmp/mapgrid.$$
  rm -f /tmp/mapgrid.$$
done
