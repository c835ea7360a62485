#!/usr/bin/env bash
# Installs the build dependencies from Debian's packages. Idempotent: does nothing when all are
# present. Needs root (or sudo) only when something is missing.
set -euo pipefail
packages=(cmake g++ make libeigen3-dev libglm-dev libstb-dev libopenexr-dev catch2 zlib1g-dev
          nlohmann-json3-dev ccache libopencv-dev libzstd-dev libwebp-dev pkg-config
          libcairo2-dev fonts-dejavu-core libcpp-httplib-dev
          chromium)  # chromium: the viewer's browser test (tests/test_view_browser.cpp)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
echo "installing: ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
