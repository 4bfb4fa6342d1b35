#!/usr/bin/env bash
# Lints and builds the protobuf contracts (proto/) with buf, as proto/buf.yaml configures it.
# buf comes from npm (@bufbuild/buf) into a tools folder that git ignores (default <repo>/.tools/buf;
# RUFFINI_TOOLS_DIR overrides <repo>/.tools); it is installed there on first use.
# Exit codes: 0 lint and build clean; 1 lint or build findings (printed); 77 could not run (no npm, or the
# install failed): the message says SKIPPED and why (ctest reports the test as skipped, not passed).
set -euo pipefail

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
  if ! npm install --no-save --no-audit --no-fund --prefix "$tools" @bufbuild/buf >"$tools/npm-install.log" 2>&1 \
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
if ((status == 0)); then echo "lint-proto: buf lint and buf build clean"; fi
exit "$status"
