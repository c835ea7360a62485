#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, ASan+UBSan) and runs each for a fixed time with seed corpora
# from the repo's fixtures and /work/shared. Crashes, leaks, timeouts and OOMs are written to
# <build>/fuzz-artifacts/<target>/; copy them to tests/fuzz/regressions/<target>/ (docs/reliability.md).
#
#   tests/fuzz/run_fuzzers.sh [build-dir] [seconds-per-target] [target ...]
#   tests/fuzz/run_fuzzers.sh build-fuzz 60                  # every target, 60 s each
#   tests/fuzz/run_fuzzers.sh build-fuzz 600 scene_ply exr   # two targets, 10 min each
#
# Environment: SHARED (default /work/shared), JOBS (build parallelism, default 2), NO_BUILD=1 to skip
# the build, PARALLEL=n fuzzers at a time (default 1), RSS_LIMIT_MB (default 2048; a larger value
# lets a target run past a known allocation finding). Fuzzers run under `nice -n 19`.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
src="$(cd "$here/../.." && pwd)"
build="$(realpath -m "${1:-$src/build-fuzz}")"
seconds="${2:-60}"
shift 2 2>/dev/null || shift $#
shared="${SHARED:-/work/shared}"
jobs="${JOBS:-2}"

if [ "${NO_BUILD:-0}" != 1 ]; then
  CC=clang CXX=clang++ cmake -S "$src" -B "$build" -DMACRO_FUZZ=ON \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null || exit 1
  nice -n 10 cmake --build "$build" -j"$jobs" --target fuzz_all || exit 1
fi

targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  for f in "$build"/fuzz/fuzz_*; do
    t="$(basename "$f" | sed 's/^fuzz_//')"
    [ "$t" = regressions ] || targets+=("$t")  # the Catch2 replay, not a fuzzer
  done
fi

seeds="$build/fuzz-seeds"
# pack2 A B: the two-file input layout of split_two() in fuzz_targets.h.
pack2() {
  perl -e 'local $/; open A, "<", $ARGV[0] or die; $a = <A>; $a //= "";
           open B, "<", $ARGV[1] or die; $b = <B>; $b //= "";
           binmode STDOUT; print pack("V", length $a) . $a . $b' "$1" "$2"
}
add() {  # add <target> <file> [max-bytes]: copy (truncated) into the seed dir of a target
  local t="$1" f="$2" max="${3:-65536}"
  [ -f "$f" ] || return 0
  mkdir -p "$seeds/$t"
  head -c "$max" "$f" >"$seeds/$t/$(echo "$f" | tr '/' '_')"
}
make_seeds() {
  rm -rf "$seeds"
  mkdir -p "$seeds"
  local tmp="$seeds/.tmp"
  mkdir -p "$tmp"
  # Splat scenes: the tiny metalsplatter files whole, the default scene truncated (header + rows).
  for f in "$shared"/scenes/metalsplatter/*.ply; do
    add scene_ply "$f"
  done
  add scene_ply "$src/data/scenes/default/scene.ply" 4096
  for f in "$shared"/scenes/metalsplatter/*.splat; do add scene_splat "$f"; done
  for f in "$shared"/scenes/metalsplatter/*.spz "$src"/data/fixtures/splat_formats/*.spz; do
    add scene_spz "$f"
  done
  add scene_sog "$src/data/fixtures/splat_formats/tiny.sog"
  add scene_gsplat "$src/data/fixtures/torch/gsplat_ckpt.pt"
  # safetensors: the smallest goldens (header + data), each capped at 64 KiB.
  find "$shared/golden" -name '*.safetensors' -size -300k 2>/dev/null | head -n 6 |
    while read -r f; do add safetensors "$f"; done
  printf '{"w":{"dtype":"F32","shape":[2],"data_offsets":[0,8]}}      ' >"$tmp/shard.h"
  perl -e 'binmode STDOUT; my $h = do { local $/; open H, "<", $ARGV[0]; <H> };
           print pack("Q<", length $h) . $h . pack("f<2", 1.5, -2)' "$tmp/shard.h" \
    >"$tmp/shard.safetensors"
  add safetensors "$tmp/shard.safetensors"
  printf '{"metadata": {"total_size": 8}, "weight_map": {"w": "shard.safetensors"}}' \
    >"$tmp/index.json"
  mkdir -p "$seeds/safetensors_index"
  pack2 "$tmp/index.json" "$tmp/shard.safetensors" >"$seeds/safetensors_index/tiny"
  # Cameras: our JSON list, nerfstudio, DL3DV-Closeup split, COLMAP text and binary.
  for f in "$src"/data/scenes/*/cameras.json "$shared"/golden/raster/*/cameras.json; do
    add cameras_json "$f"
    add cameras_any "$f"
  done
  local pose='[[1,0,0,0.5],[0,1,0,-0.25],[0,0,1,4],[0,0,0,1]]'
  printf '{"w": 64, "h": 48, "fl_x": 50, "fl_y": 51, "cx": 32.5, "cy": 24, "k1": 0.01,
  "camera_model": "OPENCV", "applied_transform": [[0,1,0,0],[1,0,0,0],[0,0,-1,0]],
  "frames": [{"file_path": "images/a.png", "transform_matrix": %s},
             {"file_path": "images/b.png", "fl_x": 60, "transform_matrix": %s}]}' \
    "$pose" "$pose" >"$tmp/transforms.json"
  add nerfstudio "$tmp/transforms.json"
  add cameras_any "$tmp/transforms.json"
  printf '{"scene": "abc", "data_factor": 4, "intrinsics": {"w": 64, "h": 48, "fl_x": 50,
  "fl_y": 51, "cx": 32, "cy": 24, "k1": 0.01, "k2": 0, "p1": 0, "p2": 0, "camera_model": "OPENCV"},
  "training_frames": ["t1.png"], "closeup_frames": ["c1.png"], "closeup_eval_pairs": [
  {"training_frame": "t1.png", "closeup_frame": "c1.png", "depth_ratio": 2.1, "iou": 0.8,
   "angle_deg": 12.6, "pair_score": 2.3}], "closeup_poses": {"c1.png": %s}}' "$pose" \
    >"$tmp/split.json"
  add closeup_split "$tmp/split.json"
  add cameras_any "$tmp/split.json"
  printf '# Camera list\n1 PINHOLE 640 480 500 510 320.5 240.25\n2 OPENCV 64 48 50 50 32 24 0.1 0.01 0 0\n' \
    >"$tmp/cameras.txt"
  printf '# Image list\n7 0 0.70710678118654752 0 -0.70710678118654752 0 0 4 1 side.png\n\n8 1 0 0 0 0.5 0 4 2 front.png\n10 20 -1\n' \
    >"$tmp/images.txt"
  mkdir -p "$seeds/colmap_text" "$seeds/colmap_binary"
  pack2 "$tmp/cameras.txt" "$tmp/images.txt" >"$seeds/colmap_text/rig"
  # COLMAP binary: cameras.bin (u64 n; i32 id, i32 model, u64 w, u64 h, f64 params[]) and
  # images.bin (u64 n; u32 id, f64 q[4], f64 t[3], u32 camera, name\0, u64 n2d, (f64 x, f64 y, i64 id)*).
  perl -e 'binmode STDOUT; print pack("Q< l< l< Q< Q< d<4", 1, 1, 1, 640, 480, 500, 510, 320.5, 240.25)' \
    >"$tmp/cameras.bin"
  perl -e 'binmode STDOUT; print pack("Q< L< d<7 L< Z* Q< d<2 q<", 1, 7, 1, 0, 0, 0, 0.5, 0, 4, 1,
           "front.png", 1, 10, 20, -1)' >"$tmp/images.bin"
  pack2 "$tmp/cameras.bin" "$tmp/images.bin" >"$seeds/colmap_binary/rig"
  # points3D: text (id x y z r g b error (image_id point2d_idx)*) and binary (u64 n; u64 id,
  # f64 xyz[3], u8 rgb[3], f64 error, u64 track length, (i32 image_id, i32 point2d_idx)*).
  printf '# 3D point list\n1 0.5 0.25 3 255 0 0 0.1 7 0 8 1\n2 -1 0 4.5 0 255 9 0.2 7 1\n' \
    >"$tmp/points3D.txt"
  add colmap_points_text "$tmp/points3D.txt"
  perl -e 'binmode STDOUT; print pack("Q< Q< d<3 C3 d< Q< l<4 Q< d<3 C3 d< Q< l<2", 2,
           1, 0.5, 0.25, 3, 255, 0, 0, 0.1, 2, 7, 0, 8, 1,
           2, -1, 0, 4.5, 0, 255, 9, 0.2, 1, 7, 1)' >"$tmp/points3D.bin"
  add colmap_points_binary "$tmp/points3D.bin"
  # Tokenizer: a tiny valid vocab/merges pair, and the real files truncated (64 KiB each).
  printf '{"a": 0, "b": 1, "c": 2, "a</w>": 3, "b</w>": 4, "c</w>": 5, "ab": 6, "ab</w>": 7, "!": 8, "<|startoftext|>": 9, "<|endoftext|>": 10}' \
    >"$tmp/vocab.json"
  printf '#version: 0.2\na b\na b</w>\n' >"$tmp/merges.txt"
  mkdir -p "$seeds/clip_tokenizer" "$seeds/clip_tokenizer_text"
  pack2 "$tmp/vocab.json" "$tmp/merges.txt" >"$seeds/clip_tokenizer/tiny"
  if [ -f "$shared/golden/clip/tokenizer/vocab.json" ]; then
    head -c 30000 "$shared/golden/clip/tokenizer/vocab.json" >"$tmp/vocab_cut.json"
    head -c 30000 "$shared/golden/clip/tokenizer/merges.txt" >"$tmp/merges_cut.txt"
    pack2 "$tmp/vocab_cut.json" "$tmp/merges_cut.txt" >"$seeds/clip_tokenizer/real_truncated"
  fi
  printf 'a photo of a cat' >"$tmp/p1"
  printf 'A &amp;amp; B  caf\xc3\xa9\t\xe2\x9c\x93 ab ab\n 12345 <|endoftext|>' >"$tmp/p2"
  : >"$tmp/empty"
  pack2 "$tmp/empty" "$tmp/p1" >"$seeds/clip_tokenizer_text/p1"
  pack2 "$tmp/empty" "$tmp/p2" >"$seeds/clip_tokenizer_text/p2"
  # Images: the shared PNGs; a small JPEG/BMP/TGA and an EXR if ImageMagick can make them.
  for f in "$shared"/images/*.png; do add image "$f" 1048576; done
  if command -v convert >/dev/null && [ -f "$shared/images/ex_ref.png" ]; then
    for ext in jpg bmp tga; do
      convert "$shared/images/ex_ref.png" -resize 16x16 "$tmp/small.$ext" 2>/dev/null &&
        add image "$tmp/small.$ext"
    done
    convert "$shared/images/ex_ref.png" -resize 8x8 "$tmp/small.exr" 2>/dev/null &&
      add exr "$tmp/small.exr"
  fi
  # PyTorch zip checkpoints (tests/fixtures/make_torch_checkpoints.py).
  for f in "$src"/data/fixtures/torch/*; do add torch_checkpoint "$f"; done
  # Diffusers configs.
  find "$shared/golden" -name config.json 2>/dev/null | while read -r f; do
    add diffusers_config "$f"
  done
  rm -rf "$tmp"
}
make_seeds

summary="$build/fuzz-summary.txt"
echo "# $(date -u +%FT%TZ) ${seconds}s per target" >>"$summary"
run_one() {
  local t="$1"
  local exe="$build/fuzz/fuzz_$t"
  [ -x "$exe" ] || { echo "missing target $exe" >&2; return; }
  corpus="$build/fuzz-corpus/$t"
  artifacts="$build/fuzz-artifacts/$t"
  mkdir -p "$corpus" "$artifacts" "$seeds/$t"
  # Known findings are not seeded: libFuzzer stops at a crashing seed. They are replayed by
  # tests/test_fuzz_regressions.cpp; add them with SEED_REGRESSIONS=1 once fixed.
  if [ "${SEED_REGRESSIONS:-0}" = 1 ]; then
    cp "$src/tests/fuzz/regressions/$t/"* "$seeds/$t/" 2>/dev/null
  fi
  log="$build/fuzz-logs/$t.log"
  mkdir -p "$(dirname "$log")"
  echo "== fuzz_$t: ${seconds}s" >&2
  # -rss_limit_mb: a lying size that allocates gigabytes is a finding (OOM artifact).
  ASAN_OPTIONS="detect_leaks=1:allocator_may_return_null=0" \
  UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1" \
    nice -n 19 "$exe" -max_total_time="$seconds" -timeout=10 -rss_limit_mb="${RSS_LIMIT_MB:-2048}" \
    -max_len=65536 -print_final_stats=1 -artifact_prefix="$artifacts/" \
    "$corpus" "$seeds/$t" >"$log" 2>&1
  rc=$?
  execs=$(grep -m1 'stat::number_of_executed_units' "$log" | awk '{print $2}')
  cov=$(grep -E '^#[0-9]+' "$log" | tail -1 | grep -oE 'cov: [0-9]+' | awk '{print $2}')
  found=$(find "$artifacts" -type f | wc -l)
  printf '%-22s %6ss  rc=%-3s execs=%-10s cov=%-6s artifacts=%s\n' \
    "$t" "$seconds" "$rc" "${execs:-?}" "${cov:-?}" "$found" | tee -a "$summary"
}
# PARALLEL=n runs n fuzzers at a time (each still under nice -n 19); default one at a time.
parallel="${PARALLEL:-1}"
for t in "${targets[@]}"; do
  while [ "$(jobs -rp | wc -l)" -ge "$parallel" ]; do sleep 1; done
  run_one "$t" &
done
wait
echo "summary: $summary; logs: $build/fuzz-logs; artifacts: $build/fuzz-artifacts" >&2
