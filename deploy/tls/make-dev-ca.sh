#!/bin/sh
# make-dev-ca.sh OUT_DIR [--scene SCENE.yaml]... [--patch ID]... [--days N] [--expired]
#
# A development CA and one certificate per service for Ruffini's mutual TLS (docs/security.md). Keys are
# written next to their certificates, unencrypted (mode 600): for development and tests only; never commit
# them. OUT_DIR then holds, in the naming scheme every service's --tls-dir reads:
#   ca.crt, ca.key                 the CA (ca.key only signs; services never need it)
#   aggregator.crt/.key            server: SAN DNS:localhost, DNS:ruffini-aggregator, IP:127.0.0.1,
#                                  URI:spiffe://ruffini/aggregator
#   controller.crt/.key            client: URI:spiffe://ruffini/controller
#   operator.crt/.key              client: URI:spiffe://ruffini/operator (may ResetStop)
#   decoder-PATCH.crt/.key         client: URI:spiffe://ruffini/decoder/PATCH, one per patch of --scene/--patch
#   expired-controller.crt/.key    (--expired) the controller's identity, expired yesterday: for tests
# The identity is the URI SAN (a SPIFFE ID); the CN repeats it for people (CN=decoder:forearm_a).
# An existing OUT_DIR/ca.key is reused, so certificates can be added to a CA later.
set -eu

usage() { echo "usage: $0 OUT_DIR [--scene SCENE.yaml]... [--patch ID]... [--days N] [--expired]" >&2; exit 2; }
[ $# -ge 1 ] || usage
out=$1; shift
patches="" days=30 expired=0
while [ $# -gt 0 ]; do
  case $1 in
    --scene) [ $# -ge 2 ] || usage
      # The patch names: `  - name: X` lines of the top-level `patches:` list.
      patches="$patches $(awk '/^[^ #]/ { inside = ($1 == "patches:") } inside && $1 == "-" && $2 == "name:" { print $3 }' "$2")"
      shift 2 ;;
    --patch) [ $# -ge 2 ] || usage; patches="$patches $2"; shift 2 ;;
    --days) [ $# -ge 2 ] || usage; days=$2; shift 2 ;;
    --expired) expired=1; shift ;;
    *) usage ;;
  esac
done
command -v openssl >/dev/null || { echo "$0: openssl not found" >&2; exit 1; }
mkdir -p "$out"
umask 077
cd "$out"

if [ ! -f ca.key ]; then
  openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -keyout ca.key -out ca.crt \
    -subj "/O=ruffini-dev/CN=ruffini development CA" -days 3650 \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" 2>/dev/null
fi

# issue NAME CN EXT DAYS: NAME.key and NAME.crt signed by the CA, with the extensions EXT.
issue() {
  openssl req -new -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -keyout "$1.key" -out "$1.csr" \
    -subj "/O=ruffini-dev/CN=$2" 2>/dev/null
  printf '%s\n' "basicConstraints=critical,CA:FALSE" "keyUsage=critical,digitalSignature" "$3" > "$1.ext"
  openssl x509 -req -in "$1.csr" -CA ca.crt -CAkey ca.key -CAcreateserial -days "$4" -extfile "$1.ext" \
    -out "$1.crt" 2>/dev/null
  rm -f "$1.csr" "$1.ext"
  chmod 644 "$1.crt"
}
client() { issue "$1" "$2" "extendedKeyUsage=clientAuth
subjectAltName=URI:spiffe://ruffini/$3" "${4:-$days}"; }

issue aggregator ruffini-aggregator "extendedKeyUsage=serverAuth
subjectAltName=DNS:localhost,DNS:ruffini-aggregator,IP:127.0.0.1,URI:spiffe://ruffini/aggregator" "$days"
client controller controller controller
client operator operator operator
for p in $patches; do client "decoder-$p" "decoder:$p" "decoder/$p"; done
[ "$expired" = 0 ] || client expired-controller controller controller -1
chmod 644 ca.crt
echo "$out: ca.crt, aggregator, controller, operator$(for p in $patches; do printf ', decoder-%s' "$p"; done)$( [ "$expired" = 0 ] || echo ', expired-controller')"
