#!/usr/bin/env bash
# The cluster's figures, with the real programs over loopback DDS in a private domain:
#   takeover   two servers, a recording (--rate max); the owner is killed with SIGKILL half way; the time from the
#              kill to the first frame the standby integrates (its log stamps it with the wall clock), and the
#              frames lost (received, integrated + rejected vs sent; the owner's frame digest vs the agent's)
#   live       the same with a live scan at 30 Hz: the frames of the gap (dropped on the new owner) and its
#              takeover time as the status reports it
#   replicas   the owner's replication log lines: bytes per second to the standby and the data dir, and the CPU
#              time per round (capture on the worker, encode and compress, append and sync)
#   spread     three servers and six live sessions started one after another: sessions per server
# On loopback the takeover is bounded by the DDS lease (3 s in the loopback and lan profiles): a killed process
# is noticed when its lease lapses, as a powered-off machine would be.
#   usage: tests/bench/cluster.sh [ROUNDS (default 3)] [FRAMES (default 600: on a quiet machine a shorter
#          recording finishes before the kill half way through it lands)]
#   env:   BUILD_DIR (default ./build), REPLICA_INTERVAL_S (default 1)
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
rounds=${1:-3}
frames=${2:-600}
interval=${REPLICA_INTERVAL_S:-1}
BUILD_DIR=${BUILD_DIR:-$root/build}
server_bin=$BUILD_DIR/recon_server/service/facescan-server
agent_bin=$BUILD_DIR/capture_agent/core/facescan-agent
for bin in "$server_bin" "$agent_bin"; do
    [ -x "$bin" ] || { echo "cluster.sh: $bin missing: cmake --build $BUILD_DIR --target facescan-server facescan-agent" >&2; exit 1; }
done
source "$root/deploy/claim-domain.sh"
claim_private_domain || { echo "cluster.sh: no free DDS domain in 100..219" >&2; exit 1; }
dds=(--profile loopback --domain "$domain")

work=$(mktemp -d /tmp/facescan-cluster-bench.XXXXXX)
pids=()
cleanup() {
    for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null || true; done
    wait 2>/dev/null || true
    rm -rf "$work"
}
trap cleanup EXIT

server() {  # ID LOGNAME: a server in the background; sets $spid
    "$server_bin" "${dds[@]}" --server-id "$1" --data-dir "$work/data-$1" --preset fast --snapshot-hz 0 \
        --replica-interval-s "$interval" --set join_settle_s=1 >"$work/$2.log" 2>&1 &
    spid=$!
    pids+=("$spid")
}
owner_of() {  # SESSION LOG: the first owner the agent was told
    for _ in $(seq 1 300); do
        o=$(grep -o "server '[^']*' owns session $1" "$2" 2>/dev/null | head -1 | cut -d"'" -f2 || true)
        [ -n "$o" ] && { echo "$o"; return; }
        sleep 0.1
    done
}
sent() { grep -o '^frames [0-9]*' "$1" 2>/dev/null | tail -1 | awk '{print $2} END {if (!NR) print 0}'; }
json_num() { grep -o "\"$2\": [0-9.]*" "$1" | head -1 | awk '{print $2}'; }
median() { sort -n | awk '{a[NR]=$1} END {if (NR) print (NR % 2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2); else print "nan"}'; }

# One takeover: MODE (max|30) ROUND. Writes "takeover_ms lost received bit_exact bytes_s cpu_ms_per_round" to
# $work/result (not a subshell: the trap must reach every process).
takeover() {
    local mode=$1 r=$2 session="bench-$1-$2"
    server "a$r" "a$r-$mode"; local pa=$spid
    server "b$r" "b$r-$mode"; local pb=$spid
    sleep 1.5
    local n=$frames
    # Live: 10 s at 30 Hz (the scan must outlast the takeover) of a still head, so tracking continues after the gap.
    [ "$mode" = max ] || n=300
    local source="synthetic:frames=$n,subject=builtin,seed=$r"
    [ "$mode" = max ] || source="$source,period=4000"
    "$agent_bin" "${dds[@]}" --session "$session" --rate "$mode" --source "$source" --wait-for-server 30 \
        >"$work/agent-$mode-$r.log" 2>&1 &
    local agent=$!
    pids+=("$agent")
    local owner
    owner=$(owner_of "$session" "$work/agent-$mode-$r.log")
    local standby=b$r victim=$pa
    [ "$owner" = "b$r" ] && { standby=a$r; victim=$pb; }
    while [ "$(sent "$work/agent-$mode-$r.log")" -lt $((n / 2)) ]; do sleep 0.05; done
    sleep 0.5
    local killed_ns
    killed_ns=$(date +%s%N)
    kill -9 "$victim"
    wait "$victim" 2>/dev/null || true
    wait "$agent" || echo "cluster.sh: agent of $session failed (logs in $work)" >&2
    local slog="$work/$standby-$mode.log" olog="$work/$owner-$mode.log"
    local first_ns
    first_ns=$(grep -o 'realtime_ns [0-9]*' "$slog" | head -1 | awk '{print $2}' || true)
    [ -n "$first_ns" ] || { echo "cluster.sh: $standby integrated no frame after the takeover (logs in $work)" >&2; first_ns=$killed_ns; }
    local summary="$work/data-$standby/$session/summary.json"
    for _ in $(seq 1 50); do [ -f "$summary" ] && break; sleep 0.2; done
    local received integrated rejected dropped
    received=$(json_num "$summary" received)
    integrated=$(json_num "$summary" integrated)
    rejected=$(json_num "$summary" rejected)
    dropped=$(json_num "$summary" dropped)
    local digest_ok=no
    [ "$(grep -o '"frames_digest": "[0-9a-f]*"' "$summary" | grep -o '[0-9a-f]\{16\}')" = \
      "$(grep -o 'frames digest [0-9a-f]*' "$work/agent-$mode-$r.log" | grep -o '[0-9a-f]\{16\}$')" ] && digest_ok=yes
    # The owner's replication while it lived: its last log line before the kill.
    local line bytes_s cpu_ms
    line=$(grep 'replication:' "$olog" | tail -1 || true)
    bytes_s=$(echo "$line" | grep -o '[0-9.]* MB/s to standbys' | awk '{print $1 * 1e6}')
    cpu_ms=$(echo "$line" | grep -o 'capture [0-9.]* ms, encode [0-9.]* ms' | awk '{print $2 + $5}')
    local takeover_ms
    takeover_ms=$(( (first_ns - killed_ns) / 1000000 ))
    local lost=$(( n - integrated - rejected ))
    [ "$mode" = max ] || lost=$dropped
    echo "$takeover_ms $lost $received $digest_ok ${bytes_s:-0} ${cpu_ms:-0}" >"$work/result"
    kill "$pa" "$pb" 2>/dev/null || true
    wait "$pa" "$pb" 2>/dev/null || true
}

echo "cluster.sh: $rounds rounds, $frames frames, replicas every $interval s, domain $domain, load $(cut -d' ' -f1-3 /proc/loadavg)"
rec_takeover=(); rec_lost=(); live_takeover=(); live_lost=(); bytes=(); cpu=()
for r in $(seq 1 "$rounds"); do
    takeover max "$r"
    read -r t l rx ok b c <"$work/result"
    echo "  recording round $r: takeover $t ms, frames lost $l (received $rx of $frames, bit-exact $ok), replicas $(awk "BEGIN {printf \"%.2f\", $b / 1e6}") MB/s, capture+encode $c ms per round"
    rec_takeover+=("$t"); rec_lost+=("$l"); bytes+=("$b"); cpu+=("$c")
    takeover 30 "$r"
    read -r t l rx ok b c <"$work/result"
    echo "  live (30 Hz) round $r: takeover $t ms, frames of the gap $l"
    live_takeover+=("$t"); live_lost+=("$l")
done

# Sessions per server: three servers, six live sessions placed one after another.
spread_pids=()
for id in s1 s2 s3; do server "$id" "spread-$id"; spread_pids+=("$spid"); done
sleep 2
owners=()
for i in $(seq 1 6); do
    "$agent_bin" "${dds[@]}" --session "spread-$i" --rate 10 --source "synthetic:frames=3000,subject=builtin,seed=$i" \
        >"$work/agent-spread-$i.log" 2>&1 &
    pids+=("$!")
    owners+=("$(owner_of "spread-$i" "$work/agent-spread-$i.log")")
done
spread=$(printf '%s\n' "${owners[@]}" | sort | uniq -c | awk '{printf "%s:%s ", $2, $1}')
echo "  spread: 6 sessions on 3 servers -> $spread"

rec_t=$(printf '%s\n' "${rec_takeover[@]}" | median)
live_t=$(printf '%s\n' "${live_takeover[@]}" | median)
rec_l=$(printf '%s\n' "${rec_lost[@]}" | awk '{s += $1} END {print s}')
live_l=$(printf '%s\n' "${live_lost[@]}" | median)
mb=$(printf '%s\n' "${bytes[@]}" | median)
cpu_ms=$(printf '%s\n' "${cpu[@]}" | median)
echo "cluster.sh: takeover median ${rec_t} ms (recording), ${live_t} ms (live); frames lost: ${rec_l} in recordings," \
     "${live_l} per live takeover (median); replicas $(awk "BEGIN {printf \"%.2f\", $mb / 1e6}") MB/s," \
     "owner CPU ${cpu_ms} ms per round ($(awk "BEGIN {printf \"%.1f\", $cpu_ms / ($interval * 10)}") % of a core); load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "{\"takeover_ms\": {\"recording\": $rec_t, \"live\": $live_t}, \"frames_lost\": {\"recording\": $rec_l," \
     "\"live_median\": $live_l}, \"replica_bytes_per_s\": $mb, \"owner_cpu_ms_per_round\": $cpu_ms," \
     "\"replica_interval_s\": $interval, \"spread\": \"${spread% }\"}"
