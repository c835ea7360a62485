#!/usr/bin/env bash
# CI sanitizer job: an ASan+UBSan build (-DMACRO_SANITIZE=ON, g++) running the stated subset of the
# tests that handles untrusted input, so it fits the CI budget beside the normal run (./test.sh).
# Any sanitizer report fails the job (-fno-sanitize-recover=undefined; ASan aborts on its first).
#
#   .ci/sanitize.sh                 # build in build-sanitize/, run the subset
#   BUILD_DIR=build-x JOBS=2 .ci/sanitize.sh
#
# Subset (Catch2 tags; docs/reliability.md says why): the parsers and their error paths —
# [formats] scene files, [cameras] camera files, [image_io] images, [runtime] safetensors / files /
# tensors / threads, [tokenizer] CLIP tokenizer, [config] diffusers configs, [weights] checkpoint
# loading, [fuzz] the fuzz regressions, [bad_inputs] the bad-input corpus through the CLI (the
# `macro` binary is built with the same sanitizers), [nn-run] the TAESD CLI; and the small
# kernels behind them, [kernels] and [ops]; [vit] the ViT loader and small forwards (DINOv2 /
# DreamSim), [mem] the VAE's banded full-resolution level (halo rows, in-place bands), [pairs]
# points3D and pair construction, [composite] composite views and masks, [attention] the fused
# attention (fp32 and bf16 kernels and their scalar twins), [winograd] the Winograd bf16 and fp32 conv,
# [pth] PyTorch checkpoints, [pft] the PFT-SR network, [zip] the zip writer, [undistort] lens
# undistortion of camera files and images, [view] the viewer's HTTP API (bad requests; the
# browser test, [browser], stays in the normal run), [train_fast] the trainer's float kernels (the
# 16-lane projection and blend with their hand-indexed buffers) against their twin. The networks' golden
# tests and the end-to-end enhance/bench/render tests stay in the normal run (minutes each under
# ASan).
set -euo pipefail
cd "$(dirname "$0")/.."
bash .ci/install-deps.sh
BUILD=${BUILD_DIR:-build-sanitize}
JOBS=${JOBS:-$(nproc)}
SUBSET=${SANITIZE_TESTS:-"[formats],[cameras],[image_io],[runtime],[tokenizer],[config],[weights],[fuzz],[bad_inputs],[nn-run],[kernels],[ops],[vit],[mem],[pairs],[composite],[attention],[winograd],[pth],[pft],[zip],[undistort],[view]~[browser],[train_fast]"}
t0=$(date +%s)
cmake -S . -B "$BUILD" -DCMAKE_BUILD_TYPE=Release -DMACRO_SANITIZE=ON >/dev/null
cmake --build "$BUILD" -j"$JOBS" --target macro macro_tests
t1=$(date +%s)
# halt_on_error: the first report fails the run; detect_leaks: LeakSanitizer too (where ptrace
# allows it; harmless elsewhere).
export ASAN_OPTIONS=${ASAN_OPTIONS:-halt_on_error=1:abort_on_error=1:detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1}
# Third-party caches that live until exit by design (.ci/lsan.supp says which and why).
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$PWD/.ci/lsan.supp}
export MACRO_QUIET=1
"$BUILD/macro_tests" "$SUBSET"
t2=$(date +%s)
echo "sanitize: build $((t1 - t0)) s, tests $((t2 - t1)) s (subset $SUBSET)"
