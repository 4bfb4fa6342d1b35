#!/usr/bin/env bash
# Runs promtool with the given arguments in the given folder; exit 77 (SKIPPED) when promtool is not installed
# (Debian `prometheus`, deploy/install-deps.sh). Usage: promtool.sh DIR ARGS...
set -euo pipefail
dir=$1; shift
if ! command -v promtool >/dev/null; then
  echo "promtool not found (apt-get install prometheus): skipped"
  exit 77
fi
cd "$dir"
exec promtool "$@"
