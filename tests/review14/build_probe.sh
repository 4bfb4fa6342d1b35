#!/bin/bash
# Review 14: review 13's probe (tests/review13/probe.cpp, the unit tests' rig) built into tests/review14/out/probe.
# Run from the repository root.
exec tests/review13/build_probe.sh tests/review14/out
