#!/usr/bin/env bash
# Builds the OpenNI2 driver for the Kinect v1 (libfreenect's OpenNI2-FreenectDriver) from Debian's libfreenect
# source package and installs it where OpenNI2 loads drivers.
#
# Why: Debian's OpenNI2 ships the PS1080 driver (PrimeSense, Asus Xtion) but no Kinect v1 driver, and Debian's
# libfreenect package does not build its OpenNI2 driver. Debian's libOpenNI2 loads drivers only from its system
# folder (<dir of libOpenNI2.so>/OpenNI2/Drivers), so that is where the driver goes.
#
# Usage: sudo deploy/install-kinect-driver.sh [--work-dir DIR] [--uninstall]
# Needs: apt access to Debian's source packages (a deb-src line is added for the running release if none exists).
set -euo pipefail

die() {
    echo "install-kinect-driver: $*" >&2
    exit 1
}

work_dir=""
uninstall=0
while [ $# -gt 0 ]; do
    case "$1" in
        --work-dir) work_dir=${2:?--work-dir needs a folder}; shift 2 ;;
        --uninstall) uninstall=1; shift ;;
        -h|--help) sed -n '2,10p' "$0"; exit 0 ;;
        *) die "unknown argument '$1' (see --help)" ;;
    esac
done

[ "$(id -u)" -eq 0 ] || die "run as root (it installs packages and writes to OpenNI2's system driver folder)"

# OpenNI2's driver folder: beside the libOpenNI2 that the dynamic loader finds.
find_driver_dir() {
    local lib
    lib=$(ldconfig -p 2>/dev/null | awk '/libOpenNI2\.so(\.0)? .*x86-64|libOpenNI2\.so(\.0)? / && !found {print $NF; found = 1}')
    if [ -z "$lib" ]; then
        lib=$(dpkg -L libopenni2-0 2>/dev/null | grep -m1 '/libOpenNI2\.so' || true)
    fi
    [ -n "$lib" ] || die "libOpenNI2 not found: install it with 'apt-get install libopenni2-0 libopenni2-dev'"
    echo "$(dirname "$(readlink -f "$lib")")/OpenNI2/Drivers"
}
driver_dir=$(find_driver_dir)
[ -d "$driver_dir" ] || die "OpenNI2 driver folder '$driver_dir' does not exist (is libopenni2-0 installed?)"

if [ "$uninstall" -eq 1 ]; then
    rm -f "$driver_dir"/libFreenectDriver.so*
    echo "install-kinect-driver: removed libFreenectDriver from $driver_dir"
    exit 0
fi

# 1. Source access: Debian's deb822 sources (bookworm) or a classic sources.list; add deb-src when missing.
has_deb_src() {
    grep -rqsE '^[[:space:]]*deb-src[[:space:]]' /etc/apt/sources.list /etc/apt/sources.list.d/*.list 2>/dev/null && return 0
    grep -rqsE '^Types:.*deb-src' /etc/apt/sources.list.d/*.sources 2>/dev/null && return 0
    return 1
}
if ! has_deb_src; then
    codename=$(. /etc/os-release && echo "${VERSION_CODENAME:-}")
    [ -n "$codename" ] || die "cannot tell the Debian release (VERSION_CODENAME missing in /etc/os-release)"
    echo "install-kinect-driver: adding deb-src for $codename in /etc/apt/sources.list.d/facescan-src.sources"
    cat >/etc/apt/sources.list.d/facescan-src.sources <<EOF
Types: deb-src
URIs: http://deb.debian.org/debian
Suites: $codename
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
fi
apt-get update -qq || die "apt-get update failed (no network or no Debian mirror reachable)"

# 2. Build tools and the driver's own dependencies (the driver needs only libusb, cmake and a C++ compiler;
#    libopenni2-dev is not needed: the driver carries its own copy of the OpenNI2 driver headers).
DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
    dpkg-dev cmake g++ make pkg-config libusb-1.0-0-dev >/dev/null ||
    die "could not install the build tools (dpkg-dev cmake g++ make pkg-config libusb-1.0-0-dev)"

# 3. The source of Debian's libfreenect.
if [ -z "$work_dir" ]; then
    work_dir=$(mktemp -d /tmp/facescan-freenect.XXXXXX)
    trap 'rm -rf "$work_dir"' EXIT
fi
mkdir -p "$work_dir"
cd "$work_dir"
patched=1
if ! apt-get source -qq libfreenect >source.log 2>&1; then
    # Seen on snapshot mirrors: the .dsc and the upstream tarball download but the Debian patch tarball is
    # missing (404). The upstream tarball is what Debian builds from, and apt has already checked it; we check
    # its SHA-256 against the (signed) .dsc again and build from it, without Debian's patches.
    dsc=$(ls libfreenect_*.dsc 2>/dev/null | head -1 || true)
    orig=$(ls libfreenect_*.orig.tar.* 2>/dev/null | head -1 || true)
    if [ -z "$dsc" ] || [ -z "$orig" ]; then
        cat source.log >&2
        die "'apt-get source libfreenect' failed: Debian's source packages are not reachable from here"
    fi
    want=$(awk -v f="$orig" '/^Checksums-Sha256:/{on=1; next} /^[^ ]/{on=0} on && $3==f {print $1}' "$dsc")
    have=$(sha256sum "$orig" | awk '{print $1}')
    [ -n "$want" ] && [ "$want" = "$have" ] || die "$orig does not match the SHA-256 in $dsc; refusing to build it"
    echo "install-kinect-driver: warning: apt-get source failed ($(grep -m1 '^E:' source.log || echo 'see source.log'))"
    echo "install-kinect-driver: building from the verified upstream tarball $orig without Debian's patches"
    tar xf "$orig"
    patched=0
fi
src=$(find "$work_dir" -maxdepth 1 -type d -name 'libfreenect-*' -print -quit)
[ -n "$src" ] || die "apt-get source gave no libfreenect-* folder in $work_dir"
[ -d "$src/OpenNI2-FreenectDriver" ] || die "$src has no OpenNI2-FreenectDriver folder (changed upstream layout?)"
echo "install-kinect-driver: building the OpenNI2 driver from $(basename "$src") (Debian patches applied: $patched)"

# 4. Configure with only what the driver needs and build its target alone. -fpermissive: the 0.5.3 driver
#    declares `static const float X = ...;` members, which GCC rejects since C++11 (our compiler's default is
#    C++17); with -fpermissive GCC accepts them with a warning and the values stay compile-time constants.
cmake -S "$src" -B "$src/build" -DCMAKE_BUILD_TYPE=Release -DBUILD_OPENNI2_DRIVER=ON -DCMAKE_CXX_FLAGS=-fpermissive \
    -DBUILD_EXAMPLES=OFF -DBUILD_FAKENECT=OFF -DBUILD_C_SYNC=OFF -DBUILD_CPP=OFF -DBUILD_PYTHON=OFF \
    -DBUILD_CV=OFF -DBUILD_AS3_SERVER=OFF -DBUILD_REDIST_PACKAGE=ON \
    >cmake.log 2>&1 || { cat cmake.log >&2; die "cmake configure of libfreenect failed"; }
cmake --build "$src/build" --target FreenectDriver -j "$(nproc)" >build.log 2>&1 ||
    { tail -40 build.log >&2; die "building the freenectdriver target failed"; }

built=$(find "$src/build" -name 'libFreenectDriver.so*' -type f -print -quit)
[ -n "$built" ] || die "the build finished but produced no libFreenectDriver.so"

# 5. Install: a real file (the driver links libfreenect statically with BUILD_REDIST_PACKAGE) plus the .so name
#    OpenNI2 scans for (lib*.so).
install -m 0644 "$built" "$driver_dir/libFreenectDriver.so.0"
ln -sf libFreenectDriver.so.0 "$driver_dir/libFreenectDriver.so"
missing=$(ldd "$driver_dir/libFreenectDriver.so.0" | awk '/not found/{print $1}')
[ -z "$missing" ] || die "installed, but these libraries are missing: $missing"
echo "install-kinect-driver: installed $driver_dir/libFreenectDriver.so"
echo "install-kinect-driver: plug in the Kinect (udev rules: apt-get install libfreenect-bin for 'freenect-glview')"
