#!/bin/bash
# Builds review 11's probes against the release build's static libraries (no cmake; seconds each).
# Usage: tests/review11/build_probes.sh [BUILD_DIR]  -> /tmp/probe_shift, /tmp/probe_strips, /tmp/probe_release
set -e; R=${1:-$(cd "$(dirname "$0")/../.." && pwd)/build/release}; S=$(cd "$(dirname "$0")/../.." && pwd); H=$S/tests/review11
I="-I$S/patches/decode/include -I$S/patches/twin/include -I$S/patches/core/include -I$R/proto -isystem /usr/include/eigen3"
L="$R/patches/decode/libruffini_decode.a $R/patches/twin/libruffini_twin.a $R/proto/libruffini_proto.a $R/patches/core/libruffini_patch.a -lprotobuf -lyaml-cpp -lspdlog -lfmt"
for p in probe_shift probe_strips probe_release; do c++ -O2 -std=c++20 $I $H/$p.cpp $L -o /tmp/$p 2>&1 | grep -v "warning: relocation" || true; done
