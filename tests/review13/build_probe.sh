#!/bin/bash
# Builds tests/review13/probe.cpp into OUT_DIR/probe (default tests/review13/out; review 14 uses its own), out of
# the main build: its own object, linked to build/release's libraries as two_touch_test is. Rebuilt when the probe
# or the unit tests' rig (tests/decode/hard_press.h) is newer. Run from the repository root: build_probe.sh [OUT_DIR]
set -e; R=build/release; O=${1:-tests/review13/out}; mkdir -p $O
[ $O/probe -nt tests/review13/probe.cpp ] && [ $O/probe -nt tests/decode/hard_press.h ] && exit 0
c++ -DRUFFINI_HAS_OVER_RANGE=1 -I tests/decode -Ipatches/link/include -Ipatches/decode/include -Ipatches/core/include -I$R/proto \
  -Ipatches/ingest/include -Ipatches/twin/include -Ipatches/sim/include -Ipatches/dataset/include -Ipatches/robot/include \
  -isystem /usr/include/eigen3 -O2 -DNDEBUG -std=c++20 -o $O/probe tests/review13/probe.cpp \
  $R/patches/link/libruffini_link.a $R/patches/twin/libruffini_twin.a $R/patches/ingest/libruffini_ingest.a $R/patches/sim/libruffini_sim.a \
  $R/patches/decode/libruffini_decode.a $R/proto/libruffini_proto.a -lprotobuf $R/patches/twin/libruffini_twin.a $R/patches/ingest/libruffini_ingest.a \
  $R/patches/dataset/libruffini_dataset.a -L/usr/lib/x86_64-linux-gnu/hdf5/serial -lhdf5_cpp -lhdf5 -lcrypto -lcurl -lsz -lz -ldl -lm \
  $R/patches/robot/libruffini_robot.a $R/patches/core/libruffini_patch.a /usr/lib/x86_64-linux-gnu/libyaml-cpp.so.0.7.0 \
  /usr/lib/x86_64-linux-gnu/liburdfdom_model.so.3.0 /usr/lib/x86_64-linux-gnu/libconsole_bridge.so.1.0 -ltinyxml \
  /usr/lib/x86_64-linux-gnu/libspdlog.so.1.10.0 /usr/lib/x86_64-linux-gnu/libfmt.so.9.1.0 -lpthread
