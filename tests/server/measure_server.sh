#!/usr/bin/env bash
# Issue-8 figures: facescan-server with real facescan-agent processes over DDS on loopback (private domain).
#   one session at 30 Hz, then two sessions at once at 30 Hz each; prints each session's summary.json
#   (fps, frames integrated/skipped, latency p50/p95, snapshot copy/mesh/encode ms) and, when server_accuracy
#   is built, the accuracy of the final mesh.
# usage: tests/server/measure_server.sh BUILD_DIR [FRAMES] [SNAPSHOT_HZ]
set -euo pipefail
build=${1:?build dir}
frames=${2:-300}
snap_hz=${3:-1}
server=$build/recon_server/service/facescan-server
agent=$build/capture_agent/core/facescan-agent
accuracy=$build/tests/server/server_accuracy
out=$(mktemp -d /tmp/facescan-measure.XXXXXX)
domain=$((100 + ($$ * 7) % 120))

run() {  # run NAME SESSIONS...
    local name=$1; shift
    "$server" --profile loopback --domain "$domain" --data-dir "$out/$name" --server-id measure \
        --snapshot-hz "$snap_hz" --max-sessions 4 > "$out/$name-server.log" 2>&1 &
    local server_pid=$!
    local pids=()
    for s in "$@"; do
        "$agent" --source "synthetic:frames=$frames" --session "$s" --profile loopback --domain "$domain" \
            --wait-for-server 30 > "$out/$name-$s-agent.log" 2>&1 &
        pids+=($!)
    done
    for p in "${pids[@]}"; do wait "$p"; done
    sleep 2
    kill -INT "$server_pid"
    wait "$server_pid"
    for s in "$@"; do
        echo "== $name / $s"
        tr -d '\n' < "$out/$name/$s/summary.json" | sed 's/  */ /g'
        echo
        if [[ -x $accuracy && -f $out/$name/$s/mesh.ply ]]; then "$accuracy" "$out/$name/$s/mesh.ply"; fi
    done
}

run one s1
run two s2a s2b
echo "outputs in $out"
