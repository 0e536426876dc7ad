#!/usr/bin/env bash
# A throwaway certificate authority and one certificate per operator, for Zenoh TLS and mutual TLS.
#
#   scripts/make_certs.sh [OUT_DIR] [ROUTER_HOST...]
#
# OUT_DIR (default deploy/certs) receives
#   ca.pem            the trust anchor: every router and client gets it (TLTRACK_ZENOH_TLS_ROOT_CA)
#   ca.key            the CA's key: keep it off the hosts, and delete it once everything is issued
#   router.pem/.key   the router's certificate (the referee's, in the federated topology); its
#                     names are localhost, 127.0.0.1 and every ROUTER_HOST (a DNS name or an IP
#                     address the clients connect to)
#   NAME.pem/.key     one certificate per identity in $TLTRACK_CERT_NAMES (default: every
#                     identity of the operator manifest, as the package's users.txt and
#                     routers/users.txt list them: `tltrack access generate` writes both),
#                     common name = NAME: with mutual TLS the router's ACL
#                     (shared/tltrack/access/acl.json5) knows the operator by it. A `router-*`
#                     name is an operator's router of the federated topology: it both listens
#                     and dials, so it gets the ROUTER_HOST names too (issue each on its own run,
#                     with its host: TLTRACK_CERT_NAMES=router-primary scripts/make_certs.sh
#                     deploy/certs hostp.example.org)
#
# Run it again with the same OUT_DIR to issue more certificates (e.g. TLTRACK_CERT_NAMES=source-s2):
# an existing ca.pem/ca.key pair is reused, existing certificates are kept. TLTRACK_CERT_DAYS
# (default 30) sets the validity. Keys are EC P-256, written mode 600.
set -euo pipefail

out=${1:-deploy/certs}
shift || true
days=${TLTRACK_CERT_DAYS:-30}
access="$(cd "$(dirname "$0")/.." && pwd)/shared/tltrack/access"
names=${TLTRACK_CERT_NAMES:-$(cut -d: -f1 "$access/users.txt" "$access/routers/users.txt")}

command -v openssl >/dev/null || { echo "make_certs.sh: needs the openssl command" >&2; exit 1; }
mkdir -p "$out"
cd "$out"
umask 077

newkey=(-newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes)

if [[ ! -f ca.pem || ! -f ca.key ]]; then
    openssl req -x509 "${newkey[@]}" -keyout ca.key -out ca.pem -days "$days" \
        -subj "/CN=tltrack throwaway CA $(date -u +%Y%m%dT%H%M%SZ)" \
        -addext "basicConstraints=critical,CA:TRUE,pathlen:0" \
        -addext "keyUsage=critical,keyCertSign,cRLSign" 2>/dev/null
    echo "made CA $out/ca.pem"
fi

# issue NAME EXTENDED_KEY_USAGE SUBJECT_ALT_NAMES
issue() {
    local name=$1 eku=$2 san=$3
    if [[ -f $name.pem && -f $name.key ]]; then
        echo "kept $out/$name.pem"
        return
    fi
    {
        echo "basicConstraints=critical,CA:FALSE"
        echo "keyUsage=critical,digitalSignature"
        echo "extendedKeyUsage=$eku"
        [[ -n $san ]] && echo "subjectAltName=$san"
    } >"$name.ext"
    openssl req "${newkey[@]}" -keyout "$name.key" -out "$name.csr" -subj "/CN=$name" 2>/dev/null
    openssl x509 -req -in "$name.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -days "$days" \
        -extfile "$name.ext" -out "$name.pem" 2>/dev/null
    rm -f "$name.csr" "$name.ext"
    echo "issued $out/$name.pem (CN=$name)"
}

san="DNS:localhost,IP:127.0.0.1"
for host in "$@"; do
    if [[ $host =~ ^[0-9.]+$ || $host == *:* ]]; then san+=",IP:$host"; else san+=",DNS:$host"; fi
done
# serverAuth to accept clients; clientAuth too, for a router that connects to another router.
issue router serverAuth,clientAuth "$san"
for name in $names; do
    [[ $name =~ ^[A-Za-z0-9_-]{1,64}$ ]] || { echo "make_certs.sh: bad name '$name'" >&2; exit 2; }
    if [[ $name == router-* ]]; then
        issue "$name" serverAuth,clientAuth "$san"
    else
        issue "$name" clientAuth ""
    fi
done
chmod 644 ./*.pem
