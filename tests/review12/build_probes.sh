#!/bin/bash
# Builds review 12's probe against the release build's static libraries (as tests/review11/build_probes.sh).
set -e; R=${1:-$(cd "$(dirname "$0")/../.." && pwd)/build/release}; S=$(cd "$(dirname "$0")/../.." && pwd)
I="-I$S/patches/decode/include -I$S/patches/twin/include -I$S/patches/core/include -I$R/proto -isystem /usr/include/eigen3"
L="$R/patches/decode/libruffini_decode.a $R/patches/twin/libruffini_twin.a $R/proto/libruffini_proto.a $R/patches/core/libruffini_patch.a -lprotobuf -lyaml-cpp -lspdlog -lfmt"
c++ -O2 -std=c++20 $I $S/tests/review12/probe_cells.cpp $L -o /tmp/r12_probe_cells 2>&1 | grep -v "warning: relocation" || true
