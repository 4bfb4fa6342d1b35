#!/usr/bin/env bash
# Builds the Debian 12 (bookworm) base image every Ruffini image starts from, without any image registry:
# mmdebstrap makes a minimal root filesystem from Debian's archive and podman imports it as
# localhost/ruffini/debian:bookworm (override with RUFFINI_BASE_IMAGE).
# Usage: deploy/container/base-image.sh [--mirror URL]   (default: http://deb.debian.org/debian)
# Needs root (or a user with subuids) and the Debian packages mmdebstrap and podman.
# Exit codes: 0 built (or already present with --if-missing), 1 failure, 2 usage.
set -euo pipefail

image=${RUFFINI_BASE_IMAGE:-localhost/ruffini/debian:bookworm}
mirror=http://deb.debian.org/debian
if_missing=0
while (($#)); do
  case $1 in
    --mirror) mirror=${2:?--mirror needs a URL}; shift 2 ;;
    --if-missing) if_missing=1; shift ;;
    *) echo "usage: $0 [--mirror URL] [--if-missing]" >&2; exit 2 ;;
  esac
done

if ((if_missing)) && podman image exists "$image"; then
  echo "base-image: $image already present"; exit 0
fi
for tool in mmdebstrap podman; do
  command -v "$tool" >/dev/null || { echo "base-image: $tool missing (apt-get install $tool)" >&2; exit 1; }
done

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
start=$(date +%s)
# minbase: Essential packages and apt only. The apt caches and lists are dropped: the build stage runs
# apt-get update itself, and the runtime stage should not carry them.
mmdebstrap --variant=minbase --quiet \
  --customize-hook='rm -rf "$1"/var/lib/apt/lists/* "$1"/var/cache/apt/*.bin' \
  bookworm "$work/rootfs.tar" "deb $mirror bookworm main" "deb $mirror bookworm-updates main" \
  "deb http://deb.debian.org/debian-security bookworm-security main"
podman import --change 'CMD ["/bin/bash"]' --change 'ENV LANG=C.UTF-8' \
  --message "mmdebstrap --variant=minbase bookworm $(date -u +%Y-%m-%d)" "$work/rootfs.tar" "$image" >/dev/null
echo "base-image: $image built in $(( $(date +%s) - start )) s, $(podman image inspect --format '{{.Size}}' "$image") bytes"
