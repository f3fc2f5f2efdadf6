#!/usr/bin/env bash
# ctest entry of the documentation check (docs_check.mjs): skips with exit code 77 when node is missing.
# usage: docs_check.sh SOURCE_DIR PROGRAM=PATH...
set -euo pipefail
command -v node >/dev/null || { echo "docs_check: SKIPPED: node is not installed (deploy/install-deps.sh installs it)"; exit 77; }
exec node "$(dirname "$0")/docs_check.mjs" "$@"
