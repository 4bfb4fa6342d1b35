#!/usr/bin/env bash
# Lints and builds the protobuf contracts (proto/) with buf, as proto/buf.yaml configures it.
# buf comes from npm (@bufbuild/buf) into a tools folder that git ignores (default <repo>/.tools/buf;
# RUFFINI_TOOLS_DIR overrides <repo>/.tools); it is installed there on first use.
# Usage: deploy/lint-proto.sh [--against GIT_REF]
#   --against GIT_REF  also runs `buf breaking` (proto/buf.yaml: FILE rules) against proto/ at that commit of
#                      this repository, e.g. `--against main`: a renamed or renumbered field fails it.
# Exit codes: 0 clean; 1 lint, build or breaking findings (printed); 2 usage; 77 could not run (no npm, or the
# install failed): the message says SKIPPED and why (ctest reports the test as skipped, not passed).
set -euo pipefail

against=""
if [[ "${1:-}" == "--against" && -n "${2:-}" ]]; then
  against=$2
elif (($# > 0)); then
  echo "usage: $0 [--against GIT_REF]" >&2
  exit 2
fi

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
tools=${RUFFINI_TOOLS_DIR:-$repo/.tools}/buf
buf=$tools/node_modules/.bin/buf

if [[ ! -x "$buf" ]]; then
  if ! command -v npm >/dev/null 2>&1; then
    echo "lint-proto: SKIPPED: buf is not installed in $tools and npm is not available (Debian: apt-get install npm)"
    exit 77
  fi
  echo "lint-proto: installing @bufbuild/buf into $tools"
  mkdir -p "$tools"
  # Bounded, so an unreachable registry is a skip within about two minutes, not a hung test.
  if ! timeout 150 npm install --no-save --no-audit --no-fund --fetch-retries=1 --fetch-timeout=30000 \
      --prefix "$tools" @bufbuild/buf >"$tools/npm-install.log" 2>&1 \
      || [[ ! -x "$buf" ]]; then
    echo "lint-proto: SKIPPED: npm could not install @bufbuild/buf (log: $tools/npm-install.log)"
    tail -n 5 "$tools/npm-install.log" || true
    exit 77
  fi
fi

cd "$repo/proto"
echo "lint-proto: buf $("$buf" --version)"
status=0
"$buf" lint || status=1
"$buf" build -o /dev/null || status=1
if [[ -n "$against" ]]; then
  # A worktree's .git is a file, so buf is given the common git directory and a commit id (resolved here:
  # HEAD or a relative ref there would be another worktree's).
  gitdir=$(git -C "$repo" rev-parse --path-format=absolute --git-common-dir)
  commit=$(git -C "$repo" rev-parse --verify "$against^{commit}")
  "$buf" breaking --against "$gitdir#ref=$commit,subdir=proto" || status=1
fi
if ((status == 0)); then echo "lint-proto: buf lint, buf build${against:+ and buf breaking against $against} clean"; fi
exit "$status"
