#!/usr/bin/env bash
# Make a throw-away certificate authority and one certificate per BuddyBot host,
# for the multi-host Zenoh profile in deploy/zenoh/ (TLS + mutual TLS + access control).
#
#   scripts/make-test-certs.sh OUTDIR [ROUTER_NAME...]
#
# OUTDIR gets:
#   ca.pem / ca.key              the test CA (keep ca.key off the robot in real life)
#   router.pem / router.key      the router's server certificate
#   robot.pem / robot.key        client certificate of the robot computer
#   radar-board.pem / .key       client certificate of the board near the radars
#   camera-host.pem / .key       client certificate of a separate camera computer
#   eye-screen.pem / .key        client certificate of a remote eye screen
#   operator.pem / .key          client certificate of an operator's laptop (read-only)
#   rogue-ca.pem, rogue.pem/.key a second CA and a certificate it signed, which the
#                                router must refuse (used by the tests)
#
# The common name (CN) of each client certificate is the identity the router's
# access control matches (deploy/zenoh/router.json5, "cert_common_names"), so the
# names here and there must agree. The router certificate carries the names clients
# dial as subject alternative names: localhost and 127.0.0.1 always, plus every
# ROUTER_NAME given (a DNS name or an IPv4/IPv6 address), e.g. buddy.local 192.168.1.20.
#
# These are test certificates: keys are unencrypted and valid for 825 days. For a
# robot in the field make the keys on each host and sign them with a CA kept offline.
set -euo pipefail

if [ $# -lt 1 ] || [ "$1" = "-h" ] || [ "$1" = "--help" ]; then
    sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//'
    [ $# -ge 1 ] && exit 0
    exit 2
fi
command -v openssl >/dev/null 2>&1 || { echo "make-test-certs: openssl not found" >&2; exit 1; }

OUT=$1
shift
mkdir -p "$OUT"
DAYS=825
HOSTS="robot radar-board eye-screen camera-host operator"
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

# EC P-256 keys in PKCS#8 PEM: small, fast, and read by rustls (Zenoh's TLS).
new_key() {
    openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null
    chmod 600 "$1"
}

# make_ca NAME CN: a self-signed CA certificate NAME.pem with key NAME.key.
make_ca() {
    new_key "$OUT/$1.key"
    cat >"$WORK/$1.ext" <<EOF
[req]
distinguished_name = dn
prompt = no
x509_extensions = v3
[dn]
CN = $2
[v3]
basicConstraints = critical, CA:TRUE
keyUsage = critical, keyCertSign, cRLSign
subjectKeyIdentifier = hash
EOF
    openssl req -new -x509 -key "$OUT/$1.key" -days "$DAYS" -config "$WORK/$1.ext" \
        -out "$OUT/$1.pem" 2>/dev/null
}

# make_cert CA NAME CN USAGE SAN: NAME.pem/NAME.key signed by CA, extended key usage USAGE.
make_cert() {
    local ca=$1 name=$2 cn=$3 usage=$4 san=$5
    new_key "$OUT/$name.key"
    openssl req -new -key "$OUT/$name.key" -subj "/O=BuddyBot/CN=$cn" \
        -out "$WORK/$name.csr" 2>/dev/null
    cat >"$WORK/$name.ext" <<EOF
basicConstraints = critical, CA:FALSE
keyUsage = critical, digitalSignature
extendedKeyUsage = $usage
subjectAltName = $san
authorityKeyIdentifier = keyid
EOF
    openssl x509 -req -in "$WORK/$name.csr" -CA "$OUT/$ca.pem" -CAkey "$OUT/$ca.key" \
        -CAcreateserial -days "$DAYS" -sha256 -extfile "$WORK/$name.ext" \
        -out "$OUT/$name.pem" 2>/dev/null
}

# Subject alternative names of the router: what clients put in tls/NAME:PORT.
router_san="DNS:localhost,IP:127.0.0.1"
for name in "$@"; do
    if [[ $name =~ ^[0-9.]+$ || $name == *:* ]]; then
        router_san="$router_san,IP:$name"
    elif [[ $name =~ ^[A-Za-z0-9.-]+$ ]]; then
        router_san="$router_san,DNS:$name"
    else
        echo "make-test-certs: not a host name or address: $name" >&2
        exit 2
    fi
done

make_ca ca "BuddyBot test CA"
make_cert ca router router "serverAuth, clientAuth" "$router_san"
for host in $HOSTS; do
    make_cert ca "$host" "$host" "clientAuth" "DNS:$host"
done

# A CA the router does not trust, and a "robot" certificate it signed: same common
# name as the real robot, so only the signature tells them apart.
make_ca rogue-ca "Not the BuddyBot CA"
make_cert rogue-ca rogue robot "clientAuth" "DNS:robot"

rm -f "$OUT"/*.srl
echo "certificates for: router ($router_san) $HOSTS; rogue -> $OUT"
