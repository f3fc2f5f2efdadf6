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
# Linked with lld when it is there (install-deps.sh installs it): GNU ld took 2-6 s for each of the suite's hundred
# test programs, lld a fraction of that. Users' builds keep their toolchain's default linker.
linker=()
command -v ld.lld >/dev/null && linker=(-DCMAKE_EXE_LINKER_FLAGS=-fuse-ld=lld -DCMAKE_SHARED_LINKER_FLAGS=-fuse-ld=lld)
start=$(date +%s)
cmake -S "$root" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DFACESCAN_WERROR=ON -DCMAKE_INSTALL_PREFIX=/usr \
    "${linker[@]}" >/dev/null
cmake --build "$BUILD_DIR" -j "$JOBS"
echo "test.sh: build took $(( $(date +%s) - start )) s"

# Each decoder of network bytes gets a short fuzzing run (longer runs: deploy/fuzz.sh SECONDS). It builds its own
# clang + ASan tree and runs beside the tests, at a lower priority: much of the suite waits on processes and the
# network (the cluster, the browser, the package), and CI's 2 cores would otherwise idle through that while the
# fuzzers wait their turn. Its output comes after the tests', and its failure fails the run as before. Its build
# gets every core too: at nice 10 it takes only what the tests leave idle, and with one job it had become the run's
# long pole (CI on 2 cores: fuzzing 531 s beside 499 s of tests).
fuzz_pid=""
fuzz_log="$BUILD_DIR/fuzz.log"
if [ -x "$root/deploy/fuzz.sh" ]; then
    fuzz_start=$(date +%s)
    ( JOBS="$JOBS" nice -n 10 "$root/deploy/fuzz.sh" "${FUZZ_SECONDS:-3}" >"$fuzz_log" 2>&1 ) &
    fuzz_pid=$!
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

# One test more than there are cores: a third of the suite's time is spent waiting on servers, agents, browsers
# and leases, and the cores idled through it at -j JOBS (CI on 2 cores: 439 s for the tests and fuzzers at -j 2,
# 383 s at -j 3). The tests pass on a loaded machine; they have to anyway.
start=$(date +%s)
tests_rc=0
ctest --test-dir "$BUILD_DIR" --output-on-failure -j "$(( JOBS + 1 ))" --timeout 600 || tests_rc=$?
echo "test.sh: tests took $(( $(date +%s) - start )) s"
fuzz_rc=0
if [ -n "$fuzz_pid" ]; then
    wait "$fuzz_pid" || fuzz_rc=$?
    cat "$fuzz_log"
    echo "test.sh: fuzzing (beside the tests) took $(( $(date +%s) - fuzz_start )) s"
fi
[ "$tests_rc" -eq 0 ] || { echo "test.sh: tests failed" >&2; exit "$tests_rc"; }
[ "$fuzz_rc" -eq 0 ] || { echo "test.sh: fuzzing failed (its output above)" >&2; exit "$fuzz_rc"; }
