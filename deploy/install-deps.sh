#!/usr/bin/env bash
# Installs every Debian 12 package Ruffini needs to build, test and run. Idempotent and non-interactive;
# run as root (or with sudo). Nothing is fetched from anywhere but Debian's archive.
# libtorch (Debian's libtorch-dev) is for training only: `ruffini train` and the libtorch comparison in
# `ruffini bench`; the decoders never link it. The tests train small models, so it is installed by default;
# `--no-training` skips it (the build then leaves `train` out).
# clang-14 is only for the Hyperion codec's libFuzzer target (tests/fuzz); libclang-rt-14-dev holds libFuzzer
# and the sanitizer runtimes (clang-14 only recommends it, and we install without recommends). Without them the
# fuzz test reports SKIPPED.
# kubernetes-client (kubectl: `kubectl kustomize` renders deploy/k8s for the deploy.k8s_manifests test) is skipped
# when another package already provides /usr/bin/kubectl (e.g. Google's `kubectl`, which conflicts with it).
# podman, mmdebstrap and podman-compose (deploy/container) are not installed here: docs/deploy.md lists them.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git
  libeigen3-dev libyaml-cpp-dev libhdf5-dev libpng-dev
  libprotobuf-dev protobuf-compiler libgrpc++-dev protobuf-compiler-grpc
  libboost-dev prometheus-cpp-dev libssl-dev prometheus
  libgtest-dev libgmock-dev libbenchmark-dev
  libcli11-dev libspdlog-dev liburdfdom-dev liburdfdom-tools liborocos-kdl-dev
  python3-grpcio python3-protobuf
  clang-14 libclang-rt-14-dev
)
if dpkg-query -W -f='${Status}' kubernetes-client 2>/dev/null | grep -q "install ok installed" \
    || ! command -v kubectl >/dev/null 2>&1; then
  packages+=(kubernetes-client)
fi
if [[ "${1:-}" != "--no-training" ]]; then
  packages+=(libtorch-dev)
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]} == 0)); then
  echo "install-deps: all ${#packages[@]} packages already installed"
  exit 0
fi

SUDO=""
if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "install-deps: done"
