#!/usr/bin/env bash
# The README's demo with DEMO_VIEW=1 on a short sequence: it prints the viewer's URL, the viewer answers during and
# after the scan, stays up after the results, and Ctrl-C (SIGINT to the demo) stops everything with exit code 0.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
if [ -z "${FACESCAN_WEB_DIR:-}" ] && [ ! -f "$root/client_cli/web/node_modules/three/build/three.module.js" ]; then
    echo "demo_view_test: SKIPPED: three.js is not installed in client_cli/web (run deploy/install-deps.sh: npm ci)"
    exit 77
fi
log=$(mktemp)
trap 'rm -f "$log"' EXIT
# The demo runs in its own process group so that the signal reaches it as Ctrl-C would reach a terminal's job.
DEMO_VIEW=1 DEMO_VIEW_PORT=0 setsid "$root/deploy/demo.sh" >"$log" 2>&1 &
demo=$!
get() {  # GET a path from the viewer with bash's /dev/tcp: the status line
    local hostport=${url#http://}; hostport=${hostport%%/*}
    exec 3<>"/dev/tcp/${hostport%:*}/${hostport##*:}" || return 1
    printf 'GET %s HTTP/1.1\r\nHost: %s\r\nConnection: close\r\n\r\n' "$1" "$hostport" >&3
    head -n 1 <&3
    exec 3<&-
}
for _ in $(seq 600); do
    grep -q "stays up at" "$log" && break
    kill -0 "$demo" 2>/dev/null || { cat "$log"; echo "demo_view_test: the demo ended before keeping the viewer up"; exit 1; }
    sleep 0.2
done
grep -q "stays up at" "$log" || { cat "$log"; echo "demo_view_test: no 'stays up' line in 120 s"; exit 1; }
url=$(grep -o 'watch it in a browser: http://[^?]*' "$log" | sed 's/.*: //')
status=$(get /api/sessions)
echo "demo_view_test: $url -> $status"
[[ "$status" == *" 200 "* ]] || { cat "$log"; exit 1; }
sleep 1
kill -0 "$demo" || { cat "$log"; echo "demo_view_test: the demo did not keep the viewer up"; exit 1; }
kill -INT -- "-$demo"
code=0
wait "$demo" || code=$?
cat "$log"
[ "$code" -eq 0 ] || { echo "demo_view_test: Ctrl-C ended the demo with $code"; exit 1; }
after=$(get / 2>/dev/null || true)
[[ "$after" != HTTP* ]] || { echo "demo_view_test: the viewer still answers after Ctrl-C: $after"; exit 1; }
echo "demo_view_test: passed"
