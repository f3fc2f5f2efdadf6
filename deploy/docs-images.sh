#!/usr/bin/env bash
# Makes the pictures of docs/images from a real run (docs/benchmarks.md says how each was made):
#   viewer-mid-scan.png   `facescan view` in Debian's headless chromium, part-way through a live scan
#   face-three-sides.png  the finished scan in the same viewer, turned left, facing, turned right
# A real facescan-server, facescan-agent (the synthetic Kinect filming the Lee Perry-Smith head scan when
# ../shared/data is beside the checkout, the built-in head otherwise) and `facescan view` on the loopback profile
# in a private DDS domain, as the browser test runs them. docs/images/architecture.svg is drawn by hand.
# usage: deploy/docs-images.sh [OUT_DIR]   (default docs/images; env BUILD_DIR, default ./build, built first)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${BUILD_DIR:-$root/build}
out=$(mkdir -p "${1:-$root/docs/images}" && cd "${1:-$root/docs/images}" && pwd)
chromium=${CHROMIUM:-/usr/bin/chromium}
modules=$root/client_cli/web/node_modules

command -v node >/dev/null || { echo "docs-images: node is missing (deploy/install-deps.sh installs it)" >&2; exit 1; }
[ -x "$chromium" ] || { echo "docs-images: no chromium at $chromium (deploy/install-deps.sh --browser)" >&2; exit 1; }
[ -d "$modules/playwright-core" ] ||
    { echo "docs-images: npm packages missing in $modules (deploy/install-deps.sh runs npm ci)" >&2; exit 1; }
for prog in recon_server/service/facescan-server capture_agent/core/facescan-agent client_cli/facescan; do
    [ -x "$build/$prog" ] || { echo "docs-images: $build/$prog is not built (cmake --build $build)" >&2; exit 1; }
done

source "$root/deploy/claim-domain.sh"
claim_private_domain || { echo "docs-images: no free DDS domain in 100..219" >&2; exit 1; }
work=$(mktemp -d "${TMPDIR:-/tmp}/facescan-docs-images.XXXXXX")
trap 'rm -rf "$work"' EXIT
echo "docs-images: domain $domain, logs in $work, pictures into $out"
FACESCAN_SERVER=$build/recon_server/service/facescan-server FACESCAN_AGENT=$build/capture_agent/core/facescan-agent \
    FACESCAN_CLI=$build/client_cli/facescan FACESCAN_WEB_NODE_MODULES=$modules CHROMIUM=$chromium \
    node "$root/deploy/docs_images.mjs" "$work" "$domain" "$out" || {
    for log in "$work"/*.log; do echo "--- $log"; tail -n 15 "$log"; done
    exit 1
}
ls -l "$out"
