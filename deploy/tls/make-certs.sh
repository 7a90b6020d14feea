#!/usr/bin/env bash
# Create the certificates of a hysid campaign over Zenoh TLS with mutual
# authentication (mTLS), with openssl only:
#
#   OUTDIR/ca.pem, OUTDIR/ca-key.pem            the campaign's own certificate authority
#   OUTDIR/coordinator/{cert,key}.pem           the coordinator (Zenoh router) certificate
#   OUTDIR/islands/<ISLAND_ID>/{cert,key}.pem   one client certificate per island
#
# usage: make-certs.sh [-o OUTDIR] [-d DAYS] [-s HOST_OR_IP]... [ISLAND_ID]...
#
#   -o OUTDIR      where to write (default ./hysid-certs); an existing CA there is
#                  reused, so islands can be added later with the same CA
#   -d DAYS        validity of new certificates (default 825)
#   -s HOST_OR_IP  a name or address the islands use to reach the coordinator
#                  (the HOST of their tls/HOST:7447 endpoint); repeat for each one.
#                  It goes into the coordinator certificate's subjectAltName, which
#                  Zenoh checks when an island connects. Giving -s (re)issues the
#                  coordinator certificate.
#   ISLAND_ID      e.g. island-1: (re)issues that island's client certificate,
#                  with CN=ISLAND_ID (the name an access-control list matches as a
#                  cert_common_name) and subjectAltName DNS:ISLAND_ID.
#
# Example: make-certs.sh -o /etc/hysid/tls -s node01 -s 10.1.0.11 island-1 island-2
#
# Keep ca-key.pem on the machine where you issue certificates; copy to each island
# only ca.pem and that island's cert.pem and key.pem.
set -euo pipefail

usage() { sed -n '/^# usage:/,/^# Example:/p' "$0" | sed 's/^# \{0,1\}//'; }
die() { echo "make-certs.sh: error: $*" >&2; exit 2; }

outdir=./hysid-certs
days=825
sans=()
while getopts ":o:d:s:h" opt; do
  case "$opt" in
    o) outdir=$OPTARG ;;
    d) [[ $OPTARG =~ ^[1-9][0-9]*$ ]] || die "-d needs a positive number of days, got '$OPTARG'"; days=$OPTARG ;;
    s) sans+=("$OPTARG") ;;
    h) usage; exit 0 ;;
    :) die "option -$OPTARG needs a value" ;;
    *) die "unknown option -$OPTARG (see -h)" ;;
  esac
done
shift $((OPTIND - 1))
islands=("$@")
[[ ${#sans[@]} -gt 0 || ${#islands[@]} -gt 0 || ! -e "$outdir/ca.pem" ]] || die "nothing to do: give -s HOST_OR_IP and/or ISLAND_ID (see -h)"
command -v openssl >/dev/null || die "openssl is not installed"
for id in "${islands[@]}"; do
  [[ $id =~ ^[A-Za-z0-9][A-Za-z0-9._-]*$ ]] || die "island id '$id' must be letters, digits, '.', '_' or '-'"
done

umask 077
mkdir -p "$outdir"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

newkey() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }
serial() { echo "0x$(openssl rand -hex 16)"; }

# issue DIR CN EXTENDED_KEY_USAGE SUBJECT_ALT_NAME
issue() {
  local dir=$1 cn=$2 eku=$3 san=$4
  mkdir -p "$dir"
  newkey "$dir/key.pem"
  cat > "$work/ext.cnf" <<EXT
basicConstraints = critical, CA:FALSE
keyUsage = critical, digitalSignature
extendedKeyUsage = $eku
subjectAltName = $san
subjectKeyIdentifier = hash
authorityKeyIdentifier = keyid
EXT
  openssl req -new -key "$dir/key.pem" -subj "/O=hysid/CN=$cn" -out "$work/req.csr"
  openssl x509 -req -in "$work/req.csr" -CA "$outdir/ca.pem" -CAkey "$outdir/ca-key.pem" \
    -set_serial "$(serial)" -days "$days" -sha256 -extfile "$work/ext.cnf" -out "$dir/cert.pem" 2>/dev/null
  openssl verify -CAfile "$outdir/ca.pem" "$dir/cert.pem" >/dev/null
  echo "issued $dir/cert.pem (CN=$cn, $san)"
}

if [[ ! -e "$outdir/ca.pem" ]]; then
  newkey "$outdir/ca-key.pem"
  cat > "$work/ca.cnf" <<CA
[req]
distinguished_name = dn
x509_extensions = ca
prompt = no
[dn]
O = hysid
CN = hysid campaign CA
[ca]
basicConstraints = critical, CA:TRUE, pathlen:0
keyUsage = critical, keyCertSign, cRLSign
subjectKeyIdentifier = hash
CA
  openssl req -x509 -new -config "$work/ca.cnf" -key "$outdir/ca-key.pem" -sha256 \
    -days "$days" -set_serial "$(serial)" -out "$outdir/ca.pem"
  echo "created CA $outdir/ca.pem"
fi
[[ -r "$outdir/ca-key.pem" ]] || die "$outdir/ca-key.pem is missing: cannot issue certificates with $outdir/ca.pem"

if [[ ${#sans[@]} -gt 0 ]]; then
  san=""
  for name in "${sans[@]}"; do
    if [[ $name =~ ^[0-9.]+$ || $name == *:* ]]; then entry="IP:$name"; else entry="DNS:$name"; fi
    san+="${san:+, }$entry"
  done
  issue "$outdir/coordinator" hysid-coordinator "serverAuth, clientAuth" "$san"
fi

for id in "${islands[@]}"; do
  issue "$outdir/islands/$id" "$id" clientAuth "DNS:$id"
done
chmod 644 "$outdir/ca.pem"
