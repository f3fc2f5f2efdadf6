#!/usr/bin/env bash
# Installs or removes facescan's synthetic OpenNI2 device (libFacescanSynth.so, URI facescan://synthetic) in
# OpenNI2's system driver folder. Debian's libOpenNI2 loads drivers only from <dir of libOpenNI2.so>/OpenNI2/Drivers,
# so the OpenNI2 tests need it there; deploy/test.sh installs it before ctest and removes it after.
# Tests that need the device skip with a message when it is not installed.
#
# Usage: deploy/openni2-test-driver.sh install|remove|status BUILD_DIR
set -euo pipefail

die() {
    echo "openni2-test-driver: $*" >&2
    exit 1
}

[ $# -eq 2 ] || die "usage: $0 install|remove|status BUILD_DIR"
action=$1
build_dir=$2
name=libFacescanSynth.so
# Debian's libOpenNI2 loads only files named lib*.so.0 from the folder (its packaging patch), so that is the
# installed name.
installed_name=$name.0

# OpenNI2's driver folder, found from where the dynamic loader finds libOpenNI2.
# awk reads to the end (no early exit): with pipefail, an awk that exits first makes ldconfig die of SIGPIPE and
# the whole script exit 141 under set -e (seen once in CI).
lib=$(ldconfig -p 2>/dev/null | awk '$1 ~ /^libOpenNI2\.so/ && !found {print $NF; found = 1}')
if [ -z "$lib" ]; then
    lib=$(dpkg -L libopenni2-0 2>/dev/null | grep -m1 '/libOpenNI2\.so' || true)
fi
[ -n "$lib" ] || die "libOpenNI2 not found (apt-get install libopenni2-0)"
driver_dir="$(dirname "$(readlink -f "$lib")")/OpenNI2/Drivers"
[ -d "$driver_dir" ] || die "OpenNI2 driver folder '$driver_dir' does not exist"
installed="$driver_dir/$installed_name"

case "$action" in
    install)
        built="$build_dir/openni2_driver/$name"
        [ -f "$built" ] || die "$built not found: build the FacescanSynth target first"
        [ -w "$driver_dir" ] || die "cannot write to $driver_dir (run as root)"
        # Copy to a temporary name and rename, so an OpenNI process starting now never loads a half-written file.
        cp "$built" "$installed.tmp.$$"
        chmod 0644 "$installed.tmp.$$"
        mv -f "$installed.tmp.$$" "$installed"
        echo "openni2-test-driver: installed $installed"
        ;;
    remove)
        for f in "$installed" "$driver_dir/$name"; do  # $name: what an earlier version installed
            if [ -e "$f" ]; then
                [ -w "$driver_dir" ] || die "cannot write to $driver_dir (run as root)"
                rm -f "$f"
                echo "openni2-test-driver: removed $f"
            fi
        done
        ;;
    status)
        if [ -e "$installed" ]; then echo "installed: $installed"; else echo "not installed (in $driver_dir)"; fi
        ;;
    *)
        die "unknown action '$action' (install, remove or status)"
        ;;
esac
