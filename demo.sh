#!/usr/bin/env bash
# Fresh machine -> dependencies, Release build, then the main job on the embedded real scene
# (data/scenes/buddha: real photos, a 3DGS that macro train made from the 3 far photos, shipped as
# .spz, and the real close-up photos as ground truth):
#   1. render the close-up on the CPU: colour PNG, EXR (R,G,B,A,depth,invdepth), inverse depth PNG;
#   2. plan MACRO (reference selection, depth planes, scale-matched crops, attention masks);
#   3. enhance it with the weight-free transfer enhancer (no downloaded weights needed), and write
#      a captioned side-by-side figure: render | enhanced | real close-up photo, each with its
#      PSNR/SSIM against the photo, and two framed regions magnified under each panel.
# Usage: ./demo.sh [close-up]   00006.png (default), 00049.png, 00055.png
#        ./demo.sh synthclose [close-up]   the same on the synthetic demo scene
#        (data/scenes/synthclose, exact ground truth; closeup.png 1.5x, closeup_01.png 4.5x
#        (default), closeup_02.png 6x)
# Environment: BUILD_DIR (default build), OUT_DIR (default out).
set -euo pipefail
cd "$(dirname "$0")"
bash .ci/install-deps.sh
BUILD=${BUILD_DIR:-build}
OUT=${OUT_DIR:-out}
if [ "${1:-}" = synthclose ]; then
  SCENE=data/scenes/synthclose
  SPLAT="$SCENE/scene.spz"
  FRAME=${2:-closeup_01.png}
  INSETS=(--zoom-inset 300,150,60,40 --zoom-inset 480,240,50,40)
  KIND="synthetic SynthClose scene, see $SCENE/README.md"
  GT="ground truth"
else
  [ "${1:-}" = buddha ] && shift
  SCENE=data/scenes/buddha
  SPLAT="$SCENE/scene.spz"
  FRAME=${1:-00006.png}
  INSETS=(--zoom-inset 220,20,90,60 --zoom-inset 330,200,80,60)
  KIND="real photos (AliceVision Buddha, CC BY 4.0), see $SCENE/README.md"
  GT="real close-up photo"
fi
NAME=${FRAME%.png}
cmake -S . -B "$BUILD" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$BUILD" -j"$(nproc)" --target macro
mkdir -p "$OUT"
M="$BUILD/macro"
"$M" render --scene "$SPLAT" --cameras "$SCENE/split.json" --camera "$FRAME" \
  --out-png "$OUT/$NAME-render.png" --out-exr "$OUT/$NAME-render.exr" \
  --out-depth-png "$OUT/$NAME-invdepth.png"
"$M" plan --scene-dir "$SCENE" --closeup "$FRAME" --out "$OUT/$NAME-plan.json"
"$M" enhance --scene-dir "$SCENE" --closeup "$FRAME" --enhancer transfer \
  --out "$OUT/$NAME-enhanced.png" --side-by-side "$OUT/$NAME-side-by-side.png" "${INSETS[@]}"
echo
echo "against the $GT ($SCENE/closeup_gt/$FRAME):"
for f in render enhanced; do
  # PSNR and SSIM only: LPIPS, DINOv2 and DreamSim need weights that are not shipped.
  printf "  %-9s %s\n" "$f:" "$("$M" metrics --pred "$OUT/$NAME-$f.png" --gt "$SCENE/closeup_gt/$FRAME" \
    --quiet | grep -E '^(psnr|ssim):' | tr '\n' ' ')"
done
echo
echo "scene:        $SCENE ($KIND)"
echo "render:       $OUT/$NAME-render.png, $OUT/$NAME-render.exr, $OUT/$NAME-invdepth.png"
echo "plan:         $OUT/$NAME-plan.json"
echo "enhanced:     $OUT/$NAME-enhanced.png"
echo "side by side: $OUT/$NAME-side-by-side.png  (render | enhanced | $GT, captioned, 2 insets)"
