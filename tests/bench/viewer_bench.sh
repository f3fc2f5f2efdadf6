#!/usr/bin/env bash
# The web viewer's benchmark (viewer_bench.mjs): snapshot-to-screen latency, Draco decode ms in the browser, the
# page's first-load transfer size, and the scan's fps with 0 and with N watchers.
#   usage: tests/bench/viewer_bench.sh [FRAMES (default 300)] [ROUNDS (default 2)] [WATCHERS (default 10)]
#   env:   BUILD_DIR (default ./build), CHROMIUM (default /usr/bin/chromium), OUT_DIR (default: a temporary folder)
# Needs deploy/install-deps.sh --browser (chromium, npm packages) and the built programs.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
BUILD_DIR=${BUILD_DIR:-$root/build}
export FACESCAN_SERVER=$BUILD_DIR/recon_server/service/facescan-server
export FACESCAN_AGENT=$BUILD_DIR/capture_agent/core/facescan-agent
export FACESCAN_CLI=$BUILD_DIR/client_cli/facescan
export FACESCAN_WEB_NODE_MODULES=$root/client_cli/web/node_modules
export CHROMIUM=${CHROMIUM:-/usr/bin/chromium}
for bin in "$FACESCAN_SERVER" "$FACESCAN_AGENT" "$FACESCAN_CLI"; do
    [ -x "$bin" ] || { echo "viewer_bench: $bin missing: cmake --build $BUILD_DIR" >&2; exit 1; }
done
[ -x "$CHROMIUM" ] && [ -d "$FACESCAN_WEB_NODE_MODULES/playwright-core" ] ||
    { echo "viewer_bench: needs chromium and the npm packages: deploy/install-deps.sh --browser" >&2; exit 1; }
source "$root/deploy/claim-domain.sh"
claim_private_domain || { echo "viewer_bench: no free DDS domain in 100..219" >&2; exit 1; }
out=${OUT_DIR:-$(mktemp -d /tmp/facescan-viewer-bench.XXXXXX)}
echo "viewer_bench: domain $domain, logs in $out, load $(cut -d' ' -f1-3 /proc/loadavg)"
node --experimental-websocket --no-warnings tests/bench/viewer_bench.mjs "$out" "$domain" "${1:-300}" "${2:-2}" "${3:-10}"
