#!/usr/bin/env bash
# A server's memory over many scans, with the real programs over loopback DDS in a private domain: one server, and
# SCANS recordings of FRAMES synthetic frames one after another (each agent streams at --rate max, ends its stream
# and waits for the server to finish the scan). After each scan the server's resident memory (VmRSS of
# /proc/PID/status) is read once the scan has left it (its files are written, then its memory goes within a
# second); the figures after scans 1, 10, 20, ... and the last are printed, with the last against the tenth.
# Target: the last within 10 % of the tenth.
#   usage: tests/bench/memory.sh [SCANS (default 100)] [FRAMES (default 90)]
#   env:   BUILD_DIR (default ./build: another build's binaries give its figures), PRESET (default face),
#          SERVER_ARGS (more server flags, e.g. "--keep-finished 4"), AT_ONCE (default 1: each of the SCANS rounds
#          runs this many recordings at once, each in threads of its own on the server), IDLE_S (default 0: after
#          the last round, the server stays idle this long, then its resident memory and its last memory line)
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
scans=${1:-100}
frames=${2:-90}
preset=${PRESET:-face}
at_once=${AT_ONCE:-1}
BUILD_DIR=${BUILD_DIR:-$root/build}
server_bin=$BUILD_DIR/recon_server/service/facescan-server
agent_bin=$BUILD_DIR/capture_agent/core/facescan-agent
for bin in "$server_bin" "$agent_bin"; do
    [ -x "$bin" ] || { echo "memory.sh: $bin missing: cmake --build $BUILD_DIR --target facescan-server facescan-agent" >&2; exit 1; }
done
source "$root/deploy/claim-domain.sh"
claim_private_domain || { echo "memory.sh: no free DDS domain in 100..219" >&2; exit 1; }
dds=(--profile loopback --domain "$domain")

work=$(mktemp -d /tmp/facescan-memory-bench.XXXXXX)
spid=""
cleanup() {
    [ -n "$spid" ] && kill -9 "$spid" 2>/dev/null || true
    wait 2>/dev/null || true
    rm -rf "$work"
}
trap cleanup EXIT

# shellcheck disable=SC2086  # SERVER_ARGS is a list of flags
"$server_bin" "${dds[@]}" --server-id mem --data-dir "$work/data" --preset "$preset" --set join_settle_s=1 \
    ${SERVER_ARGS:-} >"$work/server.log" 2>&1 &
spid=$!
sleep 1.5
rss_mb() { awk '/^VmRSS:/ {printf "%.1f", $2 / 1024}' "/proc/$spid/status"; }
echo "memory.sh: $scans rounds of $at_once scan(s) of $frames frames (--preset $preset), $BUILD_DIR, domain $domain, load $(cut -d' ' -f1-3 /proc/loadavg)"
rss_10=""
start_s=$(date +%s)
for i in $(seq 1 "$scans"); do
    pids=()
    for j in $(seq 1 "$at_once"); do
        session="mem-$i" seed=$i
        [ "$at_once" -gt 1 ] && session="mem-$i-$j" seed=$i$j
        "$agent_bin" "${dds[@]}" --session "$session" --rate max --wait-for-server 30 \
            --source "synthetic:frames=$frames,subject=builtin,seed=$seed" >"$work/agent-$j.log" 2>&1 &
        pids+=($!)
    done
    for j in $(seq 1 "$at_once"); do
        if ! wait "${pids[$((j - 1))]}"; then
            echo "memory.sh: an agent of scan $i failed:" >&2
            tail -5 "$work/agent-$j.log" >&2
            # The work folder goes on exit: the server's side of it is printed here.
            echo "memory.sh: the server's log ends:" >&2
            grep -v "replication:" "$work/server.log" | tail -15 >&2
            exit 1
        fi
    done
    for j in $(seq 1 "$at_once"); do
        session="mem-$i"
        [ "$at_once" -gt 1 ] && session="mem-$i-$j"
        for _ in $(seq 1 100); do [ -f "$work/data/$session/summary.json" ] && break; sleep 0.1; done
        [ -f "$work/data/$session/summary.json" ] || { echo "memory.sh: $session was not written (log: $work/server.log)" >&2; exit 1; }
    done
    sleep 2  # the server retires a finished scan within a few status ticks (2 Hz)
    rss=$(rss_mb)
    [ "$i" -eq 10 ] && rss_10=$rss
    if [ "$i" -eq 1 ] || [ $((i % 10)) -eq 0 ] || [ "$i" -eq "$scans" ]; then
        echo "  after scan $i: resident $rss MB ($(($(date +%s) - start_s)) s)"
    fi
done
if [ "${IDLE_S:-0}" -gt 0 ]; then
    sleep "$IDLE_S"
    echo "  idle $IDLE_S s after the last scan: resident $(rss_mb) MB"
    grep "memory:" "$work/server.log" | tail -1 | sed 's/^/  /'
fi
if [ -n "$rss_10" ]; then
    awk -v a="$rss_10" -v b="$rss" -v n="$scans" \
        'BEGIN {printf "memory.sh: after scan %d %.1f MB against %.1f MB after scan 10: %+.1f %% (target within 10 %%)\n", n, b, a, (b / a - 1) * 100}'
fi
