#!/usr/bin/env bash
# The campaigns of docs/fuzzing.md, one target after another on one core, niced (other work on the machine
# keeps its CPU):
#   tests/fuzz/campaign.sh OUT_DIR [RUNS [CORE_LONG_SECONDS]]
# runs hyperion, safety_client and core for RUNS executions each (default 10000000) with run.sh. The Core's
# RUNS are short programs (--max-len 96: some 10 to 25 steps, about 2 000 a second; a program of hundreds of
# steps costs milliseconds, docs/fuzzing.md); with CORE_LONG_SECONDS, a run of long programs (max_len 2048)
# follows for that long. Writes OUT_DIR/<target>.txt (run.sh --report; core-long.txt), keeps
# OUT_DIR/corpus_<target>, and prints the reports. Exits 1 when any target crashed.
{
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
out=${1:?usage: $0 OUT_DIR [RUNS [CORE_LONG_SECONDS]]}
runs=${2:-10000000}
core_long_seconds=${3:-}
mkdir -p "$out"
status=0
run() {  # name, run.sh arguments...
  local name=$1
  shift
  nice -n 15 "$here/run.sh" "$@" --report "$out/$name.txt" --keep-corpus "$out/corpus_$name" >"$out/$name.log" 2>&1
  local rc=$?
  if ((rc == 77)); then echo "$name: SKIPPED (not built)"; return; fi
  ((rc == 0)) || status=1
  cat "$out/$name.txt"
  echo
}
run hyperion --target hyperion --runs "$runs"
run safety_client --target safety_client --runs "$runs"
run core --target core --runs "$runs" --max-len 96
if [[ -n "$core_long_seconds" ]]; then run core-long --target core "$core_long_seconds"; fi
exit $status
}
