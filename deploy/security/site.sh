#!/usr/bin/env bash
# facescan site script: makes and runs a DDS Security site (OMG DDS Security, Cyclone DDS's built-in plugins)
# with nothing but openssl. A site is one folder: two CAs (identities, permissions), the signed governance
# document, a certificate revocation list, and one folder per enrolled machine or user (an "identity"), which
# holds everything that machine needs and nothing more: `facescan-agent --security SITE/NAME` (and the server,
# the client, the viewer) use it. The CA keys stay in SITE/ca and never leave the site's machine.
# Run `site.sh --help` for the commands.
set -euo pipefail
umask 077

PROG=$(basename "$0")
CA_DAYS=3650       # the two CAs and the revocation list
DEFAULT_DAYS=365   # an identity's certificate and permissions
DOMAINS_MIN=0
DOMAINS_MAX=230    # the highest domain id DDS Security documents may name (Cyclone refuses more)
ROLES="agent server client viewer"
# Written by the build into the installed copy (deploy/CMakeLists.txt); empty in the source tree, where
# --version asks the checkout instead.
VERSION_LINE=""
LOGIN_ITERATIONS=600000  # PBKDF2-HMAC-SHA256 rounds of a viewer login (OWASP's 2023 figure for this hash)

usage() {
    cat <<EOF
usage: $PROG init DIR [--name SITE] [--days N]
       $PROG add DIR ROLE NAME [--days N] [--from DATE] [--until DATE]
       $PROG revoke DIR NAME
       $PROG list DIR
       $PROG --version
       $PROG web DIR NAME --host HOST [--host HOST...] [--days N] [--from DATE] [--until DATE]
       $PROG login DIR NAME USER [--remove]
       $PROG --help

Makes and runs a facescan DDS Security site in DIR with openssl: only enrolled machines join the DDS domain,
every frame, status and mesh is encrypted, and each role may do only its job.

  init DIR      a new site: the identity CA and the permissions CA (DIR/ca, private: keep it on this machine),
                the signed governance document (discovery, liveliness and every facescan topic encrypted and
                signed; unauthenticated participants refused), the revocation list, and one identity per role:
                DIR/agent, DIR/server, DIR/client, DIR/viewer. --name names the site (default: DIR's name);
                --days is how long those four identities are valid (default $DEFAULT_DAYS).
  add           enrols one more machine or user as DIR/NAME with ROLE's permissions, signed by the site:
                  agent    publishes camera info and frames; reads status, replies, who owns its scan and
                           erasures (it drops the frames it kept for an erased scan)
                  server   reads frames and commands; publishes status, snapshots and replies, its announcement
                           and its claims on scans; talks to the other servers of the cluster (facescan/cluster/*)
                  client   reads status, snapshots, replies and the cluster's announcements and owners; sends
                           commands (reset, finish, get mesh)
                  viewer   only reads status, snapshots, the cluster's announcements and owners, and erasures
                           (an erased scan leaves its pages)
                Valid from now (or --from DATE) for --days N days (default $DEFAULT_DAYS) or until --until DATE
                (DATE: YYYY-MM-DD or YYYY-MM-DDTHH:MM:SS, UTC).
  revoke        revokes NAME: its certificate (and a viewer's web certificate) goes on the revocation list
                (DIR/crl.pem, copied into every identity folder of DIR) and its permissions are re-issued to allow
                nothing. A running web viewer with NAME's folder refuses every connection (and so every login)
                as soon as its crl.pem lists its web certificate, and will not start again with it. Copy the new
                crl.pem to every machine's identity folder; each peer rejects NAME from its next start.
  list          the identities of DIR: role, validity, revoked or not.
  web           a TLS certificate for the web viewer that runs with identity DIR/NAME (normally a viewer), signed
                by the site's identity CA, for each --host (a name or an IP address browsers use to reach it):
                DIR/NAME/web.pem (its key and certificate, private) and web.crt. Browsers must trust the site's
                CA (DIR/identity_ca.pem: import it once). Valid as for add (default $DEFAULT_DAYS days).
  login         adds a viewer login USER to DIR/NAME/logins, or changes its password (asked twice on a terminal,
                else one line on standard input; at least 10 characters); --remove removes it. Stored as a salted
                PBKDF2-HMAC-SHA256 hash ($LOGIN_ITERATIONS iterations, openssl enc -pbkdf2), never the password.
                The viewer reads the file again at the next login, and a removed user's sessions end.

Every program takes the identity folder: --security DIR/NAME (facescan-agent, facescan-server, facescan).
The web viewer over HTTPS with a login: facescan view --bind 0.0.0.0 --security DIR/NAME --tls DIR/NAME.

Enrol a new capture PC (here: capture-3) in three commands:
  $PROG add /etc/facescan/site agent capture-3            # on the machine that holds the site
  scp -r /etc/facescan/site/capture-3 capture-3:/etc/facescan/    # its identity folder (no CA key in it)
  facescan-agent --profile lan --security /etc/facescan/capture-3   # on capture-3
EOF
}

die() {
    echo "$PROG: $*" >&2
    exit 1
}
usage_error() {
    echo "$PROG: $*" >&2
    echo "(see $PROG --help)" >&2
    exit 2
}

command -v openssl >/dev/null || die "openssl not found: sudo apt-get install openssl"

# Names go into certificate subjects and the permissions' subject_name, where Cyclone splits on , / and |.
valid_name() { [[ $1 =~ ^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$ ]]; }

# DATE (YYYY-MM-DD[THH:MM:SS], UTC) -> seconds since the epoch.
epoch_of() {
    local s
    s=$(date -u -d "${1/T/ } UTC" +%s 2>/dev/null) || usage_error "cannot read the date '$1' (use YYYY-MM-DD or YYYY-MM-DDTHH:MM:SS, UTC)"
    echo "$s"
}
asn1_time() { date -u -d "@$1" +%Y%m%d%H%M%SZ; }  # openssl ca -startdate/-enddate
xml_time() { date -u -d "@$1" +%Y-%m-%dT%H:%M:%S; }  # the permissions' <validity>

site_conf() { sed -n "s/^$2=//p" "$1/site.conf"; }

need_site() {
    [ -f "$1/site.conf" ] && [ -f "$1/ca/openssl.cnf" ] || die "$1 is not a facescan site (make one with: $PROG init $1)"
}

# openssl ca runs inside DIR/ca with relative paths, so a site folder can be moved or copied.
site_ca() {
    local dir=$1
    shift
    (cd "$dir/ca" && openssl ca -config openssl.cnf -batch "$@" 2>ca.log) || {
        cat "$dir/ca/ca.log" >&2
        die "openssl ca failed (above)"
    }
}

# S/MIME, clear text, signed by the permissions CA: the form DDS Security's access control plugin reads.
smime_sign() {
    openssl smime -sign -text -in "$2" -out "$3" -signer "$1/permissions_ca.pem" -inkey "$1/ca/permissions_ca.key" \
        || die "cannot sign $2"
}

governance_xml() {
    cat <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<!-- facescan site "$1": governance of every facescan DDS domain ($DOMAINS_MIN-$DOMAINS_MAX). Signed by the site's
     permissions CA (governance.p7s); made by deploy/security/site.sh. -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id_range><min>$DOMAINS_MIN</min><max>$DOMAINS_MAX</max></id_range></domains>
      <!-- Only participants with an identity of this site take part; the others are not even discovered. -->
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <!-- Every RTPS message is signed: nobody outside the site can inject heartbeats or acknowledgements. -->
      <rtps_protection_kind>SIGN</rtps_protection_kind>
      <topic_access_rules>
        <!-- Every topic (facescan/*, facescan/cluster/*): payloads encrypted (AES-GCM), then the submessage that
             carries them signed; readers and writers need a permissions grant. -->
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>SIGN</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
EOF
}

# The topics of idl/include/wire/topics.hpp each role may publish and subscribe to (space-separated patterns).
# The cluster's public topics (servers announce themselves and claim sessions) are published by servers and read
# by everyone (an agent streams to its session's owner); facescan/cluster/* is between servers only.
CLUSTER_PUBLIC="facescan/ServerAnnounce facescan/SessionOwner"
# Erasure: a client asks (EraseRequest), servers pass the request on (so a server that was down learns it) and
# report (EraseReport); agents and viewers read the requests to drop what they hold of an erased scan. Identities enrolled before these topics existed need their permissions made again.
ERASURE="facescan/EraseRequest facescan/EraseReport"
role_publishes() {
    case $1 in
        agent) echo "facescan/CameraInfo facescan/RgbdFrame" ;;
        server) echo "facescan/ScanStatus facescan/MeshSnapshot facescan/ScanReply $CLUSTER_PUBLIC facescan/cluster/* $ERASURE" ;;
        client) echo "facescan/ScanCommand facescan/EraseRequest" ;;
        viewer) echo "" ;;
    esac
}
role_subscribes() {
    case $1 in
        agent) echo "facescan/ScanStatus facescan/ScanReply $CLUSTER_PUBLIC facescan/EraseRequest" ;;
        server) echo "facescan/CameraInfo facescan/RgbdFrame facescan/ScanCommand $CLUSTER_PUBLIC facescan/cluster/* facescan/EraseRequest" ;;
        client) echo "facescan/ScanStatus facescan/MeshSnapshot facescan/ScanReply $CLUSTER_PUBLIC facescan/EraseReport facescan/EraseRequest" ;;
        viewer) echo "facescan/ScanStatus facescan/MeshSnapshot $CLUSTER_PUBLIC facescan/EraseRequest" ;;
    esac
}

# One publish or subscribe block. A grant without <partitions> makes Cyclone refuse readers and writers
# (NOT_ALLOWED_BY_SECURITY), so every block names the partitions it allows: all of them.
topics_block() {
    local kind=$1 topics=$2 t
    [ -n "$topics" ] || return 0
    echo "        <$kind>"
    echo "          <topics>"
    for t in $topics; do echo "            <topic>$t</topic>"; done
    echo "          </topics>"
    echo "          <partitions><partition>*</partition></partitions>"
    echo "        </$kind>"
}

# permissions_xml SUBJECT NAME ROLE NOT_BEFORE NOT_AFTER [revoked]
permissions_xml() {
    local subject=$1 name=$2 role=$3 from=$4 until=$5 revoked=${6:-}
    cat <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<!-- facescan identity "$name", role $role. Signed by the site's permissions CA (permissions.p7s). -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="$name">
      <subject_name>$subject</subject_name>
      <validity><not_before>$from</not_before><not_after>$until</not_after></validity>
EOF
    if [ -z "$revoked" ]; then
        cat <<EOF
      <allow_rule>
        <domains><id_range><min>$DOMAINS_MIN</min><max>$DOMAINS_MAX</max></id_range></domains>
$(topics_block publish "$(role_publishes "$role")")
$(topics_block subscribe "$(role_subscribes "$role")")
      </allow_rule>
EOF
    else
        echo "      <!-- revoked on $revoked: nothing is allowed -->"
    fi
    cat <<EOF
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
EOF
}

# Copies the site-wide public files into an identity folder.
refresh_identity() {
    local dir=$1 id=$2
    cp "$dir/identity_ca.pem" "$dir/permissions_ca.pem" "$dir/governance.p7s" "$dir/crl.pem" "$id/"
    chmod 644 "$id/identity_ca.pem" "$id/permissions_ca.pem" "$id/governance.p7s" "$id/crl.pem"
}

cmd_add() {
    [ $# -ge 3 ] || usage_error "add needs DIR ROLE NAME"
    local dir=$1 role=$2 name=$3 days=$DEFAULT_DAYS from="" until=""
    shift 3
    while [ $# -gt 0 ]; do
        case $1 in
            --days) [ $# -ge 2 ] || usage_error "--days needs a value"; days=$2; shift 2 ;;
            --from) [ $# -ge 2 ] || usage_error "--from needs a date"; from=$2; shift 2 ;;
            --until) [ $# -ge 2 ] || usage_error "--until needs a date"; until=$2; shift 2 ;;
            *) usage_error "unknown option '$1' for add" ;;
        esac
    done
    need_site "$dir"
    case " $ROLES " in *" $role "*) ;; *) usage_error "unknown role '$role' (one of: $ROLES)" ;; esac
    valid_name "$name" || usage_error "'$name' is not a valid name (letters, digits, . _ -; at most 64)"
    [ "$name" != ca ] || usage_error "'ca' is the site's private folder, not a name"
    [[ $days =~ ^[0-9]+$ ]] && [ "$days" -ge 1 ] || usage_error "--days takes a positive number of days"
    local id="$dir/$name"
    [ ! -e "$id" ] || die "$id exists already (revoke it and choose another name)"

    local start end
    start=$(if [ -n "$from" ]; then epoch_of "$from"; else date -u +%s; fi)
    end=$(if [ -n "$until" ]; then epoch_of "$until"; else echo $((start + days * 86400)); fi)
    [ "$end" -gt "$start" ] || usage_error "the identity would end before it starts"

    local site subject
    site=$(site_conf "$dir" name)
    subject="CN=$name,OU=$role,O=$site"
    mkdir -p "$id"
    openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:prime256v1 -out "$id/identity.key" 2>/dev/null \
        || die "cannot make a key for $name"
    openssl req -new -key "$id/identity.key" -subj "/O=$site/OU=$role/CN=$name" -out "$id/identity.csr" \
        || die "cannot make a certificate request for $name"
    site_ca "$dir" -in "../$name/identity.csr" -out "../$name/identity.pem" -notext \
        -startdate "$(asn1_time "$start")" -enddate "$(asn1_time "$end")"
    rm -f "$id/identity.csr"
    echo "$role" >"$id/role"
    permissions_xml "$subject" "$name" "$role" "$(xml_time "$start")" "$(xml_time "$end")" >"$id/permissions.xml"
    smime_sign "$dir" "$id/permissions.xml" "$id/permissions.p7s"
    refresh_identity "$dir" "$id"
    chmod 700 "$id"
    chmod 600 "$id/identity.key"
    chmod 644 "$id/identity.pem" "$id/permissions.xml" "$id/permissions.p7s" "$id/role"
    echo "$PROG: enrolled $name as $role, valid $(xml_time "$start") to $(xml_time "$end") UTC: $id"
}

cmd_init() {
    [ $# -ge 1 ] || usage_error "init needs DIR"
    local dir=$1 name="" days=$DEFAULT_DAYS
    shift
    while [ $# -gt 0 ]; do
        case $1 in
            --name) [ $# -ge 2 ] || usage_error "--name needs a value"; name=$2; shift 2 ;;
            --days) [ $# -ge 2 ] || usage_error "--days needs a value"; days=$2; shift 2 ;;
            *) usage_error "unknown option '$1' for init" ;;
        esac
    done
    if [ -e "$dir" ] && [ -n "$(ls -A "$dir" 2>/dev/null)" ]; then die "$dir exists and is not empty"; fi
    [ -n "$name" ] || name=$(basename "$(realpath -m "$dir")")
    valid_name "$name" || usage_error "'$name' is not a valid site name (letters, digits, . _ -): use --name"
    mkdir -p "$dir/ca/newcerts"
    chmod 700 "$dir/ca"
    echo "name=$name" >"$dir/site.conf"
    : >"$dir/ca/index.txt"
    echo 1000 >"$dir/ca/serial"
    echo 1000 >"$dir/ca/crlnumber"
    cat >"$dir/ca/openssl.cnf" <<EOF
# openssl ca configuration of facescan site "$name" (deploy/security/site.sh); paths relative to this folder.
[ ca ]
default_ca = identity_ca
[ identity_ca ]
database = index.txt
new_certs_dir = newcerts
serial = serial
crlnumber = crlnumber
certificate = ../identity_ca.pem
private_key = identity_ca.key
default_md = sha256
default_crl_days = $CA_DAYS
policy = policy_site
unique_subject = no
x509_extensions = identity_cert
[ policy_site ]
organizationName = supplied
organizationalUnitName = supplied
commonName = supplied
[ identity_cert ]
basicConstraints = critical, CA:FALSE
keyUsage = critical, digitalSignature
subjectKeyIdentifier = hash
authorityKeyIdentifier = keyid
EOF
    local which
    for which in identity permissions; do
        openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:prime256v1 -out "$dir/ca/${which}_ca.key" 2>/dev/null \
            || die "cannot make the $which CA key"
        openssl req -x509 -new -key "$dir/ca/${which}_ca.key" -sha256 -days "$CA_DAYS" \
            -subj "/O=$name/CN=facescan $which CA" \
            -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign,digitalSignature" \
            -out "$dir/${which}_ca.pem" || die "cannot make the $which CA"
        chmod 644 "$dir/${which}_ca.pem"
    done
    site_ca "$dir" -gencrl -out ../crl.pem
    governance_xml "$name" >"$dir/governance.xml"
    smime_sign "$dir" "$dir/governance.xml" "$dir/governance.p7s"
    chmod 644 "$dir/crl.pem" "$dir/governance.xml" "$dir/governance.p7s" "$dir/site.conf"
    chmod 755 "$dir"
    echo "$PROG: site '$name' in $dir (CA keys in $dir/ca: keep them here)"
    local role
    for role in $ROLES; do cmd_add "$dir" "$role" "$role" --days "$days"; done
}

cmd_revoke() {
    [ $# -eq 2 ] || usage_error "revoke needs DIR NAME"
    local dir=$1 name=$2
    need_site "$dir"
    valid_name "$name" && [ "$name" != ca ] || usage_error "'$name' is not an identity name"
    local id="$dir/$name"
    [ -f "$id/identity.pem" ] || die "no identity '$name' in $dir"
    [ ! -f "$id/REVOKED" ] || die "$name is already revoked ($(cat "$id/REVOKED"))"
    site_ca "$dir" -revoke "../$name/identity.pem"
    # A viewer's web certificate goes too: its TLS front stops serving once it reads the new list.
    local web=""
    if [ -f "$id/web.crt" ]; then
        site_ca "$dir" -revoke "../$name/web.crt"
        web=" and its web certificate"
    fi
    site_ca "$dir" -gencrl -out ../crl.pem
    chmod 644 "$dir/crl.pem"
    local now role subject
    now=$(xml_time "$(date -u +%s)")
    role=$(cat "$id/role")
    subject="CN=$name,OU=$role,O=$(site_conf "$dir" name)"
    permissions_xml "$subject" "$name" "$role" "$now" "$now" "$now" >"$id/permissions.xml"
    smime_sign "$dir" "$id/permissions.xml" "$id/permissions.p7s"
    echo "$now UTC" >"$id/REVOKED"
    local other count=0
    for other in "$dir"/*/; do
        other=${other%/}
        [ "$(basename "$other")" != ca ] && [ -f "$other/identity.pem" ] || continue
        refresh_identity "$dir" "$other"
        count=$((count + 1))
    done
    echo "$PROG: revoked $name ($role)$web; the new revocation list is $dir/crl.pem (copied into the $count identity folders here)."
    echo "$PROG: copy it to every machine's identity folder (DIR/NAME/crl.pem); each peer rejects $name from its next start."
}

cmd_list() {
    [ $# -eq 1 ] || usage_error "list needs DIR"
    local dir=$1 id name role until state now
    need_site "$dir"
    now=$(date -u +%s)
    printf '%-24s %-7s %-22s %s\n' NAME ROLE "VALID UNTIL (UTC)" STATE
    for id in "$dir"/*/; do
        id=${id%/}
        name=$(basename "$id")
        [ "$name" != ca ] && [ -f "$id/identity.pem" ] || continue
        role=$(cat "$id/role" 2>/dev/null || echo "?")
        until=$(openssl x509 -in "$id/identity.pem" -noout -enddate | sed 's/^notAfter=//')
        state=ok
        if [ -f "$id/REVOKED" ]; then
            state="revoked $(cat "$id/REVOKED")"
        elif [ "$(date -u -d "$until" +%s)" -le "$now" ]; then
            state=expired
        fi
        printf '%-24s %-7s %-22s %s\n' "$name" "$role" "$(date -u -d "$until" +%Y-%m-%dT%H:%M:%S)" "$state"
    done
}

# "facescan-site VERSION (commit HASH)", as the programs print it.
print_version() {
    if [ -z "$VERSION_LINE" ]; then
        local src version commit
        src=$(cd "$(dirname "$0")/../.." && pwd)
        version=$(sed -n 's/^project(facescan VERSION \([0-9.]*\).*/\1/p' "$src/CMakeLists.txt" 2>/dev/null || true)
        commit=$(git -C "$src" rev-parse --short=12 HEAD 2>/dev/null || echo unknown)
        VERSION_LINE="${version:-unknown} (commit $commit)"
    fi
    echo "$PROG $VERSION_LINE"
}

# A TLS server certificate for the web viewer, signed by the identity CA (browsers import DIR/identity_ca.pem).
cmd_web() {
    [ $# -ge 2 ] || usage_error "web needs DIR NAME --host HOST"
    local dir=$1 name=$2 days=$DEFAULT_DAYS from="" until="" hosts=()
    shift 2
    while [ $# -gt 0 ]; do
        case $1 in
            --host) [ $# -ge 2 ] || usage_error "--host needs a name or an IP address"; hosts+=("$2"); shift 2 ;;
            --days) [ $# -ge 2 ] || usage_error "--days needs a value"; days=$2; shift 2 ;;
            --from) [ $# -ge 2 ] || usage_error "--from needs a date"; from=$2; shift 2 ;;
            --until) [ $# -ge 2 ] || usage_error "--until needs a date"; until=$2; shift 2 ;;
            *) usage_error "unknown option '$1' for web" ;;
        esac
    done
    need_site "$dir"
    valid_name "$name" && [ "$name" != ca ] || usage_error "'$name' is not an identity name"
    local id="$dir/$name"
    [ -d "$id" ] || die "no identity '$name' in $dir (enrol the viewer first: $PROG add $dir viewer $name)"
    [ ${#hosts[@]} -gt 0 ] || usage_error "web needs at least one --host: the name or address browsers use"
    [[ $days =~ ^[0-9]+$ ]] && [ "$days" -ge 1 ] || usage_error "--days takes a positive number of days"
    local san="" host
    for host in "${hosts[@]}"; do
        if [[ $host =~ ^[0-9]{1,3}(\.[0-9]{1,3}){3}$ ]] || [[ $host =~ ^[0-9A-Fa-f:]*:[0-9A-Fa-f:.]*$ ]]; then
            san+="${san:+, }IP:$host"
        elif [[ $host =~ ^[A-Za-z0-9][A-Za-z0-9.-]{0,252}$ ]]; then
            san+="${san:+, }DNS:$host"
        else
            usage_error "'$host' is neither a host name nor an IP address"
        fi
    done
    local start end
    start=$(if [ -n "$from" ]; then epoch_of "$from"; else date -u +%s; fi)
    end=$(if [ -n "$until" ]; then epoch_of "$until"; else echo $((start + days * 86400)); fi)
    [ "$end" -gt "$start" ] || usage_error "the certificate would end before it starts"
    printf '%s\n' "[ web_cert ]" "basicConstraints = critical, CA:FALSE" "keyUsage = critical, digitalSignature" \
        "extendedKeyUsage = serverAuth" "subjectAltName = $san" "subjectKeyIdentifier = hash" \
        "authorityKeyIdentifier = keyid" >"$id/web.ext"
    openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:prime256v1 -out "$id/web.key" 2>/dev/null \
        || die "cannot make a key for the web certificate of $name"
    openssl req -new -key "$id/web.key" -subj "/O=$(site_conf "$dir" name)/OU=web/CN=${hosts[0]}" -out "$id/web.csr" \
        || die "cannot make a certificate request for the web certificate of $name"
    site_ca "$dir" -in "../$name/web.csr" -out "../$name/web.crt" -notext -extfile "../$name/web.ext" \
        -extensions web_cert -startdate "$(asn1_time "$start")" -enddate "$(asn1_time "$end")"
    # CivetWeb reads the key and the certificate from one file.
    cat "$id/web.key" "$id/web.crt" >"$id/web.pem"
    rm -f "$id/web.csr" "$id/web.ext" "$id/web.key"
    chmod 600 "$id/web.pem"
    chmod 644 "$id/web.crt"
    echo "$PROG: web certificate for ${hosts[*]}, valid $(xml_time "$start") to $(xml_time "$end") UTC: $id/web.pem"
    echo "$PROG: browsers must trust $dir/identity_ca.pem; add logins with: $PROG login $dir $name USER"
}

# A viewer login: USER:pbkdf2-sha256:ITERATIONS:SALT:KEY in DIR/NAME/logins (client/view_logins.hpp reads it).
cmd_login() {
    [ $# -ge 3 ] || usage_error "login needs DIR NAME USER"
    local dir=$1 name=$2 user=$3 remove=0
    shift 3
    while [ $# -gt 0 ]; do
        case $1 in
            --remove) remove=1; shift ;;
            *) usage_error "unknown option '$1' for login" ;;
        esac
    done
    need_site "$dir"
    valid_name "$name" && [ "$name" != ca ] || usage_error "'$name' is not an identity name"
    local id="$dir/$name" file="$dir/$name/logins"
    [ -d "$id" ] || die "no identity '$name' in $dir"
    [[ $user =~ ^[A-Za-z0-9._@-]{1,64}$ ]] || usage_error "'$user' is not a valid user name (letters, digits, . _ @ -)"
    local others=""
    if [ -f "$file" ]; then others=$(grep -v "^$user:" "$file" || true); fi
    if [ "$remove" = 1 ]; then
        [ -f "$file" ] && grep -q "^$user:" "$file" || die "no login '$user' in $file"
        printf '%s\n' "$others" | sed '/^$/d' >"$file.tmp"
        chmod 600 "$file.tmp"
        mv "$file.tmp" "$file"
        echo "$PROG: removed login $user from $file (its sessions end at their next request)"
        return
    fi
    local password="" again=""
    if [ -t 0 ]; then
        read -rsp "password for $user: " password && echo
        read -rsp "again: " again && echo
        [ "$password" = "$again" ] || die "the two passwords differ"
    else
        IFS= read -r password || [ -n "$password" ] || die "no password on standard input"
    fi
    [ ${#password} -ge 10 ] || die "a password needs at least 10 characters"
    local salt key
    salt=$(openssl rand -hex 8) || die "openssl rand failed"
    # The password goes through a pipe (printf is a shell builtin): never on a command line, where ps shows it.
    key=$(printf '%s\n' "$password" | openssl enc -aes-256-cbc -pbkdf2 -md sha256 -iter "$LOGIN_ITERATIONS" \
        -S "$salt" -pass stdin -P | sed -n 's/^key=//p') || die "openssl enc -pbkdf2 failed"
    [ ${#key} -eq 64 ] || die "openssl enc -pbkdf2 gave no key"
    {
        if [ -n "$others" ]; then printf '%s\n' "$others"; fi
        printf '%s:pbkdf2-sha256:%s:%s:%s\n' "$user" "$LOGIN_ITERATIONS" "$salt" "$key"
    } >"$file.tmp"
    chmod 600 "$file.tmp"
    mv "$file.tmp" "$file"
    echo "$PROG: login $user in $file (copy it to the viewer's DIR/NAME; it reads it again at the next login)"
}

case ${1:-} in
    -h | --help | help) usage ;;
    --version) print_version ;;
    init) shift; cmd_init "$@" ;;
    add) shift; cmd_add "$@" ;;
    revoke) shift; cmd_revoke "$@" ;;
    list) shift; cmd_list "$@" ;;
    web) shift; cmd_web "$@" ;;
    login) shift; cmd_login "$@" ;;
    "") usage_error "no command given" ;;
    *) usage_error "unknown command '$1'" ;;
esac
