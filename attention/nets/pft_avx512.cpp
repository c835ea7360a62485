// PFT-SR's depthwise k x k convolution, one output row, AVX-512 (the scalar twin and the contract
// are pft_dw_row_scalar in pft.cpp): channels in blocks of 64 held in four registers while the
// k*k taps accumulate, the last block masked.
#include <immintrin.h>

#include <cstdint>

namespace macro::nets::detail {

void pft_dw_row_avx512(float* y, int64_t ldy, const float* x, int64_t ldx, int64_t h, int64_t w,
                       int64_t oy, const float* taps, const float* bias, int64_t c, int k) {
  const int r = k / 2;
  for (int64_t c0 = 0; c0 < c; c0 += 64) {
    const int64_t nb = c - c0 < 64 ? c - c0 : 64;
    __mmask16 m[4];
    for (int b = 0; b < 4; ++b) {
      const int64_t left = nb - 16 * b;
      m[b] = left >= 16  ? __mmask16(0xFFFF)
             : left <= 0 ? __mmask16(0)
                         : __mmask16((1u << left) - 1);
    }
    for (int64_t ox = 0; ox < w; ++ox) {
      __m512 acc[4];
      for (int b = 0; b < 4; ++b) acc[b] = _mm512_maskz_loadu_ps(m[b], bias + c0 + 16 * b);
      for (int dy = 0; dy < k; ++dy) {
        const int64_t iy = oy + dy - r;
        if (iy < 0 || iy >= h) continue;
        for (int dx = 0; dx < k; ++dx) {
          const int64_t ix = ox + dx - r;
          if (ix < 0 || ix >= w) continue;
          const float* xp = x + (iy * w + ix) * ldx + c0;
          const float* tp = taps + (dy * k + dx) * c + c0;
          for (int b = 0; b < 4; ++b)
            acc[b] = _mm512_fmadd_ps(_mm512_maskz_loadu_ps(m[b], tp + 16 * b),
                                     _mm512_maskz_loadu_ps(m[b], xp + 16 * b), acc[b]);
        }
      }
      float* yp = y + ox * ldy + c0;
      for (int b = 0; b < 4; ++b) _mm512_mask_storeu_ps(yp + 16 * b, m[b], acc[b]);
    }
  }
}

}  // namespace macro::nets::detail

namespace macro::nets::detail {

// o [rows, d] = per row i: sum_j a[i*kk + j] * v[key(i, j) * d ...], key = idx[i*kk + j] or j.
// d in blocks of 16 lanes (the light model's d = 13 is one masked register).
void pft_av_rows_avx512(float* o, const float* a, const uint16_t* idx, const float* v, int rows,
                        int kk, int64_t d) {
  for (int64_t e0 = 0; e0 < d; e0 += 16) {
    const int64_t left = d - e0;
    const __mmask16 m = left >= 16 ? __mmask16(0xFFFF) : __mmask16((1u << left) - 1);
    for (int i = 0; i < rows; ++i) {
      const float* ar = a + int64_t(i) * kk;
      const uint16_t* ir = idx ? idx + int64_t(i) * kk : nullptr;
      __m512 acc0 = _mm512_setzero_ps(), acc1 = _mm512_setzero_ps();
      int j = 0;
      for (; j + 2 <= kk; j += 2) {
        const int64_t k0 = ir ? ir[j] : j, k1 = ir ? ir[j + 1] : j + 1;
        acc0 =
            _mm512_fmadd_ps(_mm512_set1_ps(ar[j]), _mm512_maskz_loadu_ps(m, v + k0 * d + e0), acc0);
        acc1 = _mm512_fmadd_ps(_mm512_set1_ps(ar[j + 1]), _mm512_maskz_loadu_ps(m, v + k1 * d + e0),
                               acc1);
      }
      if (j < kk) {
        const int64_t k0 = ir ? ir[j] : j;
        acc0 =
            _mm512_fmadd_ps(_mm512_set1_ps(ar[j]), _mm512_maskz_loadu_ps(m, v + k0 * d + e0), acc0);
      }
      _mm512_mask_storeu_ps(o + int64_t(i) * d + e0, m, _mm512_add_ps(acc0, acc1));
    }
  }
}

}  // namespace macro::nets::detail
