// bench winograd: bf16 (or, with --f32, fp32) 3x3 stride-1 conv, Winograd F(2x2, 3x3) against
// the direct implicit GEMM of the same type (the baseline), same weights, same run, runs
// interleaved (direct, Winograd, direct, ...) so a busy neighbour hits both alike; medians of
// wall and process CPU time.
//
//   bench winograd [--threads N] [--reps R] [--quick] [--only SUBSTR] [--chunk TILES] [--f32]
//                  [--wino-only]
//   bench winograd --tile-error [--only SUBSTR]
// --wino-only runs the Winograd conv alone (no direct baseline; for profiling it with perf).
// --tile-error measures accuracy, not time: the rms error against the exact (fp64) conv of the
// engine's bf16 convs (direct and Winograd F(2x2, 3x3), through conv2d) and of a model of bf16
// Winograd F(m x m, 3 x 3) for larger tiles (m = 3, 4; Toom-Cook transforms from interpolation
// points), which is why the bf16 path keeps 2 x 2 tiles.
// Shapes: the Difix VAE's 3x3 convs at 960x536 and the SD-Turbo U-Net's at its 120x67 latent.
// --quick crops the spatial sizes by 4 per side. GFLOP/s are the direct conv's FLOP per second
// (2 Cin Cout 9 per pixel) for both, so the columns compare directly; "best w" is the fastest
// Winograd run (ms: on a busy VM the least disturbed one).
#include <algorithm>
#include <cmath>
#include <cstdint>
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

float bf16_round(float f) {  // nearest even, as the engine's bf16 rounding (finite values)
  uint32_t u;
  std::memcpy(&u, &f, 4);
  u = (u + 0x7fffu + ((u >> 16) & 1u)) & 0xffff0000u;
  std::memcpy(&f, &u, 4);
  return f;
}

// The 1-D Toom-Cook transforms of F(m, 3) from m + 1 finite interpolation points (and infinity):
// y = A^T [(G g) . (B^T d)] for a tile of m outputs from a = m + 2 inputs.
struct TileTransforms {
  int m = 0, a = 0;
  std::vector<double> bt, g, at;  // [a][a], [a][3], [m][a]
};

TileTransforms toom_cook(const std::vector<double>& p) {
  TileTransforms t;
  const int np = int(p.size()), a = np + 1, m = a - 2;
  t.m = m, t.a = a;
  t.bt.assign(size_t(a * a), 0.0), t.g.assign(size_t(a * 3), 0.0), t.at.assign(size_t(m * a), 0.0);
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < np; ++j) t.at[size_t(i * a + j)] = std::pow(p[size_t(j)], i);
    t.at[size_t(i * a + a - 1)] = i == m - 1 ? 1.0 : 0.0;
  }
  for (int j = 0; j < np; ++j) {
    double nj = 1.0;
    for (int l = 0; l < np; ++l)
      if (l != j) nj *= p[size_t(j)] - p[size_t(l)];
    for (int k = 0; k < 3; ++k) t.g[size_t(j * 3 + k)] = std::pow(p[size_t(j)], k) / nj;
  }
  t.g[size_t((a - 1) * 3 + 2)] = 1.0;
  // Row j of B^T: the coefficients of prod_{l != j} (x - p_l) (all points for the last row).
  for (int j = 0; j < a; ++j) {
    std::vector<double> c(size_t(a + 1), 0.0);
    c[0] = 1.0;
    int deg = 0;
    for (int l = 0; l < np; ++l) {
      if (l == j) continue;
      for (int d = deg + 1; d >= 1; --d)
        c[size_t(d)] = c[size_t(d - 1)] - p[size_t(l)] * c[size_t(d)];
      c[0] = -p[size_t(l)] * c[0];
      ++deg;
    }
    for (int d = 0; d < a; ++d) t.bt[size_t(j * a + d)] = c[size_t(d)];
  }
  return t;
}

// out [rows x rows] = L in L^T for L [rows x k] (row-major), in [k x k], in T arithmetic: the
// left product first, each sum over k in order (the transforms of the engine's Winograd).
template <typename T>
void sandwich(const std::vector<double>& l, int rows, int k, const T* in, T* out) {
  T left[8 * 8];
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j < k; ++j) {
      T s = 0;
      for (int q = 0; q < k; ++q) s += T(l[size_t(i * k + q)]) * in[q * k + j];
      left[i * k + j] = s;
    }
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j < rows; ++j) {
      T s = 0;
      for (int q = 0; q < k; ++q) s += left[i * k + q] * T(l[size_t(j * k + q)]);
      out[i * rows + j] = s;
    }
}

// The bf16 Winograd conv as the engine computes it, for any tile: V = B^T d B in fp32, U = G g G^T
// in double, both rounded to bf16, products summed over channels in fp32, Y = A^T M A in fp32.
// x [cin][n + 2][n + 2] (the padding included), w [cin][3][3]; y [n][n] for one output channel.
void winograd_model(const TileTransforms& t, const std::vector<double>& x,
                    const std::vector<double>& w, int64_t cin, int64_t n, std::vector<double>& y) {
  const int m = t.m, a = t.a;
  const int64_t xs = n + 2, tiles = (n + m - 1) / m;
  std::vector<float> u(size_t(cin * a * a));
  double ud[8 * 8];
  for (int64_t c = 0; c < cin; ++c) {
    sandwich(t.g, a, 3, w.data() + c * 9, ud);
    for (int e = 0; e < a * a; ++e) u[size_t(c * a * a + e)] = bf16_round(float(ud[e]));
  }
  float d[8 * 8], v[8 * 8], mm[8 * 8], yt[8 * 8];
  for (int64_t ty = 0; ty < tiles; ++ty)
    for (int64_t tx = 0; tx < tiles; ++tx) {
      std::fill(mm, mm + a * a, 0.0f);
      for (int64_t c = 0; c < cin; ++c) {
        for (int i = 0; i < a; ++i)
          for (int j = 0; j < a; ++j) {
            const int64_t iy = ty * m + i, ix = tx * m + j;
            d[i * a + j] = iy < xs && ix < xs ? float(x[size_t((c * xs + iy) * xs + ix)]) : 0.0f;
          }
        sandwich(t.bt, a, a, d, v);
        for (int e = 0; e < a * a; ++e) mm[e] += bf16_round(v[e]) * u[size_t(c * a * a + e)];
      }
      sandwich(t.at, m, a, mm, yt);
      for (int i = 0; i < m; ++i)
        for (int j = 0; j < m; ++j) {
          const int64_t oy = ty * m + i, ox = tx * m + j;
          if (oy < n && ox < n) y[size_t(oy * n + ox)] = yt[i * m + j];
        }
    }
}

// --tile-error: rms of (conv - exact) over rms of exact, per method, for 128 and 512 channels.
int tile_error(const std::string& only) {
  constexpr int64_t kN = 48, kCout = 8;  // 48 x 48 outputs (divisible by 2, 3 and 4) per channel
  struct Method {
    const char* name;
    std::vector<double> points;  // empty: the engine's conv2d
    ConvWinograd mode = ConvWinograd::kOff;
  };
  const std::vector<Method> methods = {
      {"engine direct bf16", {}, ConvWinograd::kOff},
      {"engine Winograd F(2x2,3x3)", {}, ConvWinograd::kAlways},
      {"model F(2x2,3x3) {0,1,-1}", {0, 1, -1}},
      {"model F(3x3,3x3) {0,1,-1,1/2}", {0, 1, -1, 0.5}},
      {"model F(3x3,3x3) {0,1,-1,2}", {0, 1, -1, 2}},
      {"model F(4x4,3x3) {0,+-1,+-2}", {0, 1, -1, 2, -2}},
      {"model F(4x4,3x3) {0,+-1,+-1/2}", {0, 1, -1, 0.5, -0.5}},
  };
  std::printf("bf16 3x3 conv accuracy by Winograd tile: rms error / rms of the exact (fp64) conv;"
              " %ldx%ld outputs x %ld channels, inputs SiLU(N(0.2, 1)), weights N(0, 1/(9 Cin));"
              " isa %s\n",
              long(kN), long(kN), long(kCout), isa_name(active_isa()));
  std::printf("  %-32s %12s %10s %12s %10s\n", "method", "Cin 128", "x direct", "Cin 512",
              "x direct");
  std::vector<std::vector<double>> err(methods.size(), std::vector<double>(2, 0.0));
  const int64_t cins[2] = {128, 512};
  for (int ci = 0; ci < 2; ++ci) {
    const int64_t cin = cins[ci], xs = kN + 2;
    std::mt19937 rng(uint32_t(11 + ci));
    std::normal_distribution<double> nd(0.0, 1.0);
    std::vector<double> x(size_t(cin * xs * xs), 0.0), w(size_t(kCout * cin * 9));
    for (int64_t c = 0; c < cin; ++c)  // the border is the conv's zero padding
      for (int64_t i = 1; i <= kN; ++i)
        for (int64_t j = 1; j <= kN; ++j) {
          const double v = nd(rng) + 0.2;
          x[size_t((c * xs + i) * xs + j)] = v / (1.0 + std::exp(-v));
        }
    for (double& v : w) v = nd(rng) / std::sqrt(9.0 * double(cin));
    // The engine's operands: x unpadded [cin][kN][kN] and w [kCout][cin][3][3] in fp32.
    std::vector<float> xf(size_t(cin * kN * kN)), wf(w.begin(), w.end());
    for (int64_t c = 0; c < cin; ++c)
      for (int64_t i = 0; i < kN; ++i)
        for (int64_t j = 0; j < kN; ++j)
          xf[size_t((c * kN + i) * kN + j)] = float(x[size_t((c * xs + i + 1) * xs + j + 1)]);
    std::vector<double> exact(size_t(kCout * kN * kN), 0.0);
    double ref = 0.0;
    for (int64_t co = 0; co < kCout; ++co)
      for (int64_t i = 0; i < kN; ++i)
        for (int64_t j = 0; j < kN; ++j) {
          double s = 0.0;
          for (int64_t c = 0; c < cin; ++c)
            for (int u = 0; u < 3; ++u)
              for (int v = 0; v < 3; ++v)
                s += double(float(x[size_t((c * xs + i + u) * xs + j + v)])) *
                     double(wf[size_t((co * cin + c) * 9 + u * 3 + v)]);
          exact[size_t((co * kN + i) * kN + j)] = s;
          ref += s * s;
        }
    const ConvWinograd old = conv2d_set_winograd(ConvWinograd::kAlways);
    const Conv2dShape s = Conv2dShape::make(1, cin, kN, kN, kCout, 3, 1, 1);
    const ConvWeights cw =
        ConvWeights::pack(wf.data(), nullptr, kCout, cin, 3, 3, WeightType::kBf16);
    std::vector<float> yf(size_t(kCout * kN * kN));
    std::vector<double> y(size_t(kN * kN));
    for (size_t mi = 0; mi < methods.size(); ++mi) {
      const Method& me = methods[mi];
      double e2 = 0.0;
      if (me.points.empty()) {
        conv2d_set_winograd(me.mode);
        conv2d(s, xf.data(), cw, nullptr, yf.data(), nullptr);
        for (size_t k = 0; k < yf.size(); ++k) e2 += (yf[k] - exact[k]) * (yf[k] - exact[k]);
      } else {
        const TileTransforms t = toom_cook(me.points);
        std::vector<double> xd(x.begin(), x.end());
        for (double& v : xd) v = double(float(v));
        for (int64_t co = 0; co < kCout; ++co) {
          const std::vector<double> wc(w.begin() + co * cin * 9, w.begin() + (co + 1) * cin * 9);
          std::vector<double> wcf(wc.size());
          for (size_t k = 0; k < wc.size(); ++k) wcf[k] = double(float(wc[k]));
          winograd_model(t, xd, wcf, cin, kN, y);
          for (int64_t k = 0; k < kN * kN; ++k) {
            const double e = y[size_t(k)] - exact[size_t(co * kN * kN + k)];
            e2 += e * e;
          }
        }
      }
      err[mi][size_t(ci)] = std::sqrt(e2 / ref);
    }
    conv2d_set_winograd(old);
  }
  for (size_t mi = 0; mi < methods.size(); ++mi) {
    if (!only.empty() && std::string(methods[mi].name).find(only) == std::string::npos) continue;
    std::printf("  %-32s %12.3e %9.2fx %12.3e %9.2fx\n", methods[mi].name, err[mi][0],
                err[mi][0] / err[0][0], err[mi][1], err[mi][1] / err[0][1]);
  }
  return 0;
}

int run(int argc, char** argv) {
  int threads = ThreadPool::global().size();
  int reps = 5;
  bool quick = false;
  std::string only;
  size_t chunk = 0;
  bool f32 = false, wino_only = false, tile_err = false;
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
    else if (!std::strcmp(argv[i], "--tile-error"))
      tile_err = true;
    else {
      std::fprintf(stderr,
                   "usage: bench winograd [--threads N] [--reps R] [--quick] [--only SUBSTR] "
                   "[--chunk TILES] [--f32] [--wino-only] [--tile-error]\n");
      return 2;
    }
  }
  if (tile_err) return tile_error(only);
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
