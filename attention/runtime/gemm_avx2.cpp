// AVX2+FMA GEMM micro-kernels: fp32 6x16 (12 ymm accumulators) and bf16 5x16 widened with shifts.
// Packed layouts and the MicroTile contract: kernels.h.
#include <immintrin.h>

#include "attention/runtime/gemm_strip.h"
#include "attention/runtime/gemm_wide_a.h"
#include "attention/runtime/kernels.h"

namespace macro {
namespace {

constexpr int kNr = 16;

template <int MR>
inline void store_tile(const MicroTile& t, const __m256* c0, const __m256* c1) {
  if (t.n < kNr) {
    // Column tail: go through a buffer and plain loops.
    alignas(32) float acc[MR * kNr];
#pragma GCC unroll 8
    for (int r = 0; r < MR; ++r) {
      _mm256_store_ps(acc + r * kNr, c0[r]);
      _mm256_store_ps(acc + r * kNr + 8, c1[r]);
    }
    for (int i = 0; i < t.m; ++i) {
      float* c = t.c + i * t.ldc;
      for (int j = 0; j < t.n; ++j) {
        float v = t.alpha * acc[i * kNr + j];
        if (t.load_c) v += t.beta * c[j];
        if (t.bias_n) v += t.bias_n[j];
        if (t.bias_m) v += t.bias_m[i];
        if (t.res) v += t.res[i * t.ldr + j];
        if (t.relu) v = v > 0.0f ? v : 0.0f;
        c[j] = v;
      }
    }
    return;
  }
  const __m256 alpha = _mm256_set1_ps(t.alpha), beta = _mm256_set1_ps(t.beta);
  const bool scale = t.alpha != 1.0f;
  // Fully unrolled, like the tail's copy above: an accumulator indexed by a loop variable would
  // keep the arrays in memory, and GCC then stores every accumulator to the stack in every step of
  // the K loop (12 stores per 12 FMAs: half the FMA rate).
#pragma GCC unroll 8
  for (int r = 0; r < MR; ++r) {
    if (r >= t.m) break;
    float* c = t.c + r * t.ldc;
    __m256 v0 = scale ? _mm256_mul_ps(c0[r], alpha) : c0[r];
    __m256 v1 = scale ? _mm256_mul_ps(c1[r], alpha) : c1[r];
    if (t.load_c) {
      v0 = _mm256_fmadd_ps(beta, _mm256_loadu_ps(c), v0);
      v1 = _mm256_fmadd_ps(beta, _mm256_loadu_ps(c + 8), v1);
    }
    if (t.bias_n) {
      v0 = _mm256_add_ps(v0, _mm256_loadu_ps(t.bias_n));
      v1 = _mm256_add_ps(v1, _mm256_loadu_ps(t.bias_n + 8));
    }
    if (t.bias_m) {
      const __m256 bm = _mm256_set1_ps(t.bias_m[r]);
      v0 = _mm256_add_ps(v0, bm);
      v1 = _mm256_add_ps(v1, bm);
    }
    if (t.res) {
      const float* rr = t.res + r * t.ldr;
      v0 = _mm256_add_ps(v0, _mm256_loadu_ps(rr));
      v1 = _mm256_add_ps(v1, _mm256_loadu_ps(rr + 8));
    }
    if (t.relu) {
      v0 = _mm256_max_ps(v0, _mm256_setzero_ps());
      v1 = _mm256_max_ps(v1, _mm256_setzero_ps());
    }
    _mm256_storeu_ps(c, v0);
    _mm256_storeu_ps(c + 8, v1);
  }
}

constexpr int kMrF32 = 6;

void micro_f32(const MicroTile& t) {
  __m256 c0[kMrF32], c1[kMrF32];
#pragma GCC unroll 8
  for (int r = 0; r < kMrF32; ++r) c0[r] = c1[r] = _mm256_setzero_ps();
  const float* a = static_cast<const float*>(t.a);
  const float* b = static_cast<const float*>(t.b);
  for (int64_t k = 0; k < t.kc; ++k) {
    const __m256 b0 = _mm256_loadu_ps(b), b1 = _mm256_loadu_ps(b + 8);
#pragma GCC unroll 8
    for (int r = 0; r < kMrF32; ++r) {
      const __m256 ar = _mm256_broadcast_ss(a + r);
      c0[r] = _mm256_fmadd_ps(ar, b0, c0[r]);
      c1[r] = _mm256_fmadd_ps(ar, b1, c1[r]);
    }
    a += kMrF32;
    b += kNr;
  }
  store_tile<kMrF32>(t, c0, c1);
}

// bf16 pairs: lane i of a 32-bit view holds (even | odd << 16); even << 16 and odd & 0xffff0000
// are the exact fp32 values; odd products first, as vdpbf16ps does. The A micro-panel is widened
// once per call or strip (gemm_wide_a.h) so each row's broadcast is a load; the B pairs are
// widened in registers, the odd halves for all rows first, then the even ones. Five rows: 10
// accumulators + 2 B words + their 2 widened halves + 1 broadcast + the mask fit the 16 ymm (six
// rows spilled an accumulator to the stack in every step, whose store-to-load round trip then
// lengthened its FMA chain). Each accumulator takes the odd product, then the even one, per pair:
// the scalar twin's bits.
constexpr int kMrBf16 = 5;

thread_local WideA t_wide_a;

template <int R>
void micro_bf16_wide_rows(const MicroTile& t) {
  __m256 c0[kMrBf16], c1[kMrBf16];
#pragma GCC unroll 8
  for (int r = 0; r < kMrBf16; ++r) c0[r] = c1[r] = _mm256_setzero_ps();
  const float* ao = t_wide_a.odd;
  const float* ae = t_wide_a.even;
  const __m256i* b = static_cast<const __m256i*>(t.b);
  const __m256i hi = _mm256_set1_epi32(int(0xffff0000u));
  for (int64_t kp = 0; kp < t.kc / 2; ++kp) {
    const __m256i w0 = _mm256_loadu_si256(b), w1 = _mm256_loadu_si256(b + 1);
    const __m256 b0o = _mm256_castsi256_ps(_mm256_and_si256(w0, hi));
    const __m256 b1o = _mm256_castsi256_ps(_mm256_and_si256(w1, hi));
#pragma GCC unroll 8
    for (int r = 0; r < R; ++r) {
      const __m256 o = _mm256_broadcast_ss(ao + r);
      c0[r] = _mm256_fmadd_ps(o, b0o, c0[r]);
      c1[r] = _mm256_fmadd_ps(o, b1o, c1[r]);
    }
    const __m256 b0e = _mm256_castsi256_ps(_mm256_slli_epi32(w0, 16));
    const __m256 b1e = _mm256_castsi256_ps(_mm256_slli_epi32(w1, 16));
#pragma GCC unroll 8
    for (int r = 0; r < R; ++r) {
      const __m256 e = _mm256_broadcast_ss(ae + r);
      c0[r] = _mm256_fmadd_ps(e, b0e, c0[r]);
      c1[r] = _mm256_fmadd_ps(e, b1e, c1[r]);
    }
    ao += kMrBf16;
    ae += kMrBf16;
    b += 2;
  }
  store_tile<kMrBf16>(t, c0, c1);
}

// The rows of the tile: the full panel, or the last panel's m < 5 (fewer accumulators).
void micro_bf16_wide(const MicroTile& t) {
  switch (t.m) {
    case 1: micro_bf16_wide_rows<1>(t); break;
    case 2: micro_bf16_wide_rows<2>(t); break;
    case 3: micro_bf16_wide_rows<3>(t); break;
    case 4: micro_bf16_wide_rows<4>(t); break;
    default: micro_bf16_wide_rows<kMrBf16>(t); break;
  }
}

void micro_bf16_emulated(const MicroTile& t) {
  widen_a_panel(static_cast<const uint32_t*>(t.a), t.kc / 2 * kMrBf16, t_wide_a);
  micro_bf16_wide(t);
}

void strip_bf16_emulated(const MicroTile& t0, int64_t ncols, int64_t b_stride) {
  widen_a_panel(static_cast<const uint32_t*>(t0.a), t0.kc / 2 * kMrBf16, t_wide_a);
  detail::for_each_strip_tile<kNr>(t0, ncols, b_stride,
                                   [](const MicroTile& t) { micro_bf16_wide(t); });
}

double probe_fma(int64_t iters) {
  __m256 x[12];
  for (int i = 0; i < 12; ++i) x[i] = _mm256_set1_ps(1.0f + 0.001f * float(i));
  const __m256 m = _mm256_set1_ps(0.99999f), c = _mm256_set1_ps(1e-6f);
  for (int64_t it = 0; it < iters; ++it) {
#pragma GCC unroll 12
    for (int i = 0; i < 12; ++i) x[i] = _mm256_fmadd_ps(x[i], m, c);
  }
  __m256 s = x[0];
  for (int i = 1; i < 12; ++i) s = _mm256_add_ps(s, x[i]);
  alignas(32) float out[8];
  _mm256_store_ps(out, s);
  volatile float sink = out[0];
  (void)sink;
  return double(iters) * 12 * 8 * 2;
}

}  // namespace

namespace detail {
void fill_avx2_kernels(KernelTable& t) {
  t.f32 = GemmKernel{kMrF32, kNr, 1, 256, PackLayout::kF32, micro_f32, "avx2 f32 6x16"};
  t.bf16 = GemmKernel{kMrBf16,
                      kNr,
                      2,
                      256,
                      PackLayout::kBf16Pairs,
                      micro_bf16_emulated,
                      "avx2 bf16 5x16 (shift-widened)"};
  t.bf16.strip = strip_bf16_emulated;
  t.probe_fma = probe_fma;
  t.probe_bf16 = probe_fma;
}
}  // namespace detail

}  // namespace macro
