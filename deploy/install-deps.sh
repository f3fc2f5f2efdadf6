#!/usr/bin/env bash
# Installs exactly what builds, runs and tests facescan on Debian 12 (bookworm), and the web viewer's three.js
# (npm ci in client_cli/web, from its package-lock.json). Idempotent: when everything is present it says so and
# returns in well under a second. Needs root (or sudo) only when a Debian package is missing.
#   --browser   also Debian's chromium, for the web viewer's browser test (deploy/test.sh passes it; users
#               watching scans use their own browser, so a server box does not get one)
#   --open3d    also Debian's python3-open3d: `facescan-bench finish --open3d` runs Open3D's quadric decimation on
#               the same mesh, the reference the finishing stage's triangle budget is held to (benchmarks only)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
with_browser=0
with_open3d=0
for arg in "$@"; do
    case "$arg" in
        --browser) with_browser=1 ;;
        --open3d) with_open3d=1 ;;
        *) echo "install-deps: unknown option $arg (--browser, --open3d)" >&2; exit 2 ;;
    esac
done

PACKAGES=(
    # toolchain
    g++ cmake make pkg-config git
    # the six libraries of the design
    libopencv-dev opencv-data libeigen3-dev cyclonedds-dev cyclonedds-tools libdraco-dev libopenmesh-dev
    libopenni2-dev
    # codecs and nearest-neighbour search
    libzstd-dev libturbojpeg0-dev libjpeg62-turbo-dev libnanoflann-dev
    # recordings of today's depth cameras: Azure Kinect / Orbbec Femto .mkv (Matroska, demuxed by FFmpeg's
    # libavformat); Intel RealSense .bag (ROS 1 bags: ROS's own rosbag storage library and the C++ types of the
    # messages librealsense records, sensor_msgs, geometry_msgs and std_msgs)
    libavformat-dev libavcodec-dev libavutil-dev
    librosbag-storage-dev libsensor-msgs-dev libgeometry-msgs-dev libstd-msgs-dev
    # DDS Security: identity checks (OpenSSL), the site script (openssl); the plugins come with cyclonedds-dev.
    # Also the viewer's HTTPS (linked: Debian's CivetWeb cannot load OpenSSL 3 itself) and its login hashes
    libssl-dev openssl
    # the client: GLB export (glTF 2.0) and the web viewer's HTTP/WebSocket server
    libtinygltf-dev libcivetweb-dev zlib1g-dev
    # tests, benchmarks, fuzzers, formatting
    libgtest-dev libgmock-dev libbenchmark-dev clang libclang-rt-14-dev clang-format
    # the test build's linker (deploy/test.sh): LLVM's lld links the suite's hundred programs several times faster
    # than GNU ld, a minute or more of CI's 2 cores
    lld
    # the viewer's TLS test: a client that trusts only the site's CA (curl; openssl s_client for the WebSocket)
    curl
    # the cross-machine cluster test: network namespaces, a bridge and veths (ip), packet loss (nft numgen)
    iproute2 nftables
    # the .deb and its test: dpkg-shlibdeps (dependencies), systemd-analyze and systemd-sysusers (units, user)
    dpkg-dev systemd
    # the man pages: made from each program's --help at build time and installed by the .deb
    help2man
)

# The viewer's three.js comes from npm (client_cli/web/package-lock.json): node and npm, from Debian unless the
# machine has its own.
command -v npm >/dev/null || PACKAGES+=(nodejs npm)
[ "$with_browser" -eq 0 ] || PACKAGES+=(chromium)
[ "$with_open3d" -eq 0 ] || PACKAGES+=(python3-open3d)

# npm ci in client_cli/web when node_modules does not match the lockfile (a stamp of the lockfile's hash).
install_web() {
    local web="$root/client_cli/web" stamp="$root/client_cli/web/node_modules/.facescan-lock.sha256"
    [ -f "$web/package-lock.json" ] || return 0
    local want
    want=$(sha256sum "$web/package-lock.json" | cut -d' ' -f1)
    if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
        echo "install-deps: the viewer's npm packages match package-lock.json"
        return 0
    fi
    echo "install-deps: npm ci in client_cli/web (three.js for the viewer, playwright-core for its test)"
    # Only `facescan view` needs these: an offline machine still builds and runs the rest (the viewer then says
    # what to run, and its tests skip).
    (cd "$web" && npm ci --no-audit --no-fund --loglevel=error) || {
        echo "install-deps: WARNING: npm ci failed in $web (is the npm registry reachable?); facescan view will" \
            "not start until it succeeds" >&2
        return 0
    }
    echo "$want" >"$stamp"
}

missing=()
for pkg in "${PACKAGES[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$pkg")
    fi
done

if [ ${#missing[@]} -eq 0 ]; then
    echo "install-deps: all ${#PACKAGES[@]} packages present"
    install_web
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
install_web
echo "install-deps: done"
