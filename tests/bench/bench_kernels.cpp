// bench kernels: GEMM (fp32, bf16) at U-Net Linear shapes and conv2d 3x3 at VAE shapes, as GFLOP/s
// and as a fraction of the machine's own peak measured in the same run (an FMA loop, a bf16
// dot-product loop, an AMX loop when present), plus the scalar twin on one shape for the ratio.
//
//   bench kernels [--threads N] [--reps R] [--quick] [--no-conv] [--no-gemm] [--only SUBSTR]
// --quick crops the conv inputs (the full 512x512 / 536x960 layers take seconds each).
#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "attention/runtime/conv.h"
#include "attention/runtime/cpu.h"
#include "attention/runtime/gemm.h"
#include "attention/runtime/kernels.h"
#include "attention/runtime/ops.h"
#include "bench_registry.h"

namespace macro::bench {
namespace {

// The machine is shared with builds, so every measurement records both the wall time and the
// process CPU time (all threads); rates per CPU-second show the kernels' efficiency on the cores
// they actually got, rates per wall-second what a user would see. Both are medians.
// GFLOP/s of a probe loop run on every thread of `pool` at once (nullptr: the calling thread),
// 2M iterations per thread.
Rate probe_peak(double (*probe)(int64_t), ThreadPool* pool, int reps) {
  return probe_rate(probe, pool, 2000000, reps);
}

struct Peaks {
  Rate fma, bf16, amx;
};

// Runs fn `reps` times between two short runs of the matching peak probe (so the ratio compares
// against the machine as it was at that moment: it is shared with builds) and prints
// wall: GFLOP/s and % of the wall peak of the same thread count; cpu: GFLOP per CPU-second and %
// of the per-CPU-second peak.
std::string g_only;  // --only SUBSTR: run the rows whose name contains SUBSTR

Timing row(const char* what, const std::string& shape, double flop, int reps,
           const std::function<void()>& fn, double (*probe)(int64_t), ThreadPool* pool) {
  if (!g_only.empty() && std::string(what).find(g_only) == std::string::npos) return {};
  const Rate p0 = probe_peak(probe, pool, 3);
  const Timing t = median_timing(reps, fn);
  const Rate p1 = probe_peak(probe, pool, 3);
  const Rate peak{0.5 * (p0.wall + p1.wall), 0.5 * (p0.cpu + p1.cpu)};
  const int threads = pool ? pool->size() : 1;
  const double gw = flop / t.wall * 1e-9, gc = flop / t.cpu * 1e-9;
  std::printf(
      "  %-34s %-17s thr %d %9.2f ms %7.1f GFLOP/s %5.1f%% | cpu %7.1f GFLOP/cpu-s %5.1f%%"
      " | peak %6.1f\n",
      what, shape.c_str(), threads, t.wall * 1e3, gw, 100.0 * gw / peak.wall, gc,
      100.0 * gc / peak.cpu, peak.wall);
  return t;
}

int run(int argc, char** argv) {
  int threads = ThreadPool::global().size();
  int reps = 7;
  bool quick = false, do_conv = true, do_gemm = true;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--threads") && i + 1 < argc)
      threads = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--reps") && i + 1 < argc)
      reps = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--quick"))
      quick = true;
    else if (!std::strcmp(argv[i], "--only") && i + 1 < argc)
      g_only = argv[++i];
    else if (!std::strcmp(argv[i], "--no-conv"))
      do_conv = false;
    else if (!std::strcmp(argv[i], "--no-gemm"))
      do_gemm = false;
    else {
      std::fprintf(stderr, "bench kernels: unknown flag '%s'\n", argv[i]);
      return 2;
    }
  }
  ThreadPool::set_global_threads(threads);
  ThreadPool* pool = threads > 1 ? &ThreadPool::global() : nullptr;
  const KernelTable& kt = kernels();
  std::printf("kernels: f32 %s, bf16 %s; threads %d; medians of %d runs\n", kt.f32.name,
              kt.bf16.name, threads, reps);

  // ---- peaks, same run ----
  Peaks peak1, peakN;
  peak1.fma = probe_peak(kt.probe_fma, nullptr, 5);
  peakN.fma = probe_peak(kt.probe_fma, pool, 5);
  peak1.bf16 = probe_peak(kt.probe_bf16, nullptr, 5);
  peakN.bf16 = probe_peak(kt.probe_bf16, pool, 5);
  std::printf(
      "peak fp32 FMA loop: %.1f GFLOP/s (1 thread), %.1f GFLOP/s (%d threads); "
      "%.1f GFLOP/cpu-s\n",
      peak1.fma.wall, peakN.fma.wall, threads, peakN.fma.cpu);
  std::printf(
      "peak bf16 dot loop: %.1f GFLOP/s (1 thread), %.1f GFLOP/s (%d threads); "
      "%.1f GFLOP/cpu-s%s\n",
      peak1.bf16.wall, peakN.bf16.wall, threads, peakN.bf16.cpu,
      isa_supported(Isa::kAvx512Bf16) ? "" : " (no native bf16: FMA loop)");
  if (isa_supported(Isa::kAmx)) {
    peakN.amx = probe_peak(kernels_for(Isa::kAmx).probe_bf16, pool, 5);
    std::printf("peak AMX loop: %.1f GFLOP/s (%d threads)\n", peakN.amx.wall, threads);
  } else {
    std::printf("peak AMX loop: not available (no AMX on this CPU)\n");
  }
  double (*bf16_probe)(int64_t) =
      kt.bf16.layout == PackLayout::kBf16Amx ? kernels_for(Isa::kAmx).probe_bf16 : kt.probe_bf16;

  {
    // The micro-kernels alone on cache-resident panels (one thread): the ceiling for everything
    // below. 64 calls over K = 256 per timing.
    std::printf("\nmicro-kernels, panels in L1/L2, 1 thread:\n");
    for (const GemmKernel* gk : {&kt.f32, &kt.bf16}) {
      const int64_t kc = 256;
      LineVec a(size_t(gk->mr * kc), 0.5f), b(size_t(gk->nr * kc), 0.25f);
      LineVec c(size_t(gk->mr * gk->nr));
      if (gk->layout != PackLayout::kF32) {
        std::fill(a.begin(), a.end(), 0.0f);
        std::fill(b.begin(), b.end(), 0.0f);
      }
      MicroTile t;
      t.kc = kc;
      t.a = a.data();
      t.b = b.data();
      t.c = c.data();
      t.ldc = gk->nr;
      t.m = gk->mr;
      t.n = gk->nr;
      const double flop = 2.0 * gk->mr * gk->nr * kc * 1000;
      row(
          gk->name, "1000 calls K256", flop, reps,
          [&] {
            for (int i = 0; i < 1000; ++i) gk->micro(t);
          },
          gk == &kt.f32 ? kt.probe_fma : bf16_probe, nullptr);
    }
  }

  if (do_gemm) {
    // U-Net Linear shapes [M tokens, K in, N out] (docs/spec/difix-spec.md §4.3, §4.4; 512x512 ->
    // L0 4096 tokens, 536x960 -> 8040).
    struct G {
      int64_t m, k, n;
      const char* what;
    };
    const G shapes[] = {
        {4096, 320, 320, "L0 q/k/v/o, proj (C=320)"},
        {4096, 320, 2560, "L0 ff.net.0 (GEGLU 8C)"},
        {4096, 1280, 320, "L0 ff.net.2 (4C->C)"},
        {1024, 640, 640, "L1 q/k/v/o (C=640)"},
        {1024, 640, 5120, "L1 ff.net.0"},
        {1024, 2560, 640, "L1 ff.net.2"},
        {256, 1280, 1280, "L2 q/k/v/o (C=1280)"},
        {8040, 320, 320, "L0 q/k/v/o at 536x960"},
        {8040, 320, 2560, "L0 ff.net.0 at 536x960"},
        {2040, 640, 5120, "L1 ff.net.0 at 536x960"},
    };
    std::printf("\nGEMM, packed weights (Linear y = x W^T + b):\n");
    for (const G& g : shapes) {
      auto x = random_vec(size_t(g.m * g.k), 1);
      auto w = random_vec(size_t(g.n * g.k), 2);
      // The scale of trained weights (std 1/sqrt(K)): the outputs are then of order 1, as the
      // GEGLU rows need (gates of +-10 and beyond drive GELU's tail into denormals).
      for (float& v : w) v *= float(std::sqrt(3.0 / double(g.k)));
      auto b = random_vec(size_t(g.n), 3);
      LineVec y(size_t(g.m * g.n));
      GemmParams p;
      p.bias_n = b.data();
      const double flop = 2.0 * double(g.m) * g.n * g.k;
      char shape[64];
      std::snprintf(shape, sizeof shape, "M%ld K%ld N%ld", long(g.m), long(g.k), long(g.n));
      PackedWeights w32 = PackedWeights::pack(w.data(), g.n, g.k, g.k, WeightType::kF32);
      row((std::string("f32  ") + g.what).c_str(), shape, flop, reps,
          [&] { gemm_packed(g.m, x.data(), g.k, w32, y.data(), g.n, p, pool); }, kt.probe_fma,
          pool);
      PackedWeights w16 = PackedWeights::pack(w.data(), g.n, g.k, g.k, WeightType::kBf16);
      row((std::string("bf16 ") + g.what).c_str(), shape, flop, reps,
          [&] { gemm_packed(g.m, x.data(), g.k, w16, y.data(), g.n, p, pool); }, bf16_probe, pool);
      if (std::string(g.what).find("ff.net.0") != std::string::npos) {
        // The same projection then geglu() over memory (the baseline), and with the GEMM's GEGLU
        // epilogue (rows permuted at pack time; the [M, N] product stays in cache).
        LineVec h(size_t(g.m * g.n / 2));
        row((std::string("bf16 ") + g.what + " + geglu()").c_str(), shape, flop, reps,
            [&] {
              gemm_packed(g.m, x.data(), g.k, w16, y.data(), g.n, p, pool);
              geglu(h.data(), y.data(), g.m, g.n / 2, pool);
            },
            bf16_probe, pool);
        const int group = 64;
        std::vector<float> wp(w.size()), bp(b.size());
        for (int64_t r = 0; r < g.n; ++r) {
          const int64_t src = geglu_source_row(r, g.n, group);
          std::copy_n(w.begin() + src * g.k, g.k, wp.begin() + r * g.k);
          bp[size_t(r)] = b[size_t(src)];
        }
        PackedWeights wg = PackedWeights::pack(wp.data(), g.n, g.k, g.k, WeightType::kBf16);
        GemmParams pg;
        pg.bias_n = bp.data();
        pg.geglu_group = group;
        row((std::string("bf16 ") + g.what + " GEGLU epilogue").c_str(), shape, flop, reps,
            [&] { gemm_packed(g.m, x.data(), g.k, wg, h.data(), g.n / 2, pg, pool); }, bf16_probe,
            pool);
      }
    }
    {
      // Unpacked B (both operands packed per call), and the scalar twin for the ratio.
      const int64_t m = 1024, k = 640, n = 640;
      auto a = random_vec(size_t(m * k), 4);
      auto bm = random_vec(size_t(n * k), 5);
      LineVec c(size_t(m * n));
      GemmParams p;
      p.trans_b = true;
      const double flop = 2.0 * double(m) * n * k;
      std::printf("\nGEMM, unpacked operands, and the scalar twin (baseline):\n");
      auto call = [&] { gemm_f32(m, n, k, a.data(), k, bm.data(), k, c.data(), n, p, pool); };
      const Timing t =
          row("f32 gemm_f32 trans_b", "M1024 K640 N640", flop, reps, call, kt.probe_fma, pool);
      const Isa saved = active_isa();
      (void)set_isa(Isa::kScalar);
      const Timing ts = row("f32 gemm_f32 trans_b, SCALAR twin", "M1024 K640 N640", flop, 3, call,
                            kt.probe_fma, pool);
      if (saved != Isa::kAvx2 && isa_supported(Isa::kAvx2)) {
        // The AVX2 path (6x16 fp32 tiles, 256-bit FMAs), a second same-run baseline.
        (void)set_isa(Isa::kAvx2);
        const Timing t2 = row("f32 gemm_f32 trans_b, AVX2 path", "M1024 K640 N640", flop, reps,
                              call, kt.probe_fma, pool);
        if (t.wall > 0 && t2.wall > 0)
          std::printf("  speed-up of %s over the AVX2 path: %.2fx (wall), %.2fx (cpu)\n",
                      isa_name(saved), t2.wall / t.wall, t2.cpu / t.cpu);
      }
      (void)set_isa(saved);
      if (t.wall > 0 && ts.wall > 0)
        std::printf("  speed-up of %s over the scalar twin: %.1fx (wall), %.1fx (cpu)\n",
                    isa_name(saved), ts.wall / t.wall, ts.cpu / t.cpu);
    }
  }

  if (do_conv) {
    // VAE conv 3x3 layers [Cin=Cout, H x W]; --quick crops the spatial size.
    struct C {
      int64_t c, h, w;
      int stride, pt, pl, pb, pr;
      int k;
      const char* what;
    };
    std::vector<C> convs = {
        {128, 512, 512, 1, 1, 1, 1, 1, 3, "VAE 128ch 3x3 @512x512"},
        {256, 256, 256, 1, 1, 1, 1, 1, 3, "VAE 256ch 3x3 @256x256"},
        {512, 128, 128, 1, 1, 1, 1, 1, 3, "VAE 512ch 3x3 @128x128"},
        {512, 64, 64, 1, 1, 1, 1, 1, 3, "VAE 512ch 3x3 @64x64"},
        {128, 536, 960, 1, 1, 1, 1, 1, 3, "VAE 128ch 3x3 @536x960"},
        {512, 134, 240, 1, 1, 1, 1, 1, 3, "VAE 512ch 3x3 @134x240"},
        {256, 256, 256, 2, 0, 0, 1, 1, 3, "VAE enc downsample 256ch s2"},
        {128, 536, 960, 2, 0, 0, 1, 1, 3, "VAE enc downsample 128ch s2 @536x960"},
        {320, 67, 120, 2, 1, 1, 1, 1, 3, "UNet downsample 320ch s2 @67x120"},
        {512, 128, 128, 1, 0, 0, 0, 0, 1, "1x1 512ch @128x128"},
        // U-Net resnet convs at a 512x512 image (64x64 latent) and the 536x960 close-up.
        {320, 64, 64, 1, 1, 1, 1, 1, 3, "UNet 320ch 3x3 @64x64"},
        {640, 32, 32, 1, 1, 1, 1, 1, 3, "UNet 640ch 3x3 @32x32"},
        {1280, 16, 16, 1, 1, 1, 1, 1, 3, "UNet 1280ch 3x3 @16x16"},
        {1280, 8, 8, 1, 1, 1, 1, 1, 3, "UNet 1280ch 3x3 @8x8"},
        {320, 67, 120, 1, 1, 1, 1, 1, 3, "UNet 320ch 3x3 @67x120"},
    };
    std::printf("\nconv2d (NCHW, implicit GEMM; fp32, and bf16 weights+activations)%s:\n",
                quick ? " [--quick: spatial sizes cropped by 4x per side]" : "");
    for (C cv : convs) {
      if (quick) {
        cv.h = std::max<int64_t>(16, cv.h / 4);
        cv.w = std::max<int64_t>(16, cv.w / 4);
      }
      Conv2dShape s;
      s.n = 1, s.c_in = cv.c, s.h = cv.h, s.w = cv.w, s.c_out = cv.c, s.kh = s.kw = cv.k;
      s.stride = cv.stride;
      s.pad_top = cv.pt, s.pad_left = cv.pl, s.pad_bottom = cv.pb, s.pad_right = cv.pr;
      auto x = random_vec(size_t(s.c_in * s.h * s.w), 6);
      auto w = random_vec(size_t(s.c_out * s.c_in * s.kh * s.kw), 7);
      auto b = random_vec(size_t(s.c_out), 8);
      LineVec y(size_t(s.c_out * s.out_h() * s.out_w()));
      ConvWeights cw = ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, s.kh, s.kw);
      ConvWeights cw16 =
          ConvWeights::pack(w.data(), b.data(), s.c_out, s.c_in, s.kh, s.kw, WeightType::kBf16);
      const double flop = 2.0 * double(s.out_h()) * s.out_w() * s.c_in * s.c_out * s.kh * s.kw;
      const int r = flop > 5e10 ? std::max(3, reps / 2) : reps;
      char shape[64];
      std::snprintf(shape, sizeof shape, "C%ld %ldx%ld s%d", long(cv.c), long(cv.h), long(cv.w),
                    cv.stride);
      row((std::string("f32  ") + cv.what).c_str(), shape, flop, r,
          [&] { conv2d(s, x.data(), cw, nullptr, y.data(), pool); }, kt.probe_fma, pool);
      row((std::string("bf16 ") + cv.what).c_str(), shape, flop, r,
          [&] { conv2d(s, x.data(), cw16, nullptr, y.data(), pool); }, bf16_probe, pool);
    }
  }
  return 0;
}

const bool registered = register_benchmark(
    {"kernels", "GEMM fp32/bf16 and conv2d vs the measured FMA/bf16 peak and the scalar twin",
     run});

}  // namespace
}  // namespace macro::bench
