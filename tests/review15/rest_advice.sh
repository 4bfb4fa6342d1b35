#!/bin/bash
# Finding 4: follow the decoder's new log advice under a held press. Real processes, about 30 s:
#  1. ruffini-sim plays tests/decoder/data/held.yaml (2 N held at 8-23.5 s at grating 6's centre);
#  2. decoder A (--rest-file) runs 0-11 s and writes the rest; stopped while the press is held;
#  3. decoder B (--rest-file) refuses its captures and logs the new warning with "remove FILE and restart";
#  4. the operator does what the log says: removes FILE, restarts (decoder C, same --rest-file): C trusts its
#     first capture, the held press, and is healthy and out of contact while 2 N is still on the skin.
# Exits 1 when the warning advises removing the rest file and doing so yields a healthy decoder under the press.
set -u
cd "$(dirname "$0")/../.." || exit 2
B=build/release/bin
T=$(mktemp -d /tmp/review15_rest.XXXX)
SCENE=config/scenes/forearm.yaml
REST=$T/rest.txt
metric() { curl -s "http://127.0.0.1:$(awk '/metrics/{print $2}' "$1")/metrics" | awk -v m="$2" 'index($0,m)==1{print $2}'; }
$B/ruffini-sim --scene $SCENE --scenario tests/decoder/data/held.yaml --rate-hz 1000 --command-port 0 --stream-port 0 \
  --ports-file $T/sim.ports > $T/sim.log 2>&1 & SIM=$!
for i in $(seq 50); do [ -s $T/sim.ports ] && break; sleep 0.1; done
SP=$(awk '/stream/{print $2}' $T/sim.ports)
dec() { $B/ruffini-decoder --insecure --scene $SCENE --patch forearm --interrogator 127.0.0.1:$SP --aggregator 127.0.0.1:1 \
  --metrics 127.0.0.1:0 --ports-file $T/$1.ports --rate-hz 1000 --rest-file $REST > $T/$1.log 2>&1 & echo $!; }
A=$(dec a); sleep 11; kill $A; wait $A 2>/dev/null
echo "rest file after A: $(test -f $REST && echo present || echo MISSING)"
Bp=$(dec b); sleep 5
grep -m1 "start-up capture refused" $T/b.log | sed 's/^/B: /'
echo "B healthy: $(metric $T/b.ports 'ruffini_decoder_healthy{')"
advice=$(grep -c "remove $REST and restart" $T/b.log)
kill $Bp; wait $Bp 2>/dev/null
rm -f "$REST"   # what the log tells the operator to do
Cp=$(dec c); sleep 4
ch=$(metric $T/c.ports 'ruffini_decoder_healthy{'); cc=$(metric $T/c.ports 'ruffini_decoder_in_contact{')
echo "C (after removing the file, press still held at $(date +%T)): healthy $ch, in_contact ${cc:-n/a}"
kill $Cp $SIM; wait 2>/dev/null
echo "logs: $T"
if [ "$advice" -ge 1 ] && [ "$ch" = "1" ]; then
  echo "PROBLEM: the log's way out absorbed the held 2 N press into the baseline (healthy, no contact)"; exit 1
fi
exit 0
