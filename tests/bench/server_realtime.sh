#!/usr/bin/env bash
# The server's real-time figures (issue 8): facescan-server and N synthetic agents at 30 Hz over loopback DDS in a
# private domain, every process on this machine. Prints each session's summary (fps, integrated / skipped frames,
# capture-to-pose latency p50/p95, per-stage ms, snapshot timings) from the server's --data-dir.
#   usage: tests/bench/server_realtime.sh [SESSIONS (default 1)] [FRAMES (default 300)] [SUBJECT (default scan)]
#   env:   BUILD_DIR (default ./build), FACESCAN_DATA_DIR (../shared/data: the real head scan), SNAPSHOT_HZ (1),
#          TUM_DIR: stream this TUM folder instead of rendering live (`facescan-bench synth --head scan --tum DIR`
#          writes the same sequence): the synthetic agent renders on the CPU the server needs (~75 % of a core
#          per agent at 30 Hz), a TUM agent only decodes PNGs, like a real camera's capture PC.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
sessions=${1:-1}
frames=${2:-300}
subject=${3:-scan}
BUILD_DIR=${BUILD_DIR:-$root/build}
server_bin=$BUILD_DIR/recon_server/service/facescan-server
agent_bin=$BUILD_DIR/capture_agent/core/facescan-agent
for bin in "$server_bin" "$agent_bin"; do
    [ -x "$bin" ] || { echo "server_realtime: $bin missing: cmake --build $BUILD_DIR --target facescan-server facescan-agent" >&2; exit 1; }
done

source "$root/deploy/claim-domain.sh"
claim_private_domain || { echo "server_realtime: no free DDS domain in 100..219" >&2; exit 1; }

work=$(mktemp -d /tmp/facescan-rt.XXXXXX)
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; }
trap cleanup EXIT

"$server_bin" --profile loopback --domain "$domain" --data-dir "$work/data" --snapshot-hz "${SNAPSHOT_HZ:-1}" \
    --max-sessions "$((sessions + 1))" >"$work/server.log" 2>&1 &
server_pid=$!
pids+=("$server_pid")
sleep 1
agent_pids=()
for s in $(seq 1 "$sessions"); do
    source="synthetic:frames=$frames,subject=$subject,seed=$s"
    [ -n "${TUM_DIR:-}" ] && source="tum:$TUM_DIR"
    "$agent_bin" --source "$source" --frames "$frames" --profile loopback --domain "$domain" \
        --session "rt$s" --rate real >"$work/agent$s.log" 2>&1 &
    agent_pids+=("$!")
    pids+=("$!")
done
for p in "${agent_pids[@]}"; do wait "$p" || echo "server_realtime: an agent failed (logs in $work)" >&2; done
for s in $(seq 1 "$sessions"); do
    for _ in $(seq 1 100); do [ -f "$work/data/rt$s/summary.json" ] && break; sleep 0.2; done
done
kill -INT "$server_pid" 2>/dev/null || true
wait "$server_pid" 2>/dev/null || true

echo "server_realtime: $sessions session(s) x $frames frames at 30 Hz from ${TUM_DIR:-live synthetic rendering}, domain $domain, load $(cut -d' ' -f1-3 /proc/loadavg)"
for s in $(seq 1 "$sessions"); do
    f="$work/data/rt$s/summary.json"
    if [ -f "$f" ]; then
        echo "--- rt$s"
        grep -E '"(mode|fps|frames|latency_ms|ms|snapshot)"' "$f"
    else
        echo "--- rt$s: no summary (logs in $work)"
    fi
done
