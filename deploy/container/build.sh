#!/usr/bin/env bash
# Builds the Ruffini service image (deploy/container/Containerfile) offline with podman and reports its size
# and build time. Makes the Debian base image first if it is missing (deploy/container/base-image.sh).
# `--runtime runc`: crun fails on hybrid cgroups (FACTS.md); `--network=host`: the build stage's apt-get
# reaches Debian's archive through the host's network.
# Usage: deploy/container/build.sh [--tag TAG] [--prometheus]
#   image localhost/ruffini/ruffini:TAG (default dev); --prometheus also builds localhost/ruffini/prometheus:TAG
#   (Debian's prometheus, for compose.yaml).
# Exit codes: 0 built; 1 failure; 2 usage.
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
tag=dev
with_prometheus=0
while (($#)); do
  case $1 in
    --tag) tag=${2:?}; shift 2 ;;
    --prometheus) with_prometheus=1; shift ;;
    *) echo "usage: $0 [--tag TAG] [--prometheus]" >&2; exit 2 ;;
  esac
done
image=localhost/ruffini/ruffini:$tag

"$repo/deploy/container/base-image.sh" --if-missing
start=$(date +%s)
podman --runtime runc build --network=host --layers --target runtime \
  -f "$repo/deploy/container/Containerfile" -t "$image" "$repo"
secs=$(( $(date +%s) - start ))
bytes=$(podman image inspect --format '{{.Size}}' "$image")
echo "build: $image in ${secs} s, $((bytes / 1000000)) MB"
if ((with_prometheus)); then
  podman --runtime runc build --network=host --layers --target prometheus \
    -f "$repo/deploy/container/Containerfile" -t "localhost/ruffini/prometheus:$tag" "$repo"
  echo "build: localhost/ruffini/prometheus:$tag, $(( $(podman image inspect --format '{{.Size}}' "localhost/ruffini/prometheus:$tag") / 1000000 )) MB"
fi
# The runtime stage must run as non-root and hold no compiler.
podman --runtime runc run --rm --ulimit nofile=4096:4096 --ulimit nproc=4096:4096 "$image" sh -c \
  'id -u; for c in cc gcc c++ g++ clang; do command -v $c && exit 1; done; ls /usr/local/bin /etc/ruffini/config'
