#!/usr/bin/env bash
# Across machines: two servers, two agents and a client, each in its own Linux network namespace, joined
# by a bridge that lives in a namespace of its own; the `lan` profile with multicast discovery, as on a real
# network. The agents' namespace drops 2 % of its packets both ways (an nftables `numgen random` rule: this kernel
# has no netem). Checked: the recording arrives complete and bit-exact (the owner's frame digest is the agent's),
# the live scan keeps its rate, the client in a third namespace sees both sessions and fetches a mesh.
# Only addresses of the namespaces made here (10.213.X.0/24 on the private bridge): nothing leaves the machine.
# Everything made is removed on exit, also on failure (trap).
#
#   usage: netns_test.sh   (env: FACESCAN_SERVER, FACESCAN_AGENT, FACESCAN_CLIENT: the programs)
#   exit:  0 pass, 1 fail, 77 skipped (not root, no network namespaces here, ip or nft missing)
set -euo pipefail

SKIP=77
server_bin=${FACESCAN_SERVER:?set FACESCAN_SERVER}
agent_bin=${FACESCAN_AGENT:?set FACESCAN_AGENT}
client_bin=${FACESCAN_CLIENT:?set FACESCAN_CLIENT}

if [ "$(id -u)" -ne 0 ]; then
    echo "SKIP: the namespace test needs root (ip netns, nft); run ctest as root to include it"
    exit $SKIP
fi
for tool in ip nft; do
    command -v $tool >/dev/null || { echo "SKIP: '$tool' is missing: run deploy/install-deps.sh (iproute2, nftables)"; exit $SKIP; }
done

tag="fs$$"                       # namespace and interface names of this run
subnet="10.213.$(( $$ % 250 + 1 ))"  # a /24 of our own on our own bridge
work=$(mktemp -d /tmp/facescan-netns-XXXXXX)
namespaces=()
pids=()

cleanup() {
    local rc=$?
    for pid in "${pids[@]}"; do kill -9 "$pid" 2>/dev/null || true; done
    for pid in "${pids[@]}"; do wait "$pid" 2>/dev/null || true; done
    # Deleting a namespace deletes its veth end (and with it the peer), its bridge and its nft tables.
    for ns in "${namespaces[@]}"; do ip netns del "$ns" 2>/dev/null || true; done
    if [ $rc -ne 0 ] && [ $rc -ne $SKIP ]; then
        echo "netns_test: FAILED; logs:"
        for f in "$work"/*.log; do echo "== $f"; tail -n 25 "$f"; done
    fi
    rm -rf "$work"
    exit $rc
}
trap cleanup EXIT INT TERM

fail() { echo "netns_test: FAIL: $*"; exit 1; }

if ! ip netns add "$tag-hub" 2>/dev/null; then
    echo "SKIP: network namespaces are not allowed here ('ip netns add' failed)"
    exit $SKIP
fi
namespaces+=("$tag-hub")
ip -n "$tag-hub" link add br0 type bridge mcast_snooping 0
ip -n "$tag-hub" link set br0 up

# A namespace on the bridge: NAME HOST_NUMBER.
node() {
    local ns="$tag-$1" host=$2
    ip netns add "$ns"
    namespaces+=("$ns")
    ip link add "v$host$tag" netns "$ns" type veth peer name "b$host$tag" netns "$tag-hub"
    ip -n "$tag-hub" link set "b$host$tag" master br0 up
    ip -n "$ns" link set lo up
    ip -n "$ns" addr add "$subnet.$host/24" dev "v$host$tag"
    ip -n "$ns" link set "v$host$tag" up
}
node srv1 11
node srv2 12
node agents 21
node client 31

# 2 % of the agents' packets are lost, each way, at random; the counters show how many.
ip netns exec "$tag-agents" nft -f - <<EOF
table inet facescan_loss {
    chain in { type filter hook input priority 0; policy accept; numgen random mod 100 < 2 counter drop; }
    chain out { type filter hook output priority 0; policy accept; numgen random mod 100 < 2 counter drop; }
}
EOF

domain=7  # the namespaces are a network of their own: no other test can hear it
dds=(--profile lan --domain $domain)
run() {  # NAMESPACE LOG PROGRAM ARGS...: in the background, its pid recorded
    local ns="$tag-$1" log="$work/$2.log"
    shift 2
    ip netns exec "$ns" "$@" >"$log" 2>&1 &
    pids+=($!)
}

start=$(date +%s)
run srv1 srv1 "$server_bin" "${dds[@]}" --server-id srv1 --data-dir "$work/data-srv1" --preset fast \
    --snapshot-hz 0 --set join_settle_s=1.5
run srv2 srv2 "$server_bin" "${dds[@]}" --server-id srv2 --data-dir "$work/data-srv2" --preset fast \
    --snapshot-hz 0 --set join_settle_s=1.5
frames=60
run agents rec "$agent_bin" "${dds[@]}" --session netns-rec --rate max --wait-for-server 40 \
    --source "synthetic:frames=$frames,subject=builtin,seed=1"
live_rate=15
live_frames=120  # 8 s at 15 Hz
run agents live "$agent_bin" "${dds[@]}" --session netns-live --rate $live_rate --wait-for-server 40 \
    --source "synthetic:frames=$live_frames,subject=builtin,seed=2,period=4000"
rec_pid=${pids[2]}
live_pid=${pids[3]}

wait "$rec_pid" || fail "the recording's agent failed"
wait "$live_pid" || fail "the live agent failed"
echo "netns_test: both agents done after $(( $(date +%s) - start )) s"

# The client, from its own namespace: both sessions, their owners, a mesh.
ip netns exec "$tag-client" "$client_bin" sessions --json "${dds[@]}" --timeout 15 >"$work/sessions.log" 2>&1 ||
    fail "facescan sessions from the client's namespace"
for s in netns-rec netns-live; do
    grep -q "\"session\":\"$s\"" "$work/sessions.log" || fail "the client does not see $s"
done
ip netns exec "$tag-client" "$client_bin" mesh netns-rec -o "$work/rec.ply" "${dds[@]}" --timeout 15 \
    >"$work/mesh.log" 2>&1 || fail "fetching the recording's mesh from the client's namespace"

# The recording: complete and bit-exact on its owner.
rec_owner=$(grep -o "server '[^']*' owns session netns-rec" "$work/rec.log" | head -1 | cut -d"'" -f2)
[ -n "$rec_owner" ] || fail "the recording never got an owner"
summary="$work/data-$rec_owner/netns-rec/summary.json"
[ -f "$summary" ] || fail "no summary of the recording on $rec_owner"
received=$(grep -o '"received": [0-9]*' "$summary" | grep -o '[0-9]*$')
dropped=$(grep -o '"dropped": [0-9]*' "$summary" | grep -o '[0-9]*$')
server_digest=$(grep -o '"frames_digest": "[0-9a-f]*"' "$summary" | grep -o '[0-9a-f]\{16\}')
agent_digest=$(grep -o 'frames digest [0-9a-f]*' "$work/rec.log" | grep -o '[0-9a-f]\{16\}$')
[ "$received" = "$frames" ] || fail "the recording arrived with $received of $frames frames"
[ "$dropped" = 0 ] || fail "$dropped frames of the recording were dropped"
[ "$server_digest" = "$agent_digest" ] || fail "frames not bit-exact: server $server_digest, agent $agent_digest"

# The live scan: delivered at its rate despite the loss.
live_owner=$(grep -o "server '[^']*' owns session netns-live" "$work/live.log" | head -1 | cut -d"'" -f2)
[ -n "$live_owner" ] || fail "the live scan never got an owner"
live_summary="$work/data-$live_owner/netns-live/summary.json"
[ -f "$live_summary" ] || fail "no summary of the live scan on $live_owner"
live_received=$(grep -o '"received": [0-9]*' "$live_summary" | grep -o '[0-9]*$')
live_fps=$(grep -o '"fps": [0-9.]*' "$live_summary" | grep -o '[0-9.]*$')
[ "$live_received" -ge $(( live_frames * 95 / 100 )) ] ||
    fail "the live scan received $live_received of $live_frames frames (less than 95 %)"
drops=$(ip netns exec "$tag-agents" nft list table inet facescan_loss | grep -o 'packets [0-9]*' | awk '{s += $2} END {print s}')
[ "${drops:-0}" -gt 0 ] || fail "the loss rule dropped nothing: the test did not test loss"

echo "netns_test: recording $received/$frames frames on $rec_owner, digest $server_digest = agent's; live scan" \
     "$live_received/$live_frames frames (sent at $live_rate Hz) on $live_owner, ${live_fps} fps processed;" \
     "$drops packets dropped by the 2 % rule; $(( $(date +%s) - start )) s"
