// bench winograd: bf16 (or, with --f32, fp32) 3x3 stride-1 conv, Winograd F(2x2, 3x3) against
// the direct implicit GEMM of the same type (the baseline), same weights, same run, runs
// interleaved (direct, Winograd, direct, ...) so a busy neighbour hits both alike; medians of
// wall and process CPU time.
//
//   bench winograd [--threads N] [--reps R] [--quick] [--only SUBSTR] [--chunk TILES] [--f32]
//                  [--wino-only]
// --wino-only runs the Winograd conv alone (no direct baseline; for profiling it with perf).
// Shapes: the Difix VAE's 3x3 convs at 960x536 and the SD-Turbo U-Net's at its 120x67 latent.
// --quick crops the spatial sizes by 4 per side. GFLOP/s are the direct conv's FLOP per second
// (2 Cin Cout 9 per pixel) for both, so the columns compare directly; "best w" is the fastest
// Winograd run (ms: on a busy VM the least disturbed one).
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "attention/runtime/conv.h"
#include "attention/runtime/cpu.h"
#include "bench_registry.h"

namespace macro::bench {
namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

int run(int argc, char** argv) {
  int threads = ThreadPool::global().size();
  int reps = 5;
  bool quick = false;
  std::string only;
  size_t chunk = 0;
  bool f32 = false, wino_only = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--threads") && i + 1 < argc)
      threads = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--reps") && i + 1 < argc)
      reps = std::max(1, std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--quick"))
      quick = true;
    else if (!std::strcmp(argv[i], "--only") && i + 1 < argc)
      only = argv[++i];
    else if (!std::strcmp(argv[i], "--chunk") && i + 1 < argc)
      chunk = size_t(std::atoll(argv[++i]));
    else if (!std::strcmp(argv[i], "--f32"))
      f32 = true;
    else if (!std::strcmp(argv[i], "--wino-only"))
      wino_only = true;
    else {
      std::fprintf(stderr,
                   "usage: bench winograd [--threads N] [--reps R] [--quick] [--only SUBSTR] "
                   "[--chunk TILES] [--f32] [--wino-only]\n");
      return 2;
    }
  }
  ThreadPool local(threads);
  ThreadPool* pool = threads > 1 ? &local : nullptr;
  struct C {
    int64_t c, h, w;
    const char* what;
  };
  const std::vector<C> convs = {
      {128, 536, 960, "VAE 128ch"},   {256, 268, 480, "VAE 256ch"}, {512, 134, 240, "VAE 512ch"},
      {512, 67, 120, "VAE 512ch lo"}, {320, 67, 120, "UNet 320ch"}, {640, 34, 60, "UNet 640ch"},
      {1280, 17, 30, "UNet 1280ch"},
  };
  std::printf("%s conv 3x3 s1 p1, Winograd F(2x2,3x3) vs direct; isa %s, threads %d, reps %d%s\n",
              f32 ? "fp32" : "bf16", isa_name(active_isa()), threads, reps,
              quick ? " [--quick: spatial sizes / 4 per side]" : "");
  std::printf("  %-14s %-16s %10s %10s %8s | %9s %9s %8s | %7s %7s | %7s\n", "layer", "shape",
              "direct ms", "wino ms", "ratio", "direct cpu", "wino cpu", "ratio", "GF/s d",
              "GF/s w", "best w");
  const size_t old_chunk = conv2d_set_winograd_chunk(chunk);
  for (C cv : convs) {
    if (!only.empty() && std::string(cv.what).find(only) == std::string::npos) continue;
    if (quick) {
      cv.h = std::max<int64_t>(8, cv.h / 4);
      cv.w = std::max<int64_t>(8, cv.w / 4);
    }
    const Conv2dShape s = Conv2dShape::make(1, cv.c, cv.h, cv.w, cv.c, 3, 1, 1);
    auto x = random_vec(size_t(s.c_in * s.h * s.w), 6);
    auto w = random_vec(size_t(s.c_out * s.c_in * 9), 7);
    auto b = random_vec(size_t(s.c_out), 8);
    LineVec y(size_t(s.c_out * s.out_h() * s.out_w()));
    const ConvWinograd old = conv2d_set_winograd(ConvWinograd::kAlways);  // packs for any shape
    const ConvWeights cw = ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, 3, 3,
                                             f32 ? WeightType::kF32 : WeightType::kBf16);
    auto once = [&](ConvWinograd m) {
      conv2d_set_winograd(m);
      const double w0 = now_seconds(), c0 = cpu_seconds();
      conv2d(s, x.data(), cw, nullptr, y.data(), pool);
      return Timing{now_seconds() - w0, cpu_seconds() - c0};
    };
    if (!wino_only) once(ConvWinograd::kOff);  // warm-up both
    once(ConvWinograd::kAlways);
    std::vector<double> dw, dc, ww, wc;
    for (int r = 0; r < reps; ++r) {
      const Timing d = wino_only ? Timing{} : once(ConvWinograd::kOff);
      const Timing v = once(ConvWinograd::kAlways);
      dw.push_back(d.wall), dc.push_back(d.cpu), ww.push_back(v.wall), wc.push_back(v.cpu);
    }
    conv2d_set_winograd(old);
    const double flop = 2.0 * double(s.out_h()) * s.out_w() * s.c_in * s.c_out * 9;
    char shape[64];
    std::snprintf(shape, sizeof shape, "C%ld %ldx%ld", long(cv.c), long(cv.w), long(cv.h));
    const double mdw = median(dw), mww = median(ww), mdc = median(dc), mwc = median(wc);
    const double best = *std::min_element(ww.begin(), ww.end()) * 1e3;
    if (wino_only)  // no direct runs: dashes, not ratios against zero
      std::printf("  %-14s %-16s %10s %10.2f %8s | %9s %9.2f %8s | %7s %7.1f | %7.2f\n", cv.what,
                  shape, "-", mww * 1e3, "-", "-", mwc * 1e3, "-", "-", flop / mww * 1e-9, best);
    else
      std::printf("  %-14s %-16s %10.2f %10.2f %7.2fx | %9.2f %9.2f %7.2fx | %7.1f %7.1f | %7.2f\n",
                  cv.what, shape, mdw * 1e3, mww * 1e3, mdw / mww, mdc * 1e3, mwc * 1e3, mdc / mwc,
                  flop / mdw * 1e-9, flop / mww * 1e-9, best);
    std::fflush(stdout);
  }
  conv2d_set_winograd_chunk(old_chunk);
  return 0;
}

const bool registered = register_benchmark(
    {"winograd",
     "bf16 or fp32 3x3 conv: Winograd F(2x2,3x3) vs the direct implicit GEMM, VAE/U-Net shapes",
     run});

}  // namespace
}  // namespace macro::bench
