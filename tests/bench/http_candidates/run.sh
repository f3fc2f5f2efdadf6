#!/usr/bin/env bash
# Measures the HTTP/WebSocket libraries that were candidates for the viewer (the packages must be installed: libcivetweb-dev
# libcpp-httplib-dev libwebsocketpp-dev libboost1.81-dev): compile time and size of each prototype, throughput of a
# 600 kB snapshot fanned out to 10 clients (node 20 clients), and the time to stop with the clients connected.
set -euo pipefail
cd "$(dirname "$0")"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
declare -A LIBS=([civetweb]="-lcivetweb" [httplib]="-lcpp-httplib" [websocketpp]="" [beast]="")
declare -A MODE=([civetweb]=ws [httplib]=sse [websocketpp]=ws [beast]=ws)
port=$((20000 + $$ % 20000))
uptime
for c in civetweb httplib websocketpp beast; do
    start=$(date +%s.%N)
    std=c++20
    if ! g++ -std=$std -O2 -o "$out/$c" "${c}_proto.cpp" ${LIBS[$c]} -pthread 2>"$out/$c.log"; then
        echo "== $c does not compile as C++20 (our standard): $(grep -m1 error: "$out/$c.log"); measured as C++17"
        std=c++17
        start=$(date +%s.%N)
        g++ -std=$std -O2 -o "$out/$c" "${c}_proto.cpp" ${LIBS[$c]} -pthread
    fi
    secs=$(awk -v a="$start" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
    strip -o "$out/$c.stripped" "$out/$c"
    echo "== $c: compile ${secs} s, stripped binary $(stat -c %s "$out/$c.stripped") B (+ shared library: ${LIBS[$c]:-none})"
    port=$((port + 1))
    "$out/$c" "$port" & pid=$!
    sleep 0.5
    node --experimental-websocket --no-warnings clients.mjs "${MODE[$c]}" "$port" || true
    wait "$pid"
done
