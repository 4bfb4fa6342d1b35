#!/bin/bash
# Review 14 (static): stop 33 made the demo reset with the run id of the SafetyState it saw instead of a fresh
# GetStatus call. The aggregator bench harness still pairs the epoch it saw with the run id of a later GetStatus
# (and sends 0 when that call fails). Exit 1 while that pattern is in services/harness/src/aggregator_bench.cpp.
cd "$(dirname "$0")/../.." || exit 2
if grep -n "Status()) r.set_aggregator_run_id" services/harness/src/aggregator_bench.cpp; then
  echo "REPRODUCED: aggregator_bench's Reset(epoch) takes the run id from a fresh GetStatus"; exit 1; fi
echo "not reproduced"; exit 0
