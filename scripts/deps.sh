#!/usr/bin/env bash
# Installs the Debian packages scancell builds and tests against, only those missing.
# Uses sudo only when not already root. Safe to run repeatedly.
set -euo pipefail
PKGS=(
  build-essential cmake pkg-config ccache
  libeigen3-dev libembree-dev libassimp-dev libopenmesh-dev libtbb-dev
  libyaml-cpp-dev nlohmann-json3-dev
  libgtest-dev libgmock-dev libbenchmark-dev libpng-dev
  coinor-libcbc-dev liborocos-kdl-dev libfcl-dev libqhull-dev
  libmodbus-dev mbpoll libgpiod-dev libsqlite3-dev zlib1g-dev
  liblcm-dev liblcm-bin iproute2 libsystemd-dev libcli11-dev libnanoflann-dev
  libaravis-dev libusb-1.0-0-dev libopenvdb-dev libboost-dev
  gnuplot-nox
)
# `scripts/deps.sh fuzz` (make fuzz): clang and its libFuzzer runtime as well.
[ "${1:-}" = fuzz ] && PKGS+=(clang libclang-rt-14-dev)
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
if [ ${#missing[@]} -gt 0 ]; then
  echo "deps: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
# LCM telemetry (udpm, ttl=0) needs a multicast route; keep it on the loopback so nothing leaves the host.
if ! ip route show 239.255.0.0/16 2>/dev/null | grep -q "dev lo"; then
  echo "deps: routing 239.255.0.0/16 over lo for LCM"
  $SUDO ip link set lo multicast on || echo "deps: warning: cannot enable multicast on lo"
  $SUDO ip route add 239.255.0.0/16 dev lo || echo "deps: warning: cannot add the LCM multicast route"
fi
