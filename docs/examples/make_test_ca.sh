#!/bin/sh
# A TEST certificate authority and one certificate per host of a pairplay study, for the
# example TLS configs beside this script (zenoh-tls-*.json5). Test only: the keys are
# unprotected and the CA lives next to them. Usage: make_test_ca.sh OUTDIR [HOST ...]
# (default hosts: server board robot). Each host's certificate names the host in its
# common name (what access control matches: cert_common_names) and carries the
# subject alternative names localhost, 127.0.0.1 and, with PAIRPLAY_TLS_IPS="10.0.0.1 ...",
# those addresses (a client checks the server's name against them).
set -eu
out=${1:?usage: make_test_ca.sh OUTDIR [HOST ...]}
shift
[ $# -gt 0 ] || set -- server board robot
mkdir -p "$out"
cd "$out"
openssl req -x509 -newkey rsa:2048 -nodes -days 30 -subj "/CN=pairplay test CA" \
    -keyout ca.key -out ca.pem 2>/dev/null
for host in "$@"; do
    san="DNS:localhost,DNS:$host,IP:127.0.0.1"
    for ip in ${PAIRPLAY_TLS_IPS:-}; do san="$san,IP:$ip"; done
    openssl req -newkey rsa:2048 -nodes -subj "/CN=$host" -keyout "$host.key" -out "$host.csr" 2>/dev/null
    printf 'subjectAltName=%s\nbasicConstraints=CA:FALSE\nkeyUsage=digitalSignature,keyEncipherment\nextendedKeyUsage=serverAuth,clientAuth\n' \
        "$san" > "$host.ext"
    openssl x509 -req -in "$host.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -days 30 \
        -extfile "$host.ext" -out "$host.pem" 2>/dev/null
    rm -f "$host.csr" "$host.ext"
done
rm -f ca.srl
echo "test CA and certificates for: $* in $out"
