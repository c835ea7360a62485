#!/usr/bin/env bash
# Fresh machine -> dependencies, Release build, then a CPU render of the embedded default scene's
# close-up into out/: colour PNG, EXR (R,G,B,A,depth,invdepth floats) and colour-mapped inverse depth.
# Usage: ./demo.sh [camera]   (default: closeup; cameras are listed in data/scenes/default/README.md)
# Environment: BUILD_DIR (default build), OUT_DIR (default out).
set -euo pipefail
cd "$(dirname "$0")"
bash .ci/install-deps.sh
BUILD=${BUILD_DIR:-build}
OUT=${OUT_DIR:-out}
CAMERA=${1:-closeup}
SCENE=data/scenes/default
cmake -S . -B "$BUILD" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$BUILD" -j"$(nproc)" --target macro
mkdir -p "$OUT"
"$BUILD/macro" render --scene "$SCENE/scene.ply" --cameras "$SCENE/cameras.json" --camera "$CAMERA" \
  --out-png "$OUT/$CAMERA.png" --out-exr "$OUT/$CAMERA.exr" \
  --out-depth-png "$OUT/$CAMERA-invdepth.png"
echo
echo "scene:   $SCENE (synthetic, see $SCENE/README.md)"
echo "colour:  $OUT/$CAMERA.png"
echo "floats:  $OUT/$CAMERA.exr  (channels R,G,B colour; A alpha; depth = depth_sum/alpha; invdepth = sum w/z)"
echo "depth:   $OUT/$CAMERA-invdepth.png  (inverse depth, bright = near)"
