// AVX2 row kernel: one 16-pixel tile row as two ymm halves (contract in gs/raster/raster_kernels.h).
// exp is the same degree-6 polynomial as the AVX-512 path, scaled by adding n to the exponent.
#include <immintrin.h>

#include "gs/raster/raster_kernels.h"

namespace macro::gs::raster {
namespace {

inline __m256 exp_neg256(__m256 x) {  // x <= 0
  x = _mm256_max_ps(x, _mm256_set1_ps(-87.0f));
  const __m256 n = _mm256_round_ps(_mm256_mul_ps(x, _mm256_set1_ps(1.44269504088896341f)),
                                   _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
  __m256 r = _mm256_fnmadd_ps(n, _mm256_set1_ps(0.693359375f), x);
  r = _mm256_fnmadd_ps(n, _mm256_set1_ps(-2.12194440e-4f), r);
  __m256 p = _mm256_set1_ps(1.f / 720.f);
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(1.f / 120.f));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(1.f / 24.f));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(1.f / 6.f));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(0.5f));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(1.f));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(1.f));
  // 2^n for n in [-126, 0]: exponent bits (n + 127) << 23.
  const __m256i bits =
      _mm256_slli_epi32(_mm256_add_epi32(_mm256_cvtps_epi32(n), _mm256_set1_epi32(127)), 23);
  return _mm256_mul_ps(p, _mm256_castsi256_ps(bits));
}

inline __m256 lane_mask(uint32_t bits) {  // bit l -> all-ones in lane l (8 lanes)
  const __m256i sel = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
  const __m256i b = _mm256_and_si256(_mm256_set1_epi32(int(bits)), sel);
  return _mm256_castsi256_ps(_mm256_cmpeq_epi32(b, sel));
}

}  // namespace

void blend_row_avx2(const TileSplat* splats, const uint32_t* idx, int n, float px0, float py,
                    RowAccum* acc, BlendCounters* counters) {
  if (!acc->active) return;
  __m256 px[2], T[2], cr[2], cg[2], cb[2], cd[2], ci[2], act[2];
  for (int h = 0; h < 2; ++h) {
    px[h] =
        _mm256_add_ps(_mm256_set1_ps(px0 + float(8 * h)), _mm256_setr_ps(0, 1, 2, 3, 4, 5, 6, 7));
    T[h] = _mm256_load_ps(acc->T + 8 * h);
    cr[h] = _mm256_load_ps(acc->r + 8 * h);
    cg[h] = _mm256_load_ps(acc->g + 8 * h);
    cb[h] = _mm256_load_ps(acc->b + 8 * h);
    cd[h] = _mm256_load_ps(acc->depth + 8 * h);
    ci[h] = _mm256_load_ps(acc->inv_depth + 8 * h);
    act[h] = lane_mask(acc->active >> (8 * h));
  }
  const __m256 max_alpha = _mm256_set1_ps(kMaxAlpha), min_alpha = _mm256_set1_ps(kMinAlpha);
  const __m256 t_stop = _mm256_set1_ps(kTransmittanceStop), one = _mm256_set1_ps(1.f);
  const __m256 zero = _mm256_setzero_ps();
  uint64_t evals = 0, blended = 0;
  for (int i = 0; i < n; ++i) {
    const TileSplat& s = splats[idx[i]];
    const float dy = s.y - py;
    const __m256 x = _mm256_set1_ps(s.x), ha = _mm256_set1_ps(0.5f * s.a);
    const __m256 bdy = _mm256_set1_ps(s.b * dy), hcdy2 = _mm256_set1_ps(0.5f * s.c * dy * dy);
    const __m256 o = _mm256_set1_ps(s.opacity);
    int any = 0;
    for (int h = 0; h < 2; ++h) {
      const int act_bits = _mm256_movemask_ps(act[h]);
      if (!act_bits) continue;
      evals += static_cast<uint64_t>(__builtin_popcount(act_bits));
      const __m256 dx = _mm256_sub_ps(x, px[h]);
      const __m256 sigma = _mm256_fmadd_ps(_mm256_fmadd_ps(ha, dx, bdy), dx, hcdy2);
      __m256 valid = _mm256_and_ps(act[h], _mm256_cmp_ps(sigma, zero, _CMP_GE_OQ));
      const __m256 alpha =
          _mm256_min_ps(max_alpha, _mm256_mul_ps(o, exp_neg256(_mm256_sub_ps(zero, sigma))));
      valid = _mm256_and_ps(valid, _mm256_cmp_ps(alpha, min_alpha, _CMP_GE_OQ));
      const __m256 next_t = _mm256_mul_ps(T[h], _mm256_sub_ps(one, alpha));
      const __m256 stop = _mm256_and_ps(valid, _mm256_cmp_ps(next_t, t_stop, _CMP_LE_OQ));
      const __m256 blend = _mm256_andnot_ps(stop, valid);
      blended += static_cast<uint64_t>(__builtin_popcount(_mm256_movemask_ps(blend)));
      const __m256 w = _mm256_and_ps(blend, _mm256_mul_ps(alpha, T[h]));  // 0 where not blended
      cr[h] = _mm256_fmadd_ps(w, _mm256_set1_ps(s.r), cr[h]);
      cg[h] = _mm256_fmadd_ps(w, _mm256_set1_ps(s.g), cg[h]);
      cb[h] = _mm256_fmadd_ps(w, _mm256_set1_ps(s.bl), cb[h]);
      cd[h] = _mm256_fmadd_ps(w, _mm256_set1_ps(s.z), cd[h]);
      ci[h] = _mm256_fmadd_ps(w, _mm256_set1_ps(s.inv_z), ci[h]);
      T[h] = _mm256_blendv_ps(T[h], next_t, blend);
      act[h] = _mm256_andnot_ps(stop, act[h]);
      any |= _mm256_movemask_ps(act[h]);
    }
    if (!any) break;
  }
  uint32_t active = 0;
  for (int h = 0; h < 2; ++h) {
    _mm256_store_ps(acc->T + 8 * h, T[h]);
    _mm256_store_ps(acc->r + 8 * h, cr[h]);
    _mm256_store_ps(acc->g + 8 * h, cg[h]);
    _mm256_store_ps(acc->b + 8 * h, cb[h]);
    _mm256_store_ps(acc->depth + 8 * h, cd[h]);
    _mm256_store_ps(acc->inv_depth + 8 * h, ci[h]);
    active |= uint32_t(_mm256_movemask_ps(act[h])) << (8 * h);
  }
  acc->active = active;
  counters->evals += evals;
  counters->blended += blended;
}

}  // namespace macro::gs::raster
