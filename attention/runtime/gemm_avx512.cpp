// AVX-512 GEMM micro-kernels: fp32 12x32 (24 zmm accumulators, A broadcast from memory) and a
// bf16 12x32 kernel that widens bf16 pairs with shifts (for CPUs with AVX-512 but no AVX512-BF16).
// Packed layouts and the MicroTile contract: kernels.h.
// GCC 12's AVX-512 headers trip -W(maybe-)uninitialized on their own _mm512_undefined_*() idiom.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include <cstdint>

#include "attention/runtime/gemm_store_avx512.h"
#include "attention/runtime/gemm_strip.h"
#include "attention/runtime/gemm_wide_a.h"
#include "attention/runtime/kernels.h"
#include "attention/runtime/masked_avx512.h"

namespace macro {
namespace {

constexpr int kNr = 32;

constexpr int kMrF32 = 12;

// The C tile is read back after the K loop when accumulating: start fetching it now.
inline void prefetch_c(const MicroTile& t, int mr) {
  if (!t.load_c) return;
  for (int r = 0; r < mr && r < t.m; ++r) {
    _mm_prefetch(reinterpret_cast<const char*>(t.c + r * t.ldc), _MM_HINT_T0);
    _mm_prefetch(reinterpret_cast<const char*>(t.c + r * t.ldc + 16), _MM_HINT_T0);
  }
}

// R rows of the 12-row panel (R < 12 only for the last panel of M).
template <int R>
void micro_f32_rows(const MicroTile& t) {
  prefetch_c(t, R);
  __m512 c0[R], c1[R];
#pragma GCC unroll 16
  for (int r = 0; r < R; ++r) c0[r] = c1[r] = _mm512_setzero_ps();
  const float* a = static_cast<const float*>(t.a);
  const float* b = static_cast<const float*>(t.b);
  for (int64_t k = 0; k < t.kc; ++k) {
    const __m512 b0 = _mm512_loadu_ps(b), b1 = _mm512_loadu_ps(b + 16);
    _mm_prefetch(reinterpret_cast<const char*>(b + 8 * kNr), _MM_HINT_T0);
#pragma GCC unroll 16
    for (int r = 0; r < R; ++r) {
      const __m512 ar = _mm512_set1_ps(a[r]);
      c0[r] = _mm512_fmadd_ps(ar, b0, c0[r]);
      c1[r] = _mm512_fmadd_ps(ar, b1, c1[r]);
    }
    a += kMrF32;
    b += kNr;
  }
  store_tile<R>(t, c0, c1);
}

void micro_f32(const MicroTile& t) {
  for_rows<kMrF32>(t, [&]<int R>() { micro_f32_rows<R>(t); });
}

// A panel [kcp][w] from row-major fp32 rows: 16 k x 4 rows per step, masked loads past valid_k and
// zero rows past valid_rows, transposed in registers (gemm_store_avx512.h). Each group of four rows
// is read front to back while the next group's rows are prefetched (as pack_a_pairs does).
void pack_a_f32(const float* src, int64_t ld, int valid_rows, int64_t valid_k, int64_t kcp, int w,
                void* dst) {
  float* d = static_cast<float*>(dst);
  const __m512 zero = _mm512_setzero_ps();
  for (int g = 0; g < w; g += 4) {
    const int rows = g + 4 <= valid_rows ? 4 : (valid_rows > g ? valid_rows - g : 0);
    const int nrows = w - g < 4 ? w - g : 4;
    const int next = valid_rows - (g + 4) < 4 ? valid_rows - (g + 4) : 4;
    for (int64_t k0 = 0; k0 < kcp; k0 += 16) {
      const int64_t left = valid_k - k0;
      const __mmask16 m = left >= 16  ? __mmask16(0xffff)
                          : left <= 0 ? __mmask16(0)
                                      : __mmask16((1u << left) - 1);
      const int nk = int(kcp - k0 < 16 ? kcp - k0 : 16);
      for (int i = 0; i < next && left > 0; ++i)
        _mm_prefetch(reinterpret_cast<const char*>(src + (g + 4 + i) * ld + k0), _MM_HINT_T0);
      __m512 r[4];
      for (int i = 0; i < 4; ++i)
        r[i] = i < rows ? load_lanes(m, src + (g + i) * ld + k0) : zero;
      transpose_store_4x16(r[0], r[1], r[2], r[3], nk, nrows, w, d + k0 * w + g);
    }
  }
}

// bf16 pairs without vdpbf16ps: lane i of a 32-bit view holds (even | odd << 16); even << 16 and
// odd & 0xffff0000 are the exact fp32 values. Odd products first, as vdpbf16ps does.
//
// The B pairs are widened in registers (4 ops per k pair for 48 FMAs). The A pairs are broadcast
// per row, so widening them in the loop would cost a GPR op and a vpbroadcastd (a port-5 uop
// beside the FMAs) per row and k pair; instead each A micro-panel is widened once (gemm_wide_a.h)
// and the loop broadcasts from memory as the fp32 kernel does. The strip kernel widens once for
// all the tiles of a strip; the single-tile kernel widens per call. Each accumulator still takes
// the odd product, then the even one, per pair: the same bits.
constexpr int kMrBf16 = 12;

thread_local WideA t_wide_a;

template <int R>
void micro_bf16_wide_rows(const MicroTile& t) {
  prefetch_c(t, R);
  __m512 c0[R], c1[R];
#pragma GCC unroll 16
  for (int r = 0; r < R; ++r) c0[r] = c1[r] = _mm512_setzero_ps();
  const float* ao = t_wide_a.odd;
  const float* ae = t_wide_a.even;
  const __m512i* b = static_cast<const __m512i*>(t.b);
  const __m512i hi = _mm512_set1_epi32(int(0xffff0000u));
  for (int64_t kp = 0; kp < t.kc / 2; ++kp) {
    const __m512i w0 = _mm512_loadu_si512(b), w1 = _mm512_loadu_si512(b + 1);
    _mm_prefetch(reinterpret_cast<const char*>(b + 8), _MM_HINT_T0);
    const __m512 b0o = _mm512_castsi512_ps(_mm512_and_si512(w0, hi));
    const __m512 b0e = _mm512_castsi512_ps(_mm512_slli_epi32(w0, 16));
    const __m512 b1o = _mm512_castsi512_ps(_mm512_and_si512(w1, hi));
    const __m512 b1e = _mm512_castsi512_ps(_mm512_slli_epi32(w1, 16));
#pragma GCC unroll 16
    for (int r = 0; r < R; ++r) {
      const __m512 o = _mm512_set1_ps(ao[r]);
      c0[r] = _mm512_fmadd_ps(o, b0o, c0[r]);
      c1[r] = _mm512_fmadd_ps(o, b1o, c1[r]);
      const __m512 e = _mm512_set1_ps(ae[r]);
      c0[r] = _mm512_fmadd_ps(e, b0e, c0[r]);
      c1[r] = _mm512_fmadd_ps(e, b1e, c1[r]);
    }
    ao += kMrBf16;
    ae += kMrBf16;
    b += 2;
  }
  store_tile<R>(t, c0, c1);
}

void micro_bf16_emulated(const MicroTile& t) {
  widen_a_panel(static_cast<const uint32_t*>(t.a), t.kc / 2 * kMrBf16, t_wide_a);
  for_rows<kMrBf16>(t, [&]<int R>() { micro_bf16_wide_rows<R>(t); });
}

void strip_bf16_emulated(const MicroTile& t0, int64_t ncols, int64_t b_stride) {
  widen_a_panel(static_cast<const uint32_t*>(t0.a), t0.kc / 2 * kMrBf16, t_wide_a);
  detail::for_each_strip_tile<kNr>(t0, ncols, b_stride, [](const MicroTile& t) {
    for_rows<kMrBf16>(t, [&]<int R>() { micro_bf16_wide_rows<R>(t); });
  });
}

// 24 independent FMA chains (enough to cover latency x throughput on current cores).
double probe_fma(int64_t iters) {
  __m512 x[24];
  for (int i = 0; i < 24; ++i) x[i] = _mm512_set1_ps(1.0f + 0.001f * float(i));
  const __m512 m = _mm512_set1_ps(0.99999f), c = _mm512_set1_ps(1e-6f);
  for (int64_t it = 0; it < iters; ++it) {
#pragma GCC unroll 24
    for (int i = 0; i < 24; ++i) x[i] = _mm512_fmadd_ps(x[i], m, c);
  }
  __m512 s = x[0];
  for (int i = 1; i < 24; ++i) s = _mm512_add_ps(s, x[i]);
  volatile float sink = _mm512_reduce_add_ps(s);
  (void)sink;
  return double(iters) * 24 * 16 * 2;
}

}  // namespace

namespace detail {
void fill_avx512_kernels(KernelTable& t) {
  const int kc = int(kc_for_l1(kMrF32, 4, 384));
  t.f32 =
      GemmKernel{kMrF32, kNr, 1, kc, PackLayout::kF32, micro_f32, "avx512 f32 12x32", pack_a_f32};
  // The widened A panel is fp32, as in the fp32 kernel: the same K block.
  t.bf16 = GemmKernel{kMrBf16,
                      kNr,
                      2,
                      kc,
                      PackLayout::kBf16Pairs,
                      micro_bf16_emulated,
                      "avx512 bf16 12x32 (shift-widened)"};
  t.bf16.strip = strip_bf16_emulated;
  t.probe_fma = probe_fma;
  t.probe_bf16 = probe_fma;
  t.conv_rows32 = avx512_conv_rows32();
}
}  // namespace detail

}  // namespace macro
