// The bf16 pieces shared by the AVX512-BF16 and AMX attention kernels (attention.h): the packing
// of pre-scaled Q into bf16 pairs and the online softmax that writes its probabilities straight
// into bf16 pair words. Include it only from *_avx512bf16.cpp and *_amx.cpp files (it uses
// AVX512-BF16 intrinsics); like attention_simd.h, everything is in an anonymous namespace.
//
// A pair word (uint32) holds two bf16, the even element in the low half: the operand order of
// vdpbf16ps and of the AMX VNNI layout, so the same buffers feed both kernels:
//   qp [D/2][BQ]  Q pairs (channels 2e, 2e+1) per query lane, pre-scaled by scale * log2(e)
//   pp [BK/2][BQ] P pairs (keys 2c, 2c+1) per query lane, built from S^T after the softmax
#pragma once

#include <limits>

#include "attention/runtime/attention_avx512_traits.h"
#include "attention/runtime/bf16_pairs_avx512.h"

namespace macro::attention_detail {
namespace {

// qp[e][r] = (bf16(s Q[r][2e]), bf16(s Q[r][2e+1])), zero for r >= rows (D % 32 == 0). Per 16
// rows and 32 channels: each row's 32 scaled channels are 16 pair words in channel order (one
// vcvtne2ps2bf16), and a 16 x 16 word transpose turns the rows into query lanes.
inline void pack_q_pairs(const BlockJob& job, uint32_t* qp) {
  const __m512 sc = _mm512_set1_ps(job.scale_log2e);
  for (int r0 = 0; r0 < kTileQ; r0 += 16) {
    const int n = std::max(0, std::min(16, job.rows - r0));
    for (int c0 = 0; c0 < job.d; c0 += 32) {
      __m512i w[16];
      for (int i = 0; i < 16; ++i) {
        if (i >= n) {
          w[i] = _mm512_setzero_si512();
          continue;
        }
        const float* q = job.q_rows[r0 + i] + c0;
        w[i] = (__m512i)_mm512_cvtne2ps_pbh(_mm512_mul_ps(_mm512_loadu_ps(q + 16), sc),
                                            _mm512_mul_ps(_mm512_loadu_ps(q), sc));
      }
      transpose_16x16_words(w);
      for (int e = 0; e < 16; ++e) _mm512_storeu_si512(qp + size_t(c0 / 2 + e) * kTileQ + r0, w[e]);
    }
  }
}

// 2^x for x <= 0 (a score minus its running max): 2^round(x) by vscalefps times a degree-3
// polynomial in f = x - round(x), |f| <= 1/2, the minimax fit for relative error (max 7.5e-5,
// 1/26 of the bf16 rounding of 2^-9 the probabilities get right after; the degree-7 fp32 kernel
// keeps 6e-9). On the avx512bf16 path the softmax is bound by its vector instructions, which
// share the two FMA ports with the dot products: two fewer FMAs take ~15% off it. x < -126, -inf
// and NaN give exactly 0.
inline __m512 exp2_bf16(__m512 x) {
  const __mmask16 live = _mm512_cmp_ps_mask(x, _mm512_set1_ps(-126.0f), _CMP_GE_OQ);
  const __m512 n = _mm512_roundscale_ps(x, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
  const __m512 f = _mm512_sub_ps(x, n);
  __m512 p = _mm512_set1_ps(0.05517166907486401f);
  p = _mm512_fmadd_ps(p, f, _mm512_set1_ps(0.24261112219433073f));
  p = _mm512_fmadd_ps(p, f, _mm512_set1_ps(0.69326098545733628f));
  p = _mm512_fmadd_ps(p, f, _mm512_set1_ps(0.9999280735404954f));
  return _mm512_maskz_scalef_ps(live, p, n);
}

// The online softmax of one key block (softmax_tile in attention_simd.h, with exp2_bf16) fused
// with the packing of the probabilities: per query vector,
// m' = max(m, max_c S), alpha = 2^(m - m'), P = 2^(S - m') summed into l in key order and written
// straight into pair words pp[c][r] = (bf16(P[2c][r]), bf16(P[2c+1][r])), a missing odd key as 0.
// The fp32 P never goes back to memory. The four 16-query vectors of the tile go through each key
// together: four independent max and sum chains (each lane's own order is unchanged), and one
// contiguous 256-byte score row per key.
inline void softmax_pack_bf16(const float* s, int cols, float* m, float* l, float* alpha,
                              uint32_t* pp) {
  constexpr int kV = kTileQ / 16;
  const __m512 zero = _mm512_setzero_ps();
  __m512 mx[kV], m_new[kV], sum[kV];
  for (int v = 0; v < kV; ++v) mx[v] = _mm512_set1_ps(-std::numeric_limits<float>::infinity());
  for (int c = 0; c < cols; ++c)
    for (int v = 0; v < kV; ++v)
      mx[v] = _mm512_max_ps(mx[v], _mm512_loadu_ps(s + size_t(c) * kTileQ + 16 * v));
  for (int v = 0; v < kV; ++v) {
    const __m512 m_old = _mm512_loadu_ps(m + 16 * v);
    m_new[v] = _mm512_max_ps(_mm512_max_ps(m_old, mx[v]),
                             _mm512_set1_ps(std::numeric_limits<float>::lowest()));
    _mm512_storeu_ps(alpha + 16 * v, exp2_bf16(_mm512_sub_ps(m_old, m_new[v])));
    sum[v] = zero;
  }
  for (int c = 0; 2 * c < cols; ++c) {
    const float* sc = s + size_t(2 * c) * kTileQ;
    const bool odd = 2 * c + 1 < cols;
    for (int v = 0; v < kV; ++v) {
      const __m512 lo = exp2_bf16(_mm512_sub_ps(_mm512_loadu_ps(sc + 16 * v), m_new[v]));
      sum[v] = _mm512_add_ps(sum[v], lo);
      __m512 hi = zero;
      if (odd) {
        hi = exp2_bf16(_mm512_sub_ps(_mm512_loadu_ps(sc + kTileQ + 16 * v), m_new[v]));
        sum[v] = _mm512_add_ps(sum[v], hi);
      }
      _mm512_storeu_si512(pp + size_t(c) * kTileQ + 16 * v, bf16_pair_words(lo, hi));
    }
  }
  for (int v = 0; v < kV; ++v) {
    _mm512_storeu_ps(l + 16 * v, _mm512_fmadd_ps(_mm512_loadu_ps(l + 16 * v),
                                                 _mm512_loadu_ps(alpha + 16 * v), sum[v]));
    _mm512_storeu_ps(m + 16 * v, m_new[v]);
  }
}

}  // namespace
}  // namespace macro::attention_detail
