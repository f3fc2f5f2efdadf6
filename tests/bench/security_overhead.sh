#!/usr/bin/env bash
# What DDS Security costs: the same live scan with and without it, in one run, alternating the two
# (plain then secure, secure then plain, ...) so that the machine's load falls on both alike. facescan-server and
# one agent streaming a TUM folder at 30 Hz (RATE; like a real camera's capture PC, it only decodes PNGs) over
# loopback DDS in a private domain; the secured runs use a fresh site from deploy/security/site.sh.
# Per run: discovery time (agent joins the domain -> a server matched; secured: authentication handshakes and key
# exchange included), agent and server CPU (seconds, % of one core over the stream, and the server's ms per
# integrated frame, which does not depend on how many frames a loaded machine let it integrate), fps,
# capture-to-pose latency p50/p95 (the server's summary). Then the mean of each mode and secure vs plain.
# Last, the transport alone (facescan-bench transport, same frames at 30 Hz, with and without --security): the
# CPU and latency DDS Security adds to each side without the recon's noise, and its flat-out throughput.
#   usage: tests/bench/security_overhead.sh [ROUNDS (default 3)] [FRAMES (default 300)]
#   env:   BUILD_DIR (default ./build), TUM_DIR (default: rendered once from the real head scan, or the built-in
#          head when ../shared/data is absent, with facescan-bench synth --tum), RATE (frames per second the agent
#          sends, default 30: the camera's rate; a lower one keeps a busy machine's server from falling behind)
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
rounds=${1:-3}
frames=${2:-300}
rate=${RATE:-30}
BUILD_DIR=${BUILD_DIR:-$root/build}
server_bin=$BUILD_DIR/recon_server/service/facescan-server
agent_bin=$BUILD_DIR/capture_agent/core/facescan-agent
bench_bin=$BUILD_DIR/tests/bench/facescan-bench
for bin in "$server_bin" "$agent_bin" "$bench_bin"; do
    [ -x "$bin" ] || { echo "security_overhead: $bin missing: cmake --build $BUILD_DIR" >&2; exit 1; }
done

source "$root/deploy/claim-domain.sh"
claim_private_domain || { echo "security_overhead: no free DDS domain in 100..219" >&2; exit 1; }

work=$(mktemp -d /tmp/facescan-secbench.XXXXXX)
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; }
trap cleanup EXIT

"$root/deploy/security/site.sh" init "$work/site" --name bench >/dev/null
tum=${TUM_DIR:-}
if [ -z "$tum" ]; then
    tum=$work/tum
    head=scan
    [ -d "${FACESCAN_DATA_DIR:-$root/../shared/data}/leeperrysmith" ] || head=builtin
    echo "security_overhead: rendering $frames frames of the $head head into $tum ..."
    "$bench_bin" synth --frames "$frames" --head "$head" --tum "$tum" >/dev/null
fi

ticks=$(getconf CLK_TCK)
cpu_s() { awk -v t="$ticks" '{ print ($14 + $15) / t }' "/proc/$1/stat"; }  # utime + stime of a live process

# run MODE N: one scan; prints "mode discovery_s agent_cpu_s server_cpu_s stream_s fps p50 p95 integrated"
run() {
    local mode=$1 n=$2 sec_server=() sec_agent=() dir=$work/$1$2
    if [ "$mode" = secure ]; then
        sec_server=(--security "$work/site/server")
        sec_agent=(--security "$work/site/agent")
    fi
    mkdir -p "$dir"
    "$server_bin" --profile loopback --domain "$domain" --data-dir "$dir/data" "${sec_server[@]}" \
        >"$dir/server.log" 2>&1 &
    local server_pid=$!
    pids+=("$server_pid")
    sleep 1
    "$agent_bin" --source "tum:$tum" --frames "$frames" --profile loopback --domain "$domain" --session "s$n" \
        --rate "$rate" "${sec_agent[@]}" >"$dir/agent.log" 2>&1 ||
        { echo "security_overhead: the agent failed (logs in $dir)" >&2; return 1; }
    for _ in $(seq 1 100); do [ -f "$dir/data/s$n/summary.json" ] && break; sleep 0.2; done
    local server_cpu
    server_cpu=$(cpu_s "$server_pid")
    kill -INT "$server_pid" 2>/dev/null || true
    wait "$server_pid" 2>/dev/null || true
    local f=$dir/data/s$n/summary.json
    [ -f "$f" ] || { echo "security_overhead: no summary (logs in $dir)" >&2; return 1; }
    local discovery agent_cpu stream fps p50 p95 integrated
    discovery=$(sed -n 's/.*server found \([0-9.]*\) s after joining.*/\1/p' "$dir/agent.log")
    agent_cpu=$(sed -n 's/.*stream ended; cpu \([0-9.]*\) s\b.*/\1/p' "$dir/agent.log")
    stream=$(sed -n 's/.*"duration_s": \([0-9.e+-]*\).*/\1/p' "$f")
    fps=$(sed -n 's/.*"fps": \([0-9.e+-]*\).*/\1/p' "$f")
    p50=$(sed -n 's/.*"latency_ms": {"p50": \([0-9.e+-]*\),.*/\1/p' "$f")
    p95=$(sed -n 's/.*"latency_ms": {[^}]*"p95": \([0-9.e+-]*\)}.*/\1/p' "$f")
    integrated=$(sed -n 's/.*"integrated": \([0-9]*\).*/\1/p' "$f")
    # An empty field would shift every column after it: refuse rather than print misleading figures.
    for v in discovery agent_cpu server_cpu stream fps p50 p95 integrated; do
        [ -n "${!v}" ] || { echo "security_overhead: no $v in the logs of $dir (format changed?)" >&2; return 1; }
    done
    echo "$mode $discovery $agent_cpu $server_cpu $stream $fps $p50 $p95 $integrated"
}

results=$work/results.txt
: >"$results"
order() { if [ $(($1 % 2)) -eq 1 ]; then echo plain secure; else echo secure plain; fi; }  # neither always first
for r in $(seq 1 "$rounds"); do
    for mode in $(order "$r"); do
        line=$(run "$mode" "$r") || exit 1
        echo "$line" >>"$results"
        echo "security_overhead: round $r $line" >&2
    done
done

echo "security_overhead: $rounds rounds x 2 modes x $frames frames at $rate Hz (TUM: depth and colour), domain $domain, load $(cut -d' ' -f1-3 /proc/loadavg)"
awk '
    { n[$1]++; d[$1]+=$2; a[$1]+=$3; s[$1]+=$4; f[$1]+=$6; p[$1]+=$7; q[$1]+=$8; k[$1]+=1000*$4/$9
      printf "%-7s discovery %5.3f s | agent cpu %5.2f s (%4.1f %%) | server cpu %5.2f s (%4.1f %%), %5.1f ms/frame | %4.1f fps | latency p50 %5.1f ms p95 %5.1f ms\n",
             $1, $2, $3, 100 * $3 / $5, $4, 100 * $4 / $5, 1000 * $4 / $9, $6, $7, $8 }
    END {
      for (m in n) {
        D[m] = d[m] / n[m]; A[m] = a[m] / n[m]; S[m] = s[m] / n[m]; F[m] = f[m] / n[m]; P[m] = p[m] / n[m]; Q[m] = q[m] / n[m]
        K[m] = k[m] / n[m]
      }
      print "mean:"
      for (i = 0; i < 2; i++) {
        m = i == 0 ? "plain" : "secure"
        printf "%-7s discovery %5.3f s | agent cpu %5.2f s | server cpu %5.2f s, %5.1f ms/frame | %4.1f fps | latency p50 %5.1f ms p95 %5.1f ms\n",
               m, D[m], A[m], S[m], K[m], F[m], P[m], Q[m]
      }
      printf "secure vs plain: discovery %+.3f s | agent cpu %+.1f %% | server cpu %+.1f %% (per frame %+.1f %%) | fps %+.1f | latency p50 %+.1f ms p95 %+.1f ms\n",
             D["secure"] - D["plain"], 100 * (A["secure"] / A["plain"] - 1), 100 * (S["secure"] / S["plain"] - 1),
             100 * (K["secure"] / K["plain"] - 1), F["secure"] - F["plain"], P["secure"] - P["plain"], Q["secure"] - Q["plain"]
    }' "$results"

# The transport alone: the same stream between two processes, with and without DDS Security, alternating.
echo "security_overhead: the transport alone (facescan-bench transport, 30 Hz for 10 s, then 5 s flat out), $rounds rounds"
transport=$work/transport.txt
: >"$transport"
for r in $(seq 1 "$rounds"); do
    for mode in $(order "$r"); do
        sec=()
        [ "$mode" = secure ] && sec=(--security "$work/site")
        json=$("$bench_bin" transport --seconds 10 --flat-out-seconds 5 --domain "$domain" "${sec[@]}" --json | tail -n 1)
        echo "$mode $json" >>"$transport"
    done
done
awk '
    { m = $1; sub(/^[a-z]+ /, ""); gsub(/[{}",:]/, " ")
      for (i = 1; i < NF; i += 2) v[m, $i] += $(i + 1)
      n[m]++ }
    END {
      for (i = 0; i < 2; i++) {
        m = i == 0 ? "plain" : "secure"
        printf "%-7s writer cpu %4.1f %% | reader cpu %4.1f %% of a core at 30 Hz | latency p50 %5.2f ms p99 %5.2f ms | flat out %6.0f frames/s\n",
               m, 100 * v[m, "writer_cpu"] / n[m], 100 * v[m, "reader_cpu"] / n[m], v[m, "p50_ms"] / n[m],
               v[m, "p99_ms"] / n[m], v[m, "fps"] / n[m]
      }
      printf "secure vs plain: writer cpu %+.1f %% of a core | reader cpu %+.1f %% of a core | latency p50 %+.2f ms p99 %+.2f ms\n",
             100 * (v["secure", "writer_cpu"] - v["plain", "writer_cpu"]) / n["plain"],
             100 * (v["secure", "reader_cpu"] - v["plain", "reader_cpu"]) / n["plain"],
             (v["secure", "p50_ms"] - v["plain", "p50_ms"]) / n["plain"], (v["secure", "p99_ms"] - v["plain", "p99_ms"]) / n["plain"]
    }' "$transport"
rm -rf "$work"
