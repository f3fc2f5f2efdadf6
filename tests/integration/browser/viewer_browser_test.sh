#!/usr/bin/env bash
# ctest entry of the browser test (viewer_browser_test.mjs): checks that node, Debian's chromium and the npm packages
# are there, and that chromium starts, or skips with exit code 77 saying what is missing; claims a private DDS
# domain; runs the test. Env: FACESCAN_SERVER, FACESCAN_AGENT, FACESCAN_CLI, OUT_DIR (default: a temporary folder).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../../.." && pwd)
export FACESCAN_WEB_NODE_MODULES=${FACESCAN_WEB_NODE_MODULES:-$root/client_cli/web/node_modules}
export CHROMIUM=${CHROMIUM:-/usr/bin/chromium}
skip() { echo "viewer_browser_test: SKIPPED: $*"; exit 77; }

command -v node >/dev/null || skip "node is not installed (deploy/install-deps.sh installs it)"
[ -x "$CHROMIUM" ] || skip "no browser at $CHROMIUM (deploy/test.sh installs Debian's chromium: deploy/install-deps.sh --browser)"
[ -d "$FACESCAN_WEB_NODE_MODULES/playwright-core" ] && [ -d "$FACESCAN_WEB_NODE_MODULES/three" ] ||
    skip "npm packages missing in $FACESCAN_WEB_NODE_MODULES (run deploy/install-deps.sh: npm ci in client_cli/web)"
probe=$(mktemp -d)
if ! timeout 60 "$CHROMIUM" --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
    --disable-background-networking --disable-component-update --disable-sync --user-data-dir="$probe/profile" \
    --dump-dom about:blank >"$probe/out" 2>&1; then
    echo "--- chromium's output:"; tail -n 20 "$probe/out"; rm -rf "$probe"
    skip "chromium cannot start here"
fi
rm -rf "$probe"

source "$root/deploy/claim-domain.sh"
claim_private_domain || { echo "viewer_browser_test: no free DDS domain in 100..219" >&2; exit 1; }
out=${OUT_DIR:-$(mktemp -d "${TMPDIR:-/tmp}/facescan-browser.XXXXXX")}
echo "viewer_browser_test: domain $domain, output in $out"
cd "$here"
# The script to run: the scan test by default, or the one named (viewer_login_browser_test.mjs).
node "${1:-viewer_browser_test.mjs}" "$out" "$domain"
