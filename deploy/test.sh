#!/usr/bin/env bash
# README command 2: installs what is missing, builds facescan, and runs the whole test suite with ctest.
# Tests that need ../shared/data skip with a message when it is absent. Set BUILD_DIR to build elsewhere.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
BUILD_DIR=${BUILD_DIR:-$root/build}
JOBS=${JOBS:-$(nproc)}

"$root/deploy/install-deps.sh"
"$root/deploy/check-format.sh"

start=$(date +%s)
cmake -S "$root" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build "$BUILD_DIR" -j "$JOBS"
echo "test.sh: build took $(( $(date +%s) - start )) s"

if [ -x "$root/deploy/fuzz.sh" ]; then
    # Each decoder of network bytes gets a short fuzzing run (longer runs: deploy/fuzz.sh SECONDS).
    "$root/deploy/fuzz.sh" "${FUZZ_SECONDS:-10}"
fi

start=$(date +%s)
ctest --test-dir "$BUILD_DIR" --output-on-failure -j "$JOBS" --timeout 600
echo "test.sh: tests took $(( $(date +%s) - start )) s"
