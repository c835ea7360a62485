// AVX512-BF16 GEMM micro-kernel: 14x32 with vdpbf16ps on pair-interleaved panels (kernels.h).
// fp32 GEMM on this path is the AVX-512 kernel.
// GCC 12's AVX-512 headers trip -W(maybe-)uninitialized on their own _mm512_undefined_*() idiom.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include "attention/runtime/bf16_pairs_avx512.h"
#include "attention/runtime/gemm_store_avx512.h"
#include "attention/runtime/kernels.h"
#include "attention/runtime/masked_avx512.h"

namespace macro {
namespace {

constexpr int kMr = 14, kNr = 32;

// R rows of the 14-row panel (R < 14 only for the last panel of M).
template <int R>
void micro_bf16_rows(const MicroTile& t) {
  __m512 c0[R], c1[R];
#pragma GCC unroll 16
  for (int r = 0; r < R; ++r) c0[r] = c1[r] = _mm512_setzero_ps();
  const uint32_t* a = static_cast<const uint32_t*>(t.a);  // [kc/2][MR] pairs
  const __m512i* b = static_cast<const __m512i*>(t.b);    // [kc/2][NR] pairs, 2 zmm per step
  for (int64_t kp = 0; kp < t.kc / 2; ++kp) {
    const __m512bh b0 = (__m512bh)_mm512_loadu_si512(b);
    const __m512bh b1 = (__m512bh)_mm512_loadu_si512(b + 1);
    _mm_prefetch(reinterpret_cast<const char*>(b + 16), _MM_HINT_T0);
#pragma GCC unroll 16
    for (int r = 0; r < R; ++r) {
      const __m512bh ar = (__m512bh)_mm512_set1_epi32(int(a[r]));
      c0[r] = _mm512_dpbf16_ps(c0[r], ar, b0);
      c1[r] = _mm512_dpbf16_ps(c1[r], ar, b1);
    }
    a += kMr;
    b += 2;
  }
  store_tile<R>(t, c0, c1);
}

void micro_bf16(const MicroTile& t) {
  for_rows<kMr>(t, [&]<int R>() { micro_bf16_rows<R>(t); });
}

// A panel [kcp/2][w] of pair words from row-major fp32 rows: 32 floats -> 16 pair words with one
// vcvtne2ps2bf16 (nearest even; like the hardware, fp32 denormal inputs become zero), four rows at
// a time transposed into the panel. Each group of four rows is read front to back (the source
// rows are usually contiguous, so the whole panel is one forward stream for the prefetchers) while
// the next group's rows are prefetched: the activations come from memory, not from cache.
void pack_a_pairs(const float* src, int64_t ld, int valid_rows, int64_t valid_k, int64_t kcp, int w,
                  void* dst) {
  float* d = static_cast<float*>(dst);  // pair words, moved as 32-bit lanes
  const int64_t pairs = kcp / 2;
  for (int g = 0; g < w; g += 4) {
    const int rows = g + 4 <= valid_rows ? 4 : (valid_rows > g ? valid_rows - g : 0);
    const int nrows = w - g < 4 ? w - g : 4;
    const int next = valid_rows - (g + 4) < 4 ? valid_rows - (g + 4) : 4;  // rows of group g + 4
    for (int64_t q0 = 0; q0 < pairs; q0 += 16) {
      const int64_t k = 2 * q0;
      const int64_t left = valid_k - k;
      const int64_t n0 = left <= 0 ? 0 : (left >= 16 ? 16 : left);
      const int64_t n1 = left <= 16 ? 0 : (left >= 32 ? 16 : left - 16);
      const __mmask16 m0 = n0 == 16 ? __mmask16(0xffff) : __mmask16((1u << n0) - 1);
      const __mmask16 m1 = n1 == 16 ? __mmask16(0xffff) : __mmask16((1u << n1) - 1);
      const int nq = int(pairs - q0 < 16 ? pairs - q0 : 16);
      for (int i = 0; i < next && n0 > 0; ++i) {
        const char* pf = reinterpret_cast<const char*>(src + (g + 4 + i) * ld + k);
        _mm_prefetch(pf, _MM_HINT_T0);
        _mm_prefetch(pf + 64, _MM_HINT_T0);
      }
      __m512 r[4];
      for (int i = 0; i < 4; ++i) {
        if (i < rows) {
          const float* s = src + (g + i) * ld + k;
          r[i] = _mm512_castsi512_ps(
              (__m512i)_mm512_cvtne2ps_pbh(load_lanes(m1, s + 16), load_lanes(m0, s)));
        } else {
          r[i] = _mm512_setzero_ps();
        }
      }
      transpose_store_4x16(r[0], r[1], r[2], r[3], nq, nrows, w, d + q0 * w + g);
    }
  }
}

// The same from a transposed source (row r, column k at src[k * ld + r]): pair q of 16 rows is
// one vector of pair words built from source rows 2q and 2q + 1, stored as is (no transpose).
void pack_a_pairs_t(const float* src, int64_t ld, int valid_rows, int64_t valid_k, int64_t kcp,
                    int w, void* dst) {
  uint32_t* d = static_cast<uint32_t*>(dst);
  const int64_t pairs = kcp / 2;
  for (int r0 = 0; r0 < w; r0 += 16) {
    const int n = w - r0 < 16 ? w - r0 : 16;  // lanes of this panel part (14-row panels: 14)
    const int nr = valid_rows - r0 <= 0 ? 0 : (valid_rows - r0 >= n ? n : valid_rows - r0);
    const __mmask16 rm = __mmask16((1u << nr) - 1);
    const __mmask16 wm = __mmask16((1u << n) - 1);
    for (int64_t q = 0; q < pairs; ++q) {
      const int64_t k = 2 * q;
      const __m512 lo =
          k < valid_k ? _mm512_maskz_loadu_ps(rm, src + k * ld + r0) : _mm512_setzero_ps();
      const __m512 hi = k + 1 < valid_k ? _mm512_maskz_loadu_ps(rm, src + (k + 1) * ld + r0)
                                        : _mm512_setzero_ps();
      _mm512_mask_storeu_epi32(d + q * w + r0, wm, bf16_pair_words(lo, hi));
    }
  }
}

// 24 independent vdpbf16ps chains; each does 16 lanes x 2 products x 2 flops.
double probe_bf16(int64_t iters) {
  __m512 x[24];
  for (int i = 0; i < 24; ++i) x[i] = _mm512_setzero_ps();
  const __m512bh a = (__m512bh)_mm512_set1_epi32(0x3f803f80);  // (1.0, 1.0)
  const __m512bh b = (__m512bh)_mm512_set1_epi32(0x33d633d6);  // tiny values
  for (int64_t it = 0; it < iters; ++it) {
#pragma GCC unroll 24
    for (int i = 0; i < 24; ++i) x[i] = _mm512_dpbf16_ps(x[i], a, b);
  }
  __m512 s = x[0];
  for (int i = 1; i < 24; ++i) s = _mm512_add_ps(s, x[i]);
  volatile float sink = _mm512_reduce_add_ps(s);
  (void)sink;
  return double(iters) * 24 * 16 * 4;
}

}  // namespace

namespace detail {
void fill_avx512bf16_kernels(KernelTable& t) {
  fill_avx512_kernels(t);
  const int kc = int(kc_for_l1(kMr, 2, 384));
  t.bf16 = GemmKernel{
      kMr,          kNr,           2, kc, PackLayout::kBf16Pairs, micro_bf16, "avx512bf16 14x32",
      pack_a_pairs, pack_a_pairs_t};
  t.probe_bf16 = probe_bf16;
}
}  // namespace detail

}  // namespace macro
