#!/usr/bin/env bash
# Fresh machine -> dependencies, Release build, the whole test suite (CTest over Catch2).
# Usage: ./test.sh [extra ctest args]
set -euo pipefail
cd "$(dirname "$0")"
bash .ci/install-deps.sh
BUILD=${BUILD_DIR:-build}
cmake -S . -B "$BUILD" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$BUILD" -j"$(nproc)"
cd "$BUILD"
ctest --output-on-failure -j"$(nproc)" --timeout 900 "$@"
