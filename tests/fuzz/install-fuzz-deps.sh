#!/usr/bin/env bash
# Optional dependencies of the fuzz build only (-DMACRO_FUZZ=ON, tests/fuzz/): clang and its
# compiler-rt runtime (libFuzzer, ASan, UBSan). The main build never needs these
# (.ci/install-deps.sh). Idempotent; needs root (or sudo) only when something is missing.
set -euo pipefail
packages=(clang libclang-rt-dev perl)
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
