#!/usr/bin/env bash
# The server's real-time figures (issue 8): facescan-server and N synthetic agents at 30 Hz over loopback DDS in a
# private domain, every process on this machine. Prints each session's summary (fps, integrated / skipped frames,
# capture-to-pose latency p50/p95, per-stage ms, snapshot timings) from the server's --data-dir.
#   usage: tests/bench/server_realtime.sh [--preload] [SESSIONS (default 1)] [FRAMES (default 300)] [SUBJECT (scan)]
#   --preload: each agent reads its whole sequence into memory first (facescan-agent --preload), then streams it at
#          30 Hz: an agent then costs only its encoding (~5 % of a core), as on a capture PC of its own. Without it
#          every agent renders (synthetic) or decodes PNGs (TUM_DIR) on the cores the server needs.
#          Every agent holds (--hold-until) until all have read their sequence, so that no agent still reading
#          shares the cores with sessions already streaming. They are then released 0.5 s apart: released at
#          once, the server claimed them together and their frames arrived in step, every session's frame at the
#          same moment of each period, which independent cameras do not do.
#   env:   BUILD_DIR (default ./build), FACESCAN_DATA_DIR (../shared/data: the real head scan), SNAPSHOT_HZ (1),
#          TUM_DIR: stream this TUM folder instead of the synthetic Kinect (`facescan-bench synth --head scan --tum
#          DIR` writes the same sequence); PRELOAD=1 is the same as --preload; SERVER_ARGS: more facescan-server
#          flags (e.g. "--set model_level=1").
#   Ends with a table: per session, frames integrated of those sent, skipped (live mode keeps the newest frame),
#   capture-to-pose latency p50/p95, and the snapshot thread's cost in % of a core.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
preload=${PRELOAD:-0}
if [ "${1:-}" = "--preload" ]; then
    preload=1
    shift
fi
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
    --max-sessions "$((sessions + 1))" ${SERVER_ARGS:-} >"$work/server.log" 2>&1 &
server_pid=$!
pids+=("$server_pid")
sleep 1
agent_pids=()
preload_flag=()
[ "$preload" = 1 ] && preload_flag=(--preload)
for s in $(seq 1 "$sessions"); do
    source="synthetic:frames=$frames,subject=$subject,seed=$s"
    [ -n "${TUM_DIR:-}" ] && source="tum:$TUM_DIR"
    "$agent_bin" --source "$source" --frames "$frames" --profile loopback --domain "$domain" \
        --session "rt$s" --rate real "${preload_flag[@]}" --hold-until "$work/go$s" >"$work/agent$s.log" 2>&1 &
    agent_pids+=("$!")
    pids+=("$!")
done
# Once every agent is ready (or has exited: its log says why), release them 0.5 s apart.
for s in $(seq 1 "$sessions"); do
    while ! grep -q "holding until" "$work/agent$s.log" 2>/dev/null && kill -0 "${agent_pids[$((s - 1))]}" 2>/dev/null; do
        sleep 0.1
    done
done
for s in $(seq 1 "$sessions"); do
    touch "$work/go$s"
    [ "$s" -lt "$sessions" ] && sleep 0.5
done
for p in "${agent_pids[@]}"; do wait "$p" || echo "server_realtime: an agent failed (logs in $work)" >&2; done
for s in $(seq 1 "$sessions"); do
    for _ in $(seq 1 100); do [ -f "$work/data/rt$s/summary.json" ] && break; sleep 0.2; done
done
kill -INT "$server_pid" 2>/dev/null || true
wait "$server_pid" 2>/dev/null || true

what=${TUM_DIR:+tum:$TUM_DIR}
what=${what:-synthetic Kinect}
[ "$preload" = 1 ] && what="$what, preloaded by the agents"
echo "server_realtime: $sessions session(s) x $frames frames at 30 Hz from $what, domain $domain, load $(cut -d' ' -f1-3 /proc/loadavg)"
for s in $(seq 1 "$sessions"); do
    f="$work/data/rt$s/summary.json"
    if [ -f "$f" ]; then
        echo "--- rt$s"
        grep -E '"(mode|fps|frames|latency_ms|ms|snapshot)"' "$f"
    else
        echo "--- rt$s: no summary (logs in $work)"
    fi
done
# One number out of a summary line: field KEY of the line that starts with "SECTION".
field() { grep -E "^  \"$2\"" "$1" | sed -E "s/.*\"$3\": ([0-9.e+-]+).*/\1/"; }
printf '%-8s %12s %9s %9s %9s %12s\n' session integrated skipped p50_ms p95_ms snapshot_cpu
for s in $(seq 1 "$sessions"); do
    f="$work/data/rt$s/summary.json"
    [ -f "$f" ] || continue
    received=$(field "$f" frames received)
    skipped=$(field "$f" frames skipped)
    # The snapshot thread's cost in % of a core, from the LAST snapshot's copy + mesh + encode ms (the summary keeps
    # no mean) times snapshots a second: one snapshot's wall-clock cost, not an average over the session.
    snapshot_cpu=$(awk -v c="$(field "$f" snapshot copy_ms)" -v m="$(field "$f" snapshot mesh_ms)" \
        -v e="$(field "$f" snapshot encode_ms)" -v hz="${SNAPSHOT_HZ:-1}" 'BEGIN { printf "%.1f", (c + m + e) * hz / 10 }')
    printf '%-8s %5s of %-4s %5s %2s %9.1f %9.1f %10s %%\n' "rt$s" "$(field "$f" frames integrated)" "$frames" \
        "$skipped" "($(( received > 0 ? 100 * skipped / received : 0 ))%)" "$(field "$f" latency_ms p50)" \
        "$(field "$f" latency_ms p95)" "$snapshot_cpu"
done
