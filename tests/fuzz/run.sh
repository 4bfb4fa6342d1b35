#!/usr/bin/env bash
# Runs a fuzzer and prints how many inputs it executed and how many crashed.
#   tests/fuzz/run.sh [--target hyperion|core|safety_client] [seconds]            fuzz for that long (default 60)
#   tests/fuzz/run.sh [--target hyperion|core|safety_client] --runs N [--seed S]  a fixed number of runs (what ctest does)
# --target picks the binary (build/release/bin/<target>_fuzz, or $RUFFINI_FUZZ_BIN) and its seed corpus
# (tests/fuzz/corpus for hyperion, tests/fuzz/core_corpus for core, tests/fuzz/corpus_safety_client for
# safety_client; $RUFFINI_FUZZ_CORPUS and $RUFFINI_FUZZ_MAX_LEN override them); default hyperion. The binaries exist only
# when clang++-14 with libFuzzer was found at configure time. Without one the script says SKIPPED and exits 77.
# The seed corpus is copied to a scratch directory first, so it is never modified;
# crashing inputs are kept under $RUFFINI_FUZZ_WORK/run.*/artifacts (a
# passing run's directory is removed).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
base=${RUFFINI_FUZZ_WORK:-$root/build/release/tests/fuzz/work}

seconds=60 runs="" seed="" target=hyperion
while (($#)); do
  case "$1" in
    --target) target=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    [0-9]*) seconds=$1; shift ;;
    *) echo "usage: $0 [--target hyperion|core|safety_client] [seconds] | --runs N [--seed S]" >&2; exit 2 ;;
  esac
done
case "$target" in
  hyperion) corpus=$here/corpus; max_len=4096 ;;
  core) corpus=$here/core_corpus; max_len=8192 ;;
  safety_client) corpus=$here/corpus_safety_client; max_len=512 ;;
  *) echo "unknown target '$target' (hyperion, core or safety_client)" >&2; exit 2 ;;
esac
corpus=${RUFFINI_FUZZ_CORPUS:-$corpus}
max_len=${RUFFINI_FUZZ_MAX_LEN:-$max_len}
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

set +e
"$bin" "${args[@]}" "$work/corpus" >"$work/log.txt" 2>&1
rc=$?
set -e

execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$work/log.txt" | tail -n 1 | grep -o '[0-9]*$' || true)
crashes=$(find "$work/artifacts" -type f | wc -l)
echo "executions: ${execs:-unknown}"
echo "crashes: $crashes"
echo "corpus: $(ls "$work/corpus" | wc -l) inputs"
if ((rc != 0 || crashes != 0)); then
  tail -n 40 "$work/log.txt"
  echo "kept: $work"
  exit 1
fi
rm -rf "$work"
