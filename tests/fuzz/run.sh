#!/usr/bin/env bash
# Runs a fuzzer and prints how many inputs it executed and how many crashed.
#   tests/fuzz/run.sh [--target hyperion|core|safety_client] [seconds]            fuzz for that long (default 60)
#   tests/fuzz/run.sh [--target hyperion|core|safety_client] --runs N [--seed S]  a fixed number of runs (what ctest does)
#   ... --report FILE   also writes a campaign report to FILE (date, machine, commit, command, executions, wall
#                       time, crashes, final corpus, libFuzzer's cov/ft; the format of docs/fuzzing.md)
#   ... --keep-corpus DIR  copies the final corpus to DIR (to resume a campaign with RUFFINI_FUZZ_CORPUS=DIR)
#   ... --max-len N     libFuzzer's -max_len (default per target, below; the Core's short-program campaign: 96)
# A campaign (docs/fuzzing.md): nice -n 15 tests/fuzz/run.sh --target core --runs 10000000 --report core.txt
# --target picks the binary (build/release/bin/<target>_fuzz, or $RUFFINI_FUZZ_BIN) and its seed corpus
# (tests/fuzz/corpus for hyperion, tests/fuzz/core_corpus for core, tests/fuzz/corpus_safety_client for
# safety_client; $RUFFINI_FUZZ_CORPUS and $RUFFINI_FUZZ_MAX_LEN override them); default hyperion. The binaries exist only
# when clang++-14 with libFuzzer was found at configure time. Without one the script says SKIPPED and exits 77.
# The seed corpus is copied to a scratch directory first, so it is never modified;
# crashing inputs are kept under $RUFFINI_FUZZ_WORK/run.*/artifacts (a
# passing run's directory is removed).
# The whole script is one compound command, read before it runs: editing the file during a long campaign
# cannot change what the running shell does next.
{
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
base=${RUFFINI_FUZZ_WORK:-$root/build/release/tests/fuzz/work}

seconds=60 runs="" seed="" target=hyperion report="" keep="" max_len_arg=""
while (($#)); do
  case "$1" in
    --target) target=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --report) report=$2; shift 2 ;;
    --keep-corpus) keep=$2; shift 2 ;;
    --max-len) max_len_arg=$2; shift 2 ;;
    [0-9]*) seconds=$1; shift ;;
    *) echo "usage: $0 [--target hyperion|core|safety_client] [seconds] | --runs N [--seed S] [--report FILE] [--keep-corpus DIR] [--max-len N]" >&2; exit 2 ;;
  esac
done
case "$target" in
  hyperion) corpus=$here/corpus; max_len=4096 ;;
  core) corpus=$here/core_corpus; max_len=2048 ;;  # up to about 400 steps; the longest seed is 1474 bytes
  safety_client) corpus=$here/corpus_safety_client; max_len=512 ;;
  *) echo "unknown target '$target' (hyperion, core or safety_client)" >&2; exit 2 ;;
esac
corpus=${RUFFINI_FUZZ_CORPUS:-$corpus}
max_len=${max_len_arg:-${RUFFINI_FUZZ_MAX_LEN:-$max_len}}
bin=${RUFFINI_FUZZ_BIN:-$root/build/release/bin/${target}_fuzz}

if [[ ! -x "$bin" ]]; then
  echo "SKIPPED: $bin not built (needs clang++-14 and libclang-rt-14-dev: deploy/install-deps.sh)"
  exit 77
fi

# A directory of its own per run: ctest and a long run may go at once.
mkdir -p "$base"
work=$(mktemp -d "$base/run.XXXXXX")
mkdir -p "$work/corpus" "$work/artifacts"
cp "$corpus"/* "$work/corpus/"
args=(-print_final_stats=1 -artifact_prefix="$work/artifacts/" -max_len=$max_len)
if [[ -n "$runs" ]]; then args+=(-runs="$runs"); else args+=(-max_total_time="$seconds"); fi
if [[ -n "$seed" ]]; then args+=(-seed="$seed"); fi

seeds=$(ls "$work/corpus" | wc -l)
started=$(date -u +%s)
# The tree as it is when the run starts (the binary's sources, unless it is stale).
commit="$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)$(git -C "$root" diff --quiet HEAD -- tests/fuzz patches services 2>/dev/null || echo ' (with local changes)')"
set +e
"$bin" "${args[@]}" "$work/corpus" >"$work/log.txt" 2>&1
rc=$?
set -e
wall=$(($(date -u +%s) - started))

execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$work/log.txt" | tail -n 1 | grep -o '[0-9]*$' || true)
# libFuzzer's findings: crash-, leak-, timeout- and oom- files. A slow-unit- file is an input that once took more than
# 10 s (on a starved machine, any input can): reported, replayed by whoever reads the report, not a finding.
crashes=$(find "$work/artifacts" -type f ! -name 'slow-unit-*' | wc -l)
slow=$(find "$work/artifacts" -type f -name 'slow-unit-*' | wc -l)
echo "executions: ${execs:-unknown}"
echo "crashes: $crashes"
((slow == 0)) || echo "slow units (more than 10 s once; replay to see): $slow"
echo "corpus: $(ls "$work/corpus" | wc -l) inputs"
if [[ -n "$keep" ]]; then mkdir -p "$keep" && cp "$work/corpus"/* "$keep/"; fi
if [[ -n "$report" ]]; then
  # libFuzzer's last status line (e.g. "#10000000 DONE cov: 812 ft: 3547 corp: 903/154Kb ...").
  status=$(grep -E '^#[0-9]+' "$work/log.txt" | tail -n 1 || true)
  # Paths in the report relative to the repository, so that a reader elsewhere can rerun the command.
  # The run's scratch directory (a mktemp name, gone after a clean run) is written WORK.
  rel() { local t="${1//$work/WORK}"; echo "${t//$root\//}"; }
  {
    echo "target:      $target ($(rel "$bin"))"
    echo "date:        $(date -u -d "@$started" '+%Y-%m-%d %H:%M:%S UTC')"
    echo "machine:     $(uname -srm), $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | sed 's/.*: //'), load average at the end $(cut -d' ' -f1-3 /proc/loadavg)"
    echo "commit:      $commit"
    echo "scheduling:  $(chrt -p $$ 2>/dev/null | head -n 1 | sed 's/.*: //' || echo unknown), nice $(nice)"
    echo "command:     nice $(nice) $(rel "$bin") $(rel "${args[*]}") CORPUS (CORPUS: a copy of $(rel "$corpus"), $seeds inputs)"
    echo "executions:  ${execs:-unknown}"
    echo "wall time:   ${wall} s ($(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$work/log.txt" | grep -o '[0-9]*$' || echo '?') executions/s)"
    echo "crashes:     $crashes (libFuzzer exit status $rc)$( ((slow == 0)) || echo "; slow units: $slow (an input that once took more than 10 s; the artifacts are kept)")"
    echo "corpus:      $(ls "$work/corpus" | wc -l) inputs at the end (from $seeds)"
    echo "coverage:    $(echo "$status" | grep -oE 'cov: [0-9]+ ft: [0-9]+' || echo unknown)"
    echo "last status: $status"
  } >"$report"
fi
if ((rc != 0 || crashes != 0 || slow != 0)); then
  tail -n 40 "$work/log.txt"
  echo "kept: $work"
  exit 1
fi
rm -rf "$work"
exit 0
}
