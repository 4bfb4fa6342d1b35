#!/usr/bin/env bash
# The campaigns of docs/fuzzing.md, one target after another on one core, niced (other work on the machine
# keeps its CPU):
#   tests/fuzz/campaign.sh OUT_DIR [RUNS [CORE_SECONDS]]
# runs hyperion, safety_client and core for RUNS executions each (default 10000000) with run.sh, the Core for
# at most CORE_SECONDS when given (a Core run costs milliseconds: docs/fuzzing.md). Writes OUT_DIR/<target>.txt
# (run.sh --report), keeps OUT_DIR/corpus_<target>, and prints the reports. Exits 1 when any target crashed.
{
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
out=${1:?usage: $0 OUT_DIR [RUNS [CORE_SECONDS]]}
runs=${2:-10000000}
core_seconds=${3:-}
mkdir -p "$out"
status=0
for target in hyperion safety_client core; do
  budget=(--runs "$runs")
  if [[ $target == core && -n "$core_seconds" ]]; then budget=("$core_seconds"); fi
  nice -n 15 "$here/run.sh" --target "$target" "${budget[@]}" --report "$out/$target.txt" \
    --keep-corpus "$out/corpus_$target" >"$out/$target.log" 2>&1
  rc=$?
  if ((rc == 77)); then echo "$target: SKIPPED (not built)"; continue; fi
  ((rc == 0)) || status=1
  cat "$out/$target.txt"
  echo
done
exit $status
}
