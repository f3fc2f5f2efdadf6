#!/usr/bin/env bash
# The .deb as a Debian user gets it, built from this (already built) tree with CPack:
#   1. the package: dpkg-deb --info (dependencies from dpkg-shlibdeps, conffiles, maintainer scripts) and
#      --contents (every program, profile, unit and config in its FHS place; nothing from the build tree);
#   2. systemd-analyze verify on the installed units;
#   3. installed into a scratch root (dpkg --root with chrootless maintainer scripts when root, else dpkg-deb -x),
#      so that postinst's system user lands in the scratch root's /etc/passwd;
#   4. run from the scratch root: facescan-server --help, the unit's own ExecStart line with --check (the shipped
#      server.conf parses and the lan profile is found in the INSTALLED share/facescan), and a loopback scan of the
#      installed server, agent and client (the server's face detection uses the Haar cascade from opencv-data);
#   5. SIGTERM to the installed server in the middle of a live scan: it exits 0 and the open scan is on disk;
#   6. what other features install: facescan view serves its page from the installed share/facescan/web, and
#      facescan-site (the DDS Security site script) makes a site.
# usage: package_test.sh BUILD_DIR        exit 0 pass, 1 fail, 77 skipped (with the reason)
set -euo pipefail
trap 'echo "FAIL: line $LINENO exited $? (set -e)" >&2' ERR

build=$(cd "${1:?usage: package_test.sh BUILD_DIR}" && pwd)
here=$(cd "$(dirname "$0")" && pwd)
root_dir=$(cd "$here/../.." && pwd)

skip() { echo "SKIP: $*"; exit 77; }
fail() { echo "FAIL: $*" >&2; exit 1; }
step() { printf '\n== %s\n' "$*"; }

prefix=$(sed -n 's/^CMAKE_INSTALL_PREFIX:PATH=//p' "$build/CMakeCache.txt")
[ "$prefix" = /usr ] || skip "this tree installs to '$prefix'; a .deb needs -DCMAKE_INSTALL_PREFIX=/usr (deploy/test.sh configures it)"
for tool in cpack dpkg-deb dpkg-shlibdeps systemd-analyze; do
    command -v "$tool" >/dev/null || skip "$tool not found (./deploy/install-deps.sh installs it)"
done
for prog in recon_server/service/facescan-server capture_agent/core/facescan-agent client_cli/facescan; do
    [ -x "$build/$prog" ] || skip "$build/$prog is not built"
done

work=$(mktemp -d "${TMPDIR:-/tmp}/facescan-package.XXXXXX")
pids=()
cleanup() {
    for pid in "${pids[@]}"; do kill -KILL "$pid" 2>/dev/null || true; done
    rm -rf "$work"
}
trap cleanup EXIT

# --- 1. the package ------------------------------------------------------------------------------------------------
step "cpack (DEB) from $build"
start=$(date +%s)
(cd "$work" && cpack -G DEB --config "$build/CPackConfig.cmake" -B "$work/pkg" >"$work/cpack.log" 2>&1) || {
    cat "$work/cpack.log"
    fail "cpack failed"
}
deb=$(ls "$work"/pkg/facescan_*.deb 2>/dev/null | head -n 1)
[ -f "$deb" ] || fail "cpack made no facescan_*.deb: $(ls "$work/pkg")"
echo "built $(basename "$deb") ($(du -k "$deb" | cut -f1) kB) in $(($(date +%s) - start)) s"

dpkg-deb --info "$deb" >"$work/info.txt"
cat "$work/info.txt"
depends=$(dpkg-deb --field "$deb" Depends)
# From dpkg-shlibdeps: the shared libraries the programs link (versioned), plus the two added by hand.
for dep in libc6 libstdc++6 libddsc0 libopencv-core libopencv-objdetect libdraco libopenmesh libopenni2-0 libzstd1 \
    libturbojpeg0 libjpeg62-turbo libssl3 libcivetweb opencv-data adduser openssl; do
    grep -q "$dep" <<<"$depends" || fail "Depends lacks $dep: $depends"
done
grep -qE 'libddsc0[^,]*\(>= ' <<<"$depends" || fail "Depends has no versions (dpkg-shlibdeps did not run?): $depends"
mkdir -p "$work/control"
dpkg-deb --control "$deb" "$work/control"
for f in postinst prerm postrm conffiles; do [ -f "$work/control/$f" ] || fail "no $f in the package"; done
diff <(sort "$work/control/conffiles") <(printf '/etc/facescan/agent.conf\n/etc/facescan/server.conf\n') ||
    fail "conffiles differ from the two configuration files"
for f in postinst prerm postrm; do sh -n "$work/control/$f" || fail "$f is not valid sh"; done

dpkg-deb --contents "$deb" | awk '{print $6}' | sed 's|^\./|/|' >"$work/contents.txt"
expected=(
    /usr/bin/facescan-server /usr/bin/facescan-agent /usr/bin/facescan
    /usr/share/facescan/profiles/lan.xml /usr/share/facescan/profiles/loopback.xml
    /etc/facescan/server.conf /etc/facescan/agent.conf
    /lib/systemd/system/facescan-server.service /lib/systemd/system/facescan-agent@.service
    /usr/lib/sysusers.d/facescan.conf /usr/lib/sysctl.d/60-facescan.conf /usr/share/doc/facescan/README.md
    /usr/share/doc/facescan/docs/deployment.md
    /usr/bin/facescan-site /usr/share/facescan/web/index.html /usr/share/facescan/web/viewer.js
)
# three.js comes from npm (deploy/install-deps.sh runs npm ci); without it the viewer is not installed whole.
web_vendor=0
if [ -f "$root_dir/client_cli/web/node_modules/three/build/three.module.js" ]; then
    web_vendor=1
    expected+=(/usr/share/facescan/web/node_modules/three/build/three.module.js)
fi
[ -x "$build/tests/bench/facescan-bench" ] && expected+=(/usr/bin/facescan-bench)
# Man pages: made by help2man at build time, when it is installed (deploy/install-deps.sh installs it).
man_pages=0
if [ -f "$build/man/facescan-server.1.gz" ]; then
    man_pages=1
    for page in facescan-server facescan-agent facescan facescan-site; do
        expected+=("/usr/share/man/man1/$page.1.gz")
    done
    [ -x "$build/tests/bench/facescan-bench" ] && expected+=(/usr/share/man/man1/facescan-bench.1.gz)
fi
for path in "${expected[@]}"; do
    grep -qx "$path" "$work/contents.txt" || fail "$path is not in the package"
done
if grep -E '^/usr/local|^/home|^/tmp|^/work' "$work/contents.txt"; then fail "the package installs outside FHS places"; fi
if grep -q "$build" <(dpkg-deb --fsys-tarfile "$deb" | tar -xO --wildcards './lib/systemd/*' './etc/*'); then
    fail "a unit or config file names the build tree"
fi
echo "contents: ${#expected[@]} expected paths present, $(wc -l <"$work/contents.txt") entries"

# --- 2. + 3. a scratch root --------------------------------------------------------------------------------------
step "install into a scratch root"
R="$work/root"
mkdir -p "$R"
if [ "$(id -u)" -eq 0 ]; then
    # dpkg's own database in the scratch root; maintainer scripts run outside a chroot with DPKG_ROOT=$R, so that
    # postinst's systemd-sysusers creates the user in $R/etc/passwd and nothing on this machine changes. The
    # package's dependencies are installed on this machine, not in the empty root: --force-depends.
    mkdir -p "$R/var/lib/dpkg/info" "$R/var/lib/dpkg/updates" "$R/etc"
    touch "$R/var/lib/dpkg/status"
    dpkg --root="$R" --log=/dev/null --force-script-chrootless --force-depends --force-not-root \
        --path-include='*' -i "$deb" >"$work/dpkg.log" 2>&1 || { cat "$work/dpkg.log"; fail "dpkg --root -i failed"; }
    grep -v '^dpkg: warning' "$work/dpkg.log" || true
    dpkg --root="$R" -s facescan | grep -q '^Status: install ok installed' || fail "dpkg does not list facescan as installed"
    if command -v systemd-sysusers >/dev/null; then
        grep -q '^facescan:' "$R/etc/passwd" || fail "postinst did not create the system user in the scratch root"
        grep -q '^video:.*facescan' "$R/etc/group" || fail "postinst did not add facescan to group video"
        echo "postinst created: $(grep '^facescan:' "$R/etc/passwd")"
    fi
else
    echo "not root: unpacking with dpkg-deb -x (maintainer scripts not run; run as root to include them)"
    dpkg-deb -x "$deb" "$R"
fi

step "systemd-analyze verify"
# --root resolves ExecStart= and EnvironmentFile= in the scratch root; the targets the units hang off
# (multi-user.target, network-online.target, sysinit.target) come from this machine's systemd, as on a real system.
for dir in /lib/systemd/system /usr/lib/systemd/system; do
    [ -d "$dir" ] && cp -rn "$dir/." "$R/lib/systemd/system/" 2>/dev/null || true
done
verify_out=$(systemd-analyze verify --root="$R" --man=no "$R/lib/systemd/system/facescan-server.service" \
    "$R/lib/systemd/system/facescan-agent@.service" 2>&1) || {
    echo "$verify_out"
    fail "systemd-analyze verify failed"
}
# verify reports unknown keys and bad values as warnings without failing: none are allowed.
if grep -vE 'Cannot add dependency job|network-online.target|^$' <<<"$verify_out" | grep .; then
    fail "systemd-analyze verify reported problems"
fi
echo "units verified"

# --- 4. the installed programs --------------------------------------------------------------------------------------
step "programs from the scratch root"
export FACESCAN_SHARE_DIR="" FACESCAN_PROFILE_DIR=""
"$R/usr/bin/facescan-server" --help >"$work/help.txt" || fail "installed facescan-server --help failed"
grep -q -- '--config FILE' "$work/help.txt" || fail "--help does not describe --config"
for prog in facescan-agent facescan; do "$R/usr/bin/$prog" --help >/dev/null || fail "installed $prog --help failed"; done
# --version: the version and the commit the package was built from, the same line from every program.
commit=$(git -C "$root_dir" rev-parse --short=12 HEAD 2>/dev/null || echo unknown)
for prog in facescan-server facescan-agent facescan facescan-site; do
    line=$("$R/usr/bin/$prog" --version) || fail "installed $prog --version failed"
    grep -qE "^$prog [0-9]+\.[0-9]+\.[0-9]+ \(commit ([0-9a-f]{12}|unknown)\)$" <<<"$line" ||
        fail "$prog --version printed '$line', not 'PROGRAM VERSION (commit HASH)'"
done
echo "--version: $("$R/usr/bin/facescan-server" --version) (checkout at $commit)"
if [ "$man_pages" -eq 1 ] && command -v man >/dev/null; then
    # What `man facescan-server` shows once the package is installed: the page from the package's man1.
    MANPATH="$R/usr/share/man" MANWIDTH=100 man facescan-server 2>/dev/null >"$work/man.txt" ||
        fail "man facescan-server found no page in the installed package"
    grep -q -- '--data-dir' "$work/man.txt" || fail "man facescan-server does not describe --data-dir"
    grep -q 'facescan-server' "$work/man.txt" || fail "man facescan-server names no program"
    echo "man facescan-server: $(wc -l <"$work/man.txt") lines"
fi

# The unit's own command line, its absolute paths moved into the scratch root, checked with the shipped config
# (data dir moved too: /var/lib/facescan belongs to the real machine).
exec_start=$(sed -n 's/^ExecStart=//p' "$R/lib/systemd/system/facescan-server.service")
read -r -a cmd <<<"$exec_start"
for i in "${!cmd[@]}"; do [[ "${cmd[$i]}" == /* ]] && cmd[$i]="$R${cmd[$i]}"; done
check=$("${cmd[@]}" --check --data-dir "$work/unit-data" 2>&1) || { echo "$check"; fail "the unit's ExecStart --check failed"; }
echo "$check"
grep -q "($R/usr/share/facescan/profiles/lan.xml)" <<<"$check" ||
    fail "the installed server did not take the lan profile from the installed share/facescan"

# A loopback scan of the installed programs in a private domain.
source "$root_dir/deploy/claim-domain.sh"
claim_private_domain || fail "no free DDS domain"
dds=(--profile loopback --domain "$domain")
session="pkg-$$"
"$R/usr/bin/facescan-server" "${dds[@]}" --data-dir "$work/data" >"$work/server.log" 2>&1 &
server_pid=$!
pids+=("$server_pid")
"$R/usr/bin/facescan-agent" "${dds[@]}" --session "$session" --source "synthetic:frames=40,subject=builtin,seed=3" \
    --rate max --wait-for-server 30 >"$work/agent.log" 2>&1 &
pids+=($!)
"$R/usr/bin/facescan" watch "$session" "${dds[@]}" --timeout 60 >"$work/watch.log" 2>&1 || {
    cat "$work/watch.log" "$work/server.log" "$work/agent.log"
    fail "installed facescan watch failed"
}
tail -n 2 "$work/watch.log"
grep -q "face found" "$work/watch.log" || fail "the installed server never found the face (Haar cascade?)"
"$R/usr/bin/facescan" mesh "$session" -o "$work/face.ply" --finish "${dds[@]}" || fail "installed facescan mesh failed"
faces=$(grep -a -m1 '^element face' "$work/face.ply" | awk '{print $3}')
[ "${faces:-0}" -gt 1000 ] || fail "the fetched mesh has ${faces:-no} faces"
echo "loopback scan from the installed tree: $faces faces"

# --- 5. SIGTERM finishes open scans --------------------------------------------------------------------------------
step "SIGTERM to the installed server during a live scan"
live="pkg-live-$$"
"$R/usr/bin/facescan-agent" "${dds[@]}" --session "$live" --source "synthetic:frames=600,subject=builtin,seed=4" \
    --rate real --wait-for-server 30 >"$work/agent-live.log" 2>&1 &
agent_pid=$!
pids+=("$agent_pid")
integrated=0
for _ in $(seq 100); do
    # Until the server knows the session, status exits 1: not a failure here.
    integrated=$({ "$R/usr/bin/facescan" status "$live" "${dds[@]}" 2>/dev/null || true; } |
        sed -n 's/^frames .* \([0-9]*\) integrated.*/\1/p' | head -n 1)
    [ "${integrated:-0}" -ge 20 ] && break
    sleep 0.2
done
[ "${integrated:-0}" -ge 20 ] || { cat "$work/server.log"; fail "the live scan did not start (integrated: ${integrated:-none})"; }
kill -TERM "$server_pid"
code=0
for _ in $(seq 300); do kill -0 "$server_pid" 2>/dev/null || break; sleep 0.1; done
wait "$server_pid" || code=$?
cat "$work/server.log" | tail -n 4
[ "$code" -eq 0 ] || fail "the server exited $code on SIGTERM"
for f in mesh.ply trajectory.txt summary.json; do
    [ -s "$work/data/$live/$f" ] || fail "SIGTERM lost the open scan: no $work/data/$live/$f"
done
grep -q '"state"' "$work/data/$live/summary.json" || true
echo "open scan saved on SIGTERM after $integrated+ frames: $(ls "$work/data/$live" | tr '\n' ' ')"
kill -TERM "$agent_pid" 2>/dev/null || true
wait "$agent_pid" 2>/dev/null || true

# --- 6. the other installed features ---------------------------------------------------------------------------
step "facescan view and facescan-site from the scratch root"
if [ "$web_vendor" -eq 1 ]; then
    "$R/usr/bin/facescan" view "${dds[@]}" --port 0 >"$work/view.log" 2>&1 &
    view_pid=$!
    pids+=("$view_pid")
    for _ in $(seq 100); do grep -q "web files from" "$work/view.log" && break; sleep 0.1; done
    cat "$work/view.log"
    grep -q "web files from $R/usr/share/facescan/web" "$work/view.log" ||
        fail "the installed viewer did not serve the installed share/facescan/web"
    port=$(sed -n 's|.*serving http://[^:]*:\([0-9]*\)/.*|\1|p' "$work/view.log" | head -n 1)
    exec 3<>"/dev/tcp/127.0.0.1/$port"
    printf 'GET /vendor/three.module.js HTTP/1.0\r\nHost: localhost\r\n\r\n' >&3
    reply=$(head -n 1 <&3 | tr -d '\r')
    exec 3>&-
    [[ "$reply" == *" 200 "* ]] || fail "the installed viewer answered '$reply' for three.js"
    echo "installed viewer on port $port: /vendor/three.module.js -> $reply"
    kill -TERM "$view_pid" 2>/dev/null || true
    wait "$view_pid" || true
else
    echo "client_cli/web/node_modules missing (npm ci not run): the installed viewer is not checked"
fi
"$R/usr/bin/facescan-site" --help >/dev/null || fail "installed facescan-site --help failed"
if command -v openssl >/dev/null; then
    "$R/usr/bin/facescan-site" init "$work/site" --days 2 >"$work/site.log" 2>&1 || { cat "$work/site.log"; fail "facescan-site init failed"; }
    "$R/usr/bin/facescan-site" list "$work/site" | tee "$work/site-list.txt" | head -n 6
    grep -q server "$work/site-list.txt" || fail "facescan-site list shows no server identity"
fi

echo
echo "PASS: package, units, scratch-root install and installed programs"
