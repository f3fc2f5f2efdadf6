#!/usr/bin/env bash
# CI check: every C++ source is clang-formatted (repo .clang-format) and no source file exceeds 1000 lines.
set -euo pipefail
cd "$(dirname "$0")/.."
mapfile -t files < <(git ls-files '*.cpp' '*.hpp' '*.h' '*.cc')
[ ${#files[@]} -gt 0 ] || exit 0
status=0
unformatted=$(clang-format --dry-run "${files[@]}" 2>&1 | grep -oE '^[^:]+\.(cpp|hpp|h|cc)' | sort -u || true)
if [ -n "$unformatted" ]; then
    echo "check-format: not clang-formatted (run: clang-format -i FILE):" >&2
    echo "$unformatted" | sed 's/^/  /' >&2
    status=1
fi
long=$(wc -l "${files[@]}" | awk '$2 != "total" && $1 > 1000 {print "  " $2 " (" $1 " lines)"}')
if [ -n "$long" ]; then
    echo "check-format: files over 1000 lines (split them):" >&2
    echo "$long" >&2
    status=1
fi
[ $status -eq 0 ] && echo "check-format: ${#files[@]} files formatted, none over 1000 lines"
exit $status
