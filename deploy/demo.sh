#!/usr/bin/env bash
# README command 1: a whole scan end to end on this machine.
#   installs what is missing, builds, starts facescan-server and facescan-agent (the synthetic Kinect filming the
#   real head scan from ../shared/data when present, the built-in head otherwise) on the loopback profile in a
#   private DDS domain, watches the scan live, fetches the results into ./out/ (face.ply, face.drc, preview.png,
#   trajectory.txt), prints their accuracy against the subject's ground truth, and stops everything it started,
#   also on Ctrl-C.
# Knobs (environment): DEMO_FRAMES (default 150), DEMO_RATE (real|max|HZ, default real: a live 30 Hz camera),
#   OUT_DIR (default ./out), BUILD_DIR (default ./build), JOBS, DEMO_NO_INSTALL=1, DEMO_NO_BUILD=1 (use
#   FACESCAN_SERVER/FACESCAN_AGENT/FACESCAN_CLIENT/FACESCAN_ACCURACY or the binaries already in BUILD_DIR),
#   DEMO_VIEW=1 (also `facescan view`: prints the web viewer's URL before the scan and keeps it up after the
#   results until Ctrl-C; DEMO_VIEW_PORT, default 8080, 0 for any free port).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
BUILD_DIR=${BUILD_DIR:-$root/build}
OUT_DIR=${OUT_DIR:-$root/out}
FRAMES=${DEMO_FRAMES:-150}
RATE=${DEMO_RATE:-real}
JOBS=${JOBS:-$(nproc)}
start_s=$(date +%s.%N)

say() { printf '\033[1mdemo:\033[0m %s\n' "$*"; }
[ -t 1 ] || say() { printf 'demo: %s\n' "$*"; }
elapsed() { awk -v a="$1" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }'; }

# --- 1. what the programs need -----------------------------------------------------------------------------------
if [ "${DEMO_NO_INSTALL:-0}" != 1 ]; then
    "$root/deploy/install-deps.sh"
fi

# --- 2. build only the four programs the demo runs ----------------------------------------------------------------
SERVER=${FACESCAN_SERVER:-$BUILD_DIR/recon_server/service/facescan-server}
AGENT=${FACESCAN_AGENT:-$BUILD_DIR/capture_agent/core/facescan-agent}
CLIENT=${FACESCAN_CLIENT:-$BUILD_DIR/client_cli/facescan}
ACCURACY=${FACESCAN_ACCURACY:-$BUILD_DIR/tests/integration/facescan-demo-accuracy}
if [ "${DEMO_NO_BUILD:-0}" != 1 ]; then
    build_s=$(date +%s.%N)
    say "building facescan into $BUILD_DIR (first time: a few minutes) ..."
    # Release, as deploy/test.sh builds the same folder: running one after the other recompiles nothing.
    cmake -S "$root" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release >/dev/null
    cmake --build "$BUILD_DIR" -j "$JOBS" --target facescan-server facescan-agent facescan facescan-demo-accuracy \
        >"$BUILD_DIR/demo-build.log" 2>&1 || {
        tail -n 30 "$BUILD_DIR/demo-build.log"
        say "build failed (full log: $BUILD_DIR/demo-build.log)"
        exit 1
    }
    say "build ready in $(elapsed "$build_s") s"
fi
for bin in "$SERVER" "$AGENT" "$CLIENT" "$ACCURACY"; do
    [ -x "$bin" ] || { say "missing program $bin (build it, or unset DEMO_NO_BUILD)"; exit 1; }
done

# --- 3. a private world: own DDS domain, own session, own temporary folder -----------------------------------------
# A private DDS domain, held until this script and everything it started exit.
source "$root/deploy/claim-domain.sh"
claim_private_domain || { echo "demo: no free DDS domain in 100..219" >&2; exit 1; }
session="demo-$$"
dds=(--profile loopback --domain "$domain")
if [ -n "${FACESCAN_DATA_DIR:-}" ] && [ -d "$FACESCAN_DATA_DIR/leeperrysmith" ] ||
    [ -d "$root/../shared/data/leeperrysmith" ]; then
    subject=scan
    subject_text="the Lee Perry-Smith head scan (../shared/data)"
else
    subject=builtin
    subject_text="the built-in head (../shared/data not found)"
fi
work=$(mktemp -d "${TMPDIR:-/tmp}/facescan-demo.XXXXXX")
mkdir -p "$OUT_DIR"

pids=()
cleanup() {
    local code=$?
    trap - EXIT INT TERM
    for pid in "${pids[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
    for pid in "${pids[@]}"; do
        # A clean stop takes well under a second; a program that hangs is killed.
        for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
        kill -KILL "$pid" 2>/dev/null || true
        wait "$pid" 2>/dev/null || true
    done
    if [ "$code" -ne 0 ]; then
        for log in server agent; do
            [ -s "$work/$log.log" ] && { say "last lines of the $log's log:"; tail -n 15 "$work/$log.log"; }
        done
    fi
    rm -rf "$work"
    exit "$code"
}
trap cleanup EXIT
trap 'echo; say "interrupted: stopping what the demo started"; exit 130' INT TERM

say "domain $domain (loopback), session $session, subject: $subject_text"
"$SERVER" "${dds[@]}" --data-dir "$work/data" >"$work/server.log" 2>&1 &
pids+=($!)
"$AGENT" "${dds[@]}" --source "synthetic:frames=$FRAMES,subject=$subject,distance=0.7,seed=1" \
    --session "$session" --rate "$RATE" --wait-for-server 30 >"$work/agent.log" 2>&1 &
agent_pid=$!
pids+=("$agent_pid")
if [ "${DEMO_VIEW:-0}" = 1 ]; then
    "$CLIENT" view --port "${DEMO_VIEW_PORT:-8080}" "${dds[@]}" >"$work/view.log" 2>&1 &
    view_pid=$!
    pids+=("$view_pid")
    for _ in $(seq 100); do
        url=$(grep -o 'http://[^ ]*' "$work/view.log" 2>/dev/null | head -n 1 || true)
        [ -n "$url" ] || ! kill -0 "$view_pid" 2>/dev/null || { sleep 0.1; continue; }
        break
    done
    [ -n "${url:-}" ] || { cat "$work/view.log"; say "the web viewer did not start"; exit 1; }
    say "watch it in a browser: $url?session=$session"
fi
say "scanning $FRAMES frames ($RATE rate); Ctrl-C stops everything"

# --- 4. watch it live until the server has finished the scan --------------------------------------------------------
scan_s=$(date +%s.%N)
"$CLIENT" watch "$session" "${dds[@]}" --timeout 30
wait "$agent_pid" || { say "the agent failed"; exit 1; }
say "scan took $(elapsed "$scan_s") s"

# --- 5. the results --------------------------------------------------------------------------------------------------
"$CLIENT" mesh "$session" -o "$OUT_DIR/face.ply" --finish "${dds[@]}"
"$CLIENT" mesh "$session" -o "$OUT_DIR/face.drc" "${dds[@]}"
"$CLIENT" preview "$session" -o "$OUT_DIR/preview.png" "${dds[@]}"
"$CLIENT" trajectory "$session" -o "$OUT_DIR/trajectory.txt" "${dds[@]}"
"$ACCURACY" --mesh "$OUT_DIR/face.ply" --subject "$subject" --distance 0.7 --seed 1

say "done in $(elapsed "$start_s") s; results in $OUT_DIR/"

if [ "${DEMO_VIEW:-0}" = 1 ]; then
    say "the web viewer stays up at $url?session=$session (turn the face, download it); Ctrl-C stops it"
    trap 'echo; say "stopping the viewer"; exit 0' INT TERM
    wait "$view_pid" || { say "the web viewer stopped by itself:"; tail -n 5 "$work/view.log"; exit 1; }
fi
