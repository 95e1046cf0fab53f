#!/bin/sh
# Make a private CA and the certificates of a TLS + access-control zenoh deployment of gngdt.
#
#   config/secure/make-certs.sh [DIR [ROUTER_HOST [CLIENT_CN ...]]]
#
# DIR (default config/secure/certs): where ca.pem/ca.key, router.pem/router.key and one
# <CLIENT_CN>.pem/.key per client name (default: one per role, gngdt-capture, gngdt-learner,
# gngdt-logger, gngdt-bridge, gngdt-viewer) are written.
# ROUTER_HOST (default localhost): the router's DNS name, also put in the certificate's
# subjectAltName together with 127.0.0.1; clients must connect to this name.
# Client certificates carry their name as Common Name: the router's access_control matches it
# (`cert_common_names`). Keep ca.key offline in a real deployment.
set -eu
dir=${1:-config/secure/certs}
host=${2:-localhost}
[ $# -ge 2 ] && shift 2 || shift $#
[ $# -eq 0 ] && set -- gngdt-capture gngdt-learner gngdt-logger gngdt-bridge gngdt-viewer
mkdir -p "$dir"
umask 077
openssl req -x509 -newkey rsa:2048 -nodes -days 365 -subj "/CN=gngdt-ca" \
  -keyout "$dir/ca.key" -out "$dir/ca.pem" 2>/dev/null

issue() {  # name common-name subjectAltName
  openssl req -newkey rsa:2048 -nodes -subj "/CN=$2" \
    -keyout "$dir/$1.key" -out "$dir/$1.csr" 2>/dev/null
  printf 'basicConstraints=CA:FALSE\nkeyUsage=digitalSignature,keyEncipherment\n%s\n%s\n' \
    "extendedKeyUsage=serverAuth,clientAuth" "subjectAltName=$3" > "$dir/$1.ext"
  openssl x509 -req -days 365 -in "$dir/$1.csr" -CA "$dir/ca.pem" -CAkey "$dir/ca.key" \
    -CAcreateserial -extfile "$dir/$1.ext" -out "$dir/$1.pem" 2>/dev/null
  rm -f "$dir/$1.csr" "$dir/$1.ext"
}

issue router "$host" "DNS:$host,DNS:localhost,IP:127.0.0.1"
for name in "$@"; do
  issue "$name" "$name" "DNS:$name"
done
echo "certificates in $dir: router ($host), clients: $*"
