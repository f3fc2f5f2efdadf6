#!/usr/bin/env bash
# Installs exactly what builds, runs and tests facescan on Debian 12 (bookworm). Idempotent: when everything
# is present it says so and returns in well under a second. Needs root (or sudo) only when something is missing.
set -euo pipefail

PACKAGES=(
    # toolchain
    g++ cmake make pkg-config git
    # the six libraries of the design
    libopencv-dev opencv-data libeigen3-dev cyclonedds-dev cyclonedds-tools libdraco-dev libopenmesh-dev
    libopenni2-dev
    # codecs and nearest-neighbour search
    libzstd-dev libturbojpeg0-dev libnanoflann-dev
    # tests, benchmarks, fuzzers, formatting
    libgtest-dev libgmock-dev libbenchmark-dev clang libclang-rt-14-dev clang-format
    # the .deb and its test: dpkg-shlibdeps (dependencies), systemd-analyze and systemd-sysusers (units, user)
    dpkg-dev systemd
)

missing=()
for pkg in "${PACKAGES[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$pkg")
    fi
done

if [ ${#missing[@]} -eq 0 ]; then
    echo "install-deps: all ${#PACKAGES[@]} packages present"
    exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    if ! command -v sudo >/dev/null; then
        echo "install-deps: missing packages (${missing[*]}) and not root; run as root or install sudo" >&2
        exit 1
    fi
    SUDO="sudo"
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
# Wait for another apt/dpkg run (a second script installing at the same time) instead of failing on its lock.
APT=(apt-get -o DPkg::Lock::Timeout=600)
$SUDO "${APT[@]}" update -qq
$SUDO "${APT[@]}" install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "install-deps: done"
