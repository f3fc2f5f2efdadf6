#!/usr/bin/env bash
# README command 2: installs what is missing, builds facescan, and runs the whole test suite with ctest.
# Tests that need ../shared/data skip with a message when it is absent. Set BUILD_DIR to build elsewhere.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
BUILD_DIR=${BUILD_DIR:-$root/build}
JOBS=${JOBS:-$(nproc)}

# --browser: Debian's chromium for the web viewer's browser test (a test-only dependency).
"$root/deploy/install-deps.sh" --browser
"$root/deploy/check-format.sh"

# The configuration users and the .deb get (Release: -O3 -DNDEBUG, the portable default instruction set), with
# warnings as errors, which only our own builds turn on. Building the test tree itself this way is what makes CI
# compile the Release configuration of every program at no extra cost (tests ran under NDEBUG already:
# RelWithDebInfo defines it too). Prefix /usr: the package test builds the .deb from this tree.
start=$(date +%s)
cmake -S "$root" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DFACESCAN_WERROR=ON -DCMAKE_INSTALL_PREFIX=/usr >/dev/null
cmake --build "$BUILD_DIR" -j "$JOBS"
echo "test.sh: build took $(( $(date +%s) - start )) s"

if [ -x "$root/deploy/fuzz.sh" ]; then
    # Each decoder of network bytes gets a short fuzzing run (longer runs: deploy/fuzz.sh SECONDS).
    start=$(date +%s)
    "$root/deploy/fuzz.sh" "${FUZZ_SECONDS:-3}"
    echo "test.sh: fuzzing took $(( $(date +%s) - start )) s"
fi

# The OpenNI2 tests open our synthetic-Kinect driver as a live camera. OpenNI2 loads drivers only from its system
# folder, so it is installed there for the run and removed afterwards (needs root; otherwise those tests skip).
if [ -x "$root/deploy/openni2-test-driver.sh" ]; then
    if [ "$(id -u)" -eq 0 ] || sudo -n true 2>/dev/null; then
        SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
        $SUDO "$root/deploy/openni2-test-driver.sh" install "$BUILD_DIR"
        trap '$SUDO "$root/deploy/openni2-test-driver.sh" remove "$BUILD_DIR"' EXIT
    else
        echo "test.sh: not root: the OpenNI2 driver tests will skip (run as root to include them)"
    fi
fi

start=$(date +%s)
ctest --test-dir "$BUILD_DIR" --output-on-failure -j "$JOBS" --timeout 600
echo "test.sh: tests took $(( $(date +%s) - start )) s"
