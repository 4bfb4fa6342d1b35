#!/bin/bash
# Review 10's harness (tests/review10/e2e_restart.sh), the operator's name review13. Usage (from the repository
# root): RESETS=... tests/review13/e2e.sh SCENE SCENARIO SECONDS OUTDIR
OPERATOR=review13 exec "$(dirname "$0")/../review10/e2e_restart.sh" "$@"
