# Sourced by the scripts that start facescan processes (demo.sh, tests/bench/server_realtime.sh): claims a private
# DDS domain, one of 100..219, with an exclusive flock held on descriptor 9 until the calling script and everything
# it started exit (the tests claim theirs the same way, tests/common/test_domain.hpp). Sets $domain; returns 1
# when every domain is taken.
claim_private_domain() {
    domain=""
    local i candidate
    for i in $(seq 0 119); do
        candidate=$((100 + ($$ + i) % 120))
        exec 9>"/tmp/facescan-test-domain-$candidate.lock"
        if flock -n 9; then domain=$candidate; return 0; fi
        exec 9>&-
    done
    return 1
}
