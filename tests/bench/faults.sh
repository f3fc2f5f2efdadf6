#!/usr/bin/env bash
# The cluster under the two faults that wedged it: three servers on one loopback domain, three agents streaming
# recordings (--rate max: every frame must be kept), and one owner
#   kill   killed with SIGKILL 2 s in (before or just after its first replica), or
#   stop   frozen with SIGSTOP for 8 s and woken with SIGCONT (a paused VM, a stalled disk).
# Each run checks what a failover must keep: no agent gives up, every session finishes once (its summary.json in exactly
# one data dir, every frame integrated or rejected once), no server is left alive with open sessions, no frozen
# server acts on what it missed; and it prints the takeover time (the fault to the agent's "taken over" line).
#   usage: tests/bench/faults.sh [kill|stop|both (default both)] [RUNS (default 5)] [FRAMES (default 300)]
#   env:   BUILD_DIR (default ./build), KEEP=1 keeps the logs of every run (else only of failed runs)
set -uo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
which=${1:-both}
runs=${2:-5}
frames=${3:-300}
BUILD_DIR=${BUILD_DIR:-$root/build}
server_bin=$BUILD_DIR/recon_server/service/facescan-server
agent_bin=$BUILD_DIR/capture_agent/core/facescan-agent
client_bin=$BUILD_DIR/client_cli/facescan
for bin in "$server_bin" "$agent_bin" "$client_bin"; do
    [ -x "$bin" ] || { echo "faults.sh: $bin missing: cmake --build $BUILD_DIR --target facescan-server facescan-agent facescan" >&2; exit 1; }
done
source "$root/deploy/claim-domain.sh"
claim_private_domain || { echo "faults.sh: no free DDS domain" >&2; exit 1; }
dds=(--profile loopback --domain "$domain")
top=$(mktemp -d /tmp/facescan-faults.XXXXXX)
pids=()
cleanup() {
    for p in "${pids[@]}"; do kill -CONT "$p" 2>/dev/null; kill -9 "$p" 2>/dev/null; done
    wait 2>/dev/null
}
trap cleanup EXIT
now_ms() { echo $(( $(date +%s%N) / 1000000 )); }

# One run: MODE RUN. Prints "ok|FAIL takeover_ms reason" to $work/result.
one_run() {
    local mode=$1 r=$2
    work=$top/$mode-$r
    mkdir -p "$work"
    declare -A spid
    for id in s1 s2 s3; do
        "$server_bin" "${dds[@]}" --server-id "$id" --data-dir "$work/data-$id" --preset fast --snapshot-hz 0 \
            --set join_settle_s=1 >"$work/$id.log" 2>&1 &
        spid[$id]=$!
        pids+=("$!")
    done
    sleep 1.5
    local apids=()
    for a in 1 2 3; do
        "$agent_bin" "${dds[@]}" --session "f$r-$a" --rate max --wait-for-server 60 --finish-timeout 150 \
            --source "synthetic:frames=$frames,subject=builtin,seed=$a" >"$work/agent-$a.log" 2>&1 &
        apids+=("$!")
        pids+=("$!")
    done
    # The victim: the owner of the first session, once it owns it.
    local victim=""
    for _ in $(seq 1 300); do
        victim=$(grep -o "server '[^']*' owns session f$r-1" "$work/agent-1.log" 2>/dev/null | head -1 | cut -d"'" -f2)
        [ -n "$victim" ] && break
        sleep 0.1
    done
    [ -n "$victim" ] || { echo "FAIL - no server took f$r-1" >"$work/result"; return; }
    sleep 2
    local fault_ms
    fault_ms=$(now_ms)
    if [ "$mode" = kill ]; then
        kill -9 "${spid[$victim]}"
    else
        kill -STOP "${spid[$victim]}"
    fi
    # Takeover: the first agent line saying another server took a session over after the fault.
    local takeover_ms=-1
    for _ in $(seq 1 400); do
        if grep -q "taken over by" "$work"/agent-*.log 2>/dev/null; then takeover_ms=$(( $(now_ms) - fault_ms )); break; fi
        [ "$mode" = stop ] && [ $(( $(now_ms) - fault_ms )) -ge 8000 ] && kill -CONT "${spid[$victim]}"
        sleep 0.05
    done
    [ "$mode" = stop ] && { while [ $(( $(now_ms) - fault_ms )) -lt 8000 ]; do sleep 0.1; done; kill -CONT "${spid[$victim]}"; }
    local reason="" gave_up=0
    for i in 0 1 2; do
        if ! timeout 240 tail --pid="${apids[$i]}" -f /dev/null; then
            reason+="agent $((i + 1)) still running after 240 s; "
            kill -9 "${apids[$i]}" 2>/dev/null
        fi
        wait "${apids[$i]}" || { gave_up=$((gave_up + 1)); reason+="agent $((i + 1)) failed: $(tail -1 "$work/agent-$((i + 1)).log"); "; }
    done
    sleep 1
    # Every session finished exactly once, with every frame.
    for a in 1 2 3; do
        local found
        found=$(ls "$work"/data-s*/"f$r-$a"/summary.json 2>/dev/null | wc -l)
        [ "$found" -eq 1 ] || reason+="f$r-$a has $found summaries (split); "
        for f in "$work"/data-s*/"f$r-$a"/summary.json; do
            [ -f "$f" ] || continue
            local integ rej
            integ=$(grep -o '"integrated": [0-9]*' "$f" | head -1 | awk '{print $2}')
            rej=$(grep -o '"rejected": [0-9]*' "$f" | head -1 | awk '{print $2}')
            [ $(( integ + rej )) -eq "$frames" ] || reason+="f$r-$a: $integ integrated + $rej rejected of $frames in $f; "
        done
    done
    # No server alive with open sessions, none wedged: every live one answers and lists nothing open.
    for id in s1 s2 s3; do
        kill -0 "${spid[$id]}" 2>/dev/null || { [ "$id" = "$victim" ] && [ "$mode" = kill ] && continue; reason+="$id exited ($(tail -1 "$work/$id.log")); "; continue; }
    done
    local open
    open=$("$client_bin" "${dds[@]}" sessions 2>/dev/null | grep -c -E "scanning|waiting|lost" || true)
    [ "$open" -eq 0 ] || reason+="$open sessions still open; "
    local servers
    servers=$("$client_bin" "${dds[@]}" servers 2>/dev/null | grep -c -E "^ *s[123] " || true)
    local expect=3; [ "$mode" = kill ] && expect=2
    [ "$servers" -ge "$expect" ] || reason+="only $servers servers answer; "
    grep -l "Resource deadlock\|terminate called" "$work"/s*.log >/dev/null 2>&1 && reason+="a server aborted; "
    for id in s1 s2 s3; do kill -CONT "${spid[$id]}" 2>/dev/null; kill -TERM "${spid[$id]}" 2>/dev/null; done
    for id in s1 s2 s3; do timeout 20 tail --pid="${spid[$id]}" -f /dev/null || kill -9 "${spid[$id]}" 2>/dev/null; done
    if [ -z "$reason" ]; then echo "ok $takeover_ms $gave_up" >"$work/result"; else echo "FAIL $takeover_ms $gave_up $reason" >"$work/result"; fi
}

echo "faults.sh: $which, $runs runs, $frames frames, domain $domain, load $(cut -d' ' -f1-3 /proc/loadavg)"
for mode in kill stop; do
    [ "$which" = both ] || [ "$which" = "$mode" ] || continue
    ok=0; times=()
    for r in $(seq 1 "$runs"); do
        one_run "$mode" "$r"
        read -r verdict t rest <"$work/result"
        echo "  $mode run $r: $verdict, takeover $t ms ${rest#* }"
        [ "$verdict" = ok ] && ok=$((ok + 1))
        [ "$t" -ge 0 ] 2>/dev/null && times+=("$t")
        if [ "$verdict" = ok ] && [ "${KEEP:-0}" != 1 ]; then rm -rf "$work"; else echo "    logs: $work"; fi
    done
    p=$(printf '%s\n' "${times[@]}" | sort -n | awk '{a[NR]=$1} END {if (NR) {i=int(NR*0.95+0.999); if (i>NR) i=NR; printf "p50 %d ms, p95 %d ms, max %d ms", a[int((NR+1)/2)], a[i], a[NR]} else print "none"}')
    echo "faults.sh: $mode: $ok of $runs runs clean; takeover $p"
done
