#!/usr/bin/env bash
# Installs the Debian packages scancell builds and tests against, only those missing.
# Uses sudo only when not already root. Safe to run repeatedly.
set -euo pipefail
PKGS=(
  build-essential cmake pkg-config ccache
  libeigen3-dev libembree-dev libassimp-dev libopenmesh-dev libtbb-dev
  libyaml-cpp-dev nlohmann-json3-dev
  libgtest-dev libgmock-dev libbenchmark-dev libpng-dev
  coinor-libcbc-dev liborocos-kdl-dev libfcl-dev
  libmodbus-dev mbpoll libgpiod-dev libsqlite3-dev zlib1g-dev
)
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
echo "deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
