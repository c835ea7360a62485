// The AVX-512 micro-tile epilogue and A-panel transpose shared by the fp32, bf16 and AMX
// micro-kernels (gemm_avx512.cpp, gemm_avx512bf16.cpp, gemm_amx.cpp; AMX stores its fp32 tiles
// and applies the same epilogue). Include ONLY from files compiled with AVX-512 flags.
// Internal linkage (anonymous namespace), so each ISA file keeps its own copy compiled with its own
// flags.
#pragma once

#include <immintrin.h>

#include <utility>

#include "attention/runtime/kernels.h"

namespace macro {
namespace {

// A micro-kernel for the tile's rows only: f.template operator()<R>() with R = min(t.m, MR), so
// the last panel of an M that is not a multiple of MR (128 output channels are 9 full 14-row
// panels and 2 rows) runs 2 rows of products, not 14. Each row's sums are the same either way.
template <int MR, typename F>
inline void for_rows(const MicroTile& t, F&& f) {
  if (t.m >= MR) {
    f.template operator()<MR>();
    return;
  }
  [&]<int... I>(std::integer_sequence<int, I...>) {
    (void)((t.m == I + 1 ? (f.template operator()<I + 1>(), true) : false) || ...);
  }
  (std::make_integer_sequence<int, MR - 1>{});
}

// Lane masks of the two 16-column halves of a 32-column tile row with n valid columns.
inline void half_masks(int n, __mmask16* k0, __mmask16* k1) {
  *k0 = n >= 16 ? __mmask16(0xffff) : __mmask16((1u << n) - 1);
  *k1 = n >= 32 ? __mmask16(0xffff) : n <= 16 ? __mmask16(0) : __mmask16((1u << (n - 16)) - 1);
}

// C = alpha*acc + beta*C (if load_c) + bias_n + bias_m + res, masked to t.n columns, t.m rows;
// acc(r, 0) and acc(r, 1) give the two 16-column halves of row r's sums.
template <int MR, typename Acc>
inline void store_tile_from(const MicroTile& t, Acc&& acc) {
  __mmask16 k0, k1;
  half_masks(t.n, &k0, &k1);
  const __m512 alpha = _mm512_set1_ps(t.alpha), beta = _mm512_set1_ps(t.beta);
  const bool scale = t.alpha != 1.0f;
  __m512 bn0 = _mm512_setzero_ps(), bn1 = _mm512_setzero_ps();
  if (t.bias_n) {
    bn0 = _mm512_maskz_loadu_ps(k0, t.bias_n);
    bn1 = _mm512_maskz_loadu_ps(k1, t.bias_n + 16);
  }
#pragma GCC unroll 16
  for (int r = 0; r < MR; ++r) {
    if (r >= t.m) break;
    float* c = t.c + r * t.ldc;
    __m512 v0 = acc(r, 0), v1 = acc(r, 1);
    if (scale) {
      v0 = _mm512_mul_ps(v0, alpha);
      v1 = _mm512_mul_ps(v1, alpha);
    }
    if (t.load_c) {
      v0 = _mm512_fmadd_ps(beta, _mm512_maskz_loadu_ps(k0, c), v0);
      v1 = _mm512_fmadd_ps(beta, _mm512_maskz_loadu_ps(k1, c + 16), v1);
    }
    if (t.bias_n) {
      v0 = _mm512_add_ps(v0, bn0);
      v1 = _mm512_add_ps(v1, bn1);
    }
    if (t.bias_m) {
      const __m512 bm = _mm512_set1_ps(t.bias_m[r]);
      v0 = _mm512_add_ps(v0, bm);
      v1 = _mm512_add_ps(v1, bm);
    }
    if (t.res) {
      const float* rr = t.res + r * t.ldr;
      v0 = _mm512_add_ps(v0, _mm512_maskz_loadu_ps(k0, rr));
      v1 = _mm512_add_ps(v1, _mm512_maskz_loadu_ps(k1, rr + 16));
    }
    if (t.relu) {
      v0 = _mm512_max_ps(v0, _mm512_setzero_ps());
      v1 = _mm512_max_ps(v1, _mm512_setzero_ps());
    }
    _mm512_mask_storeu_ps(c, k0, v0);
    _mm512_mask_storeu_ps(c + 16, k1, v1);
  }
}

// The same from register arrays: c0[r], c1[r] are row r's halves.
template <int MR>
inline void store_tile(const MicroTile& t, const __m512* c0, const __m512* c1) {
  store_tile_from<MR>(t, [&](int r, int half) { return half ? c1[r] : c0[r]; });
}

// Transposed store of four rows of 16 32-bit elements (fp32 values, or bf16 pair words):
// dst[k * w + i] = row_i[k] for k < nk (<= 16), i < nrows (<= 4; the others are not written). This
// is the A-panel packing step ([K][MR] from row-major rows): a 4x4 transpose inside each 128-bit
// lane, then one 16-byte store per k.
inline void transpose_store_4x16(__m512 r0, __m512 r1, __m512 r2, __m512 r3, int nk, int nrows,
                                 int64_t w, float* dst) {
  const __m512 t0 = _mm512_unpacklo_ps(r0, r1), t1 = _mm512_unpackhi_ps(r0, r1);
  const __m512 t2 = _mm512_unpacklo_ps(r2, r3), t3 = _mm512_unpackhi_ps(r2, r3);
  // u_j lane l holds the four rows at k = 4 l + j.
  const __m512 u0 =
      _mm512_castpd_ps(_mm512_unpacklo_pd(_mm512_castps_pd(t0), _mm512_castps_pd(t2)));
  const __m512 u1 =
      _mm512_castpd_ps(_mm512_unpackhi_pd(_mm512_castps_pd(t0), _mm512_castps_pd(t2)));
  const __m512 u2 =
      _mm512_castpd_ps(_mm512_unpacklo_pd(_mm512_castps_pd(t1), _mm512_castps_pd(t3)));
  const __m512 u3 =
      _mm512_castpd_ps(_mm512_unpackhi_pd(_mm512_castps_pd(t1), _mm512_castps_pd(t3)));
  if (nk == 16 && nrows == 4) {
#define MACRO_STORE_LANE(L)                                            \
  _mm_storeu_ps(dst + (4 * L + 0) * w, _mm512_extractf32x4_ps(u0, L)); \
  _mm_storeu_ps(dst + (4 * L + 1) * w, _mm512_extractf32x4_ps(u1, L)); \
  _mm_storeu_ps(dst + (4 * L + 2) * w, _mm512_extractf32x4_ps(u2, L)); \
  _mm_storeu_ps(dst + (4 * L + 3) * w, _mm512_extractf32x4_ps(u3, L));
    MACRO_STORE_LANE(0)
    MACRO_STORE_LANE(1)
    MACRO_STORE_LANE(2)
    MACRO_STORE_LANE(3)
#undef MACRO_STORE_LANE
    return;
  }
  if (nk == 16 && nrows == 2) {
    // The last pair of rows of a 14-row panel: the low 8 bytes of each lane.
#define MACRO_STORE_LANE2(L)                                                                     \
  _mm_storel_pi(reinterpret_cast<__m64*>(dst + (4 * L + 0) * w), _mm512_extractf32x4_ps(u0, L)); \
  _mm_storel_pi(reinterpret_cast<__m64*>(dst + (4 * L + 1) * w), _mm512_extractf32x4_ps(u1, L)); \
  _mm_storel_pi(reinterpret_cast<__m64*>(dst + (4 * L + 2) * w), _mm512_extractf32x4_ps(u2, L)); \
  _mm_storel_pi(reinterpret_cast<__m64*>(dst + (4 * L + 3) * w), _mm512_extractf32x4_ps(u3, L));
    MACRO_STORE_LANE2(0)
    MACRO_STORE_LANE2(1)
    MACRO_STORE_LANE2(2)
    MACRO_STORE_LANE2(3)
#undef MACRO_STORE_LANE2
    return;
  }
  alignas(64) float tmp[4][16];
  _mm512_store_ps(tmp[0], u0);
  _mm512_store_ps(tmp[1], u1);
  _mm512_store_ps(tmp[2], u2);
  _mm512_store_ps(tmp[3], u3);
  for (int k = 0; k < nk; ++k) {
    const float* s = &tmp[k & 3][4 * (k >> 2)];
    for (int i = 0; i < nrows; ++i) dst[k * w + i] = s[i];
  }
}

}  // namespace
}  // namespace macro
