// AVX-512 row kernel: one 16-pixel tile row per zmm register (contract in gs/raster/raster_kernels.h).
// exp is a degree-6 polynomial on the range-reduced argument, scaled with vscalefps
// (relative error ~2e-7 against std::exp for the arguments that matter, -sigma in [-88, 0]).
// GCC 12's avx512fintrin.h seeds unmasked intrinsics with _mm512_undefined_ps(), which trips
// -W(maybe-)uninitialized on every inlined use; the warnings are about the header, not this code.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
// FMAs are written out where wanted; keep the row builder's separate multiplies and adds as the
// scalar twin has them.
#pragma GCC optimize("fp-contract=off")
#include <immintrin.h>

#include "gs/raster/raster_kernels.h"

namespace macro::gs::raster {
namespace {

inline __m512 exp_neg512(__m512 x) {  // x <= 0
  x = _mm512_max_ps(x, _mm512_set1_ps(-87.0f));
  const __m512 n = _mm512_roundscale_ps(_mm512_mul_ps(x, _mm512_set1_ps(1.44269504088896341f)),
                                        _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
  __m512 r = _mm512_fnmadd_ps(n, _mm512_set1_ps(0.693359375f), x);
  r = _mm512_fnmadd_ps(n, _mm512_set1_ps(-2.12194440e-4f), r);
  __m512 p = _mm512_set1_ps(1.f / 720.f);
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(1.f / 120.f));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(1.f / 24.f));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(1.f / 6.f));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(0.5f));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(1.f));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(1.f));
  return _mm512_scalef_ps(p, n);
}

}  // namespace

void blend_row_avx512(const TileSplat* splats, const uint32_t* idx, int n, float px0, float py,
                      RowAccum* acc, BlendCounters* counters) {
  __mmask16 active = static_cast<__mmask16>(acc->active);
  if (!active) return;
  const __m512 px = _mm512_add_ps(
      _mm512_set1_ps(px0), _mm512_setr_ps(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15));
  __m512 T = _mm512_load_ps(acc->T);
  __m512 cr = _mm512_load_ps(acc->r), cg = _mm512_load_ps(acc->g), cb = _mm512_load_ps(acc->b);
  __m512 cd = _mm512_load_ps(acc->depth), ci = _mm512_load_ps(acc->inv_depth);
  const __m512 max_alpha = _mm512_set1_ps(kMaxAlpha), min_alpha = _mm512_set1_ps(kMinAlpha);
  const __m512 t_stop = _mm512_set1_ps(kTransmittanceStop), one = _mm512_set1_ps(1.f);
  const __m512 zero = _mm512_setzero_ps();
  // Per-lane counters (exact up to 2^24 per call: n <= kBlendBatch), summed once at the end.
  __m512 lane_evals = zero, lane_blended = zero;
  for (int i = 0; i < n; ++i) {
    const TileSplat& s = splats[idx[i]];
    const float dy = s.y - py;
    // sigma = 0.5 a dx^2 + b dy dx + 0.5 c dy^2
    const __m512 dx = _mm512_sub_ps(_mm512_set1_ps(s.x), px);
    const __m512 inner = _mm512_fmadd_ps(_mm512_set1_ps(0.5f * s.a), dx, _mm512_set1_ps(s.b * dy));
    const __m512 sigma = _mm512_fmadd_ps(inner, dx, _mm512_set1_ps(0.5f * s.c * dy * dy));
    __mmask16 valid = _mm512_mask_cmp_ps_mask(active, sigma, zero, _CMP_GE_OQ);
    const __m512 e = exp_neg512(_mm512_sub_ps(zero, sigma));
    const __m512 alpha = _mm512_min_ps(max_alpha, _mm512_mul_ps(_mm512_set1_ps(s.opacity), e));
    valid = _mm512_mask_cmp_ps_mask(valid, alpha, min_alpha, _CMP_GE_OQ);
    const __m512 next_t = _mm512_mul_ps(T, _mm512_sub_ps(one, alpha));
    const __mmask16 stop = _mm512_mask_cmp_ps_mask(valid, next_t, t_stop, _CMP_LE_OQ);
    const __mmask16 blend = valid & static_cast<__mmask16>(~stop);
    lane_evals = _mm512_mask_add_ps(lane_evals, active, lane_evals, one);
    lane_blended = _mm512_mask_add_ps(lane_blended, blend, lane_blended, one);
    const __m512 w = _mm512_mul_ps(alpha, T);
    cr = _mm512_mask3_fmadd_ps(w, _mm512_set1_ps(s.r), cr, blend);
    cg = _mm512_mask3_fmadd_ps(w, _mm512_set1_ps(s.g), cg, blend);
    cb = _mm512_mask3_fmadd_ps(w, _mm512_set1_ps(s.bl), cb, blend);
    cd = _mm512_mask3_fmadd_ps(w, _mm512_set1_ps(s.z), cd, blend);
    ci = _mm512_mask3_fmadd_ps(w, _mm512_set1_ps(s.inv_z), ci, blend);
    T = _mm512_mask_mov_ps(T, blend, next_t);
    active = active & static_cast<__mmask16>(~stop);
    if (!active) break;
  }
  _mm512_store_ps(acc->T, T);
  _mm512_store_ps(acc->r, cr);
  _mm512_store_ps(acc->g, cg);
  _mm512_store_ps(acc->b, cb);
  _mm512_store_ps(acc->depth, cd);
  _mm512_store_ps(acc->inv_depth, ci);
  acc->active = active;
  counters->evals += static_cast<uint64_t>(_mm512_reduce_add_ps(lane_evals));
  counters->blended += static_cast<uint64_t>(_mm512_reduce_add_ps(lane_blended));
}

void build_rows_avx512(const RowCullBatch& batch, int n, const RowCullTile& tile,
                       uint32_t (*rows)[kRowListStride], int* counts) {
  const __m512i lanes = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const __m512 x_lo = _mm512_set1_ps(tile.x_lo), x_hi = _mm512_set1_ps(tile.x_hi);
  const __m512 zero = _mm512_setzero_ps();
  for (int r = 0; r < kTile; ++r) counts[r] = 0;
  for (int r = 0; r < tile.h; ++r) {
    if (!(tile.live >> r & 1u)) continue;
    const __m512 py = _mm512_set1_ps(tile.y0 + float(r) + 0.5f);
    uint32_t* list = rows[r];
    int count = 0;
    for (int c = 0; c < n; c += 16) {
      const __mmask16 in = n - c >= 16 ? __mmask16(0xffff) : __mmask16((1u << (n - c)) - 1u);
      const __m512 dy = _mm512_sub_ps(py, _mm512_load_ps(batch.y + c));
      const __m512 half2 =
          _mm512_sub_ps(_mm512_load_ps(batch.a0 + c),
                        _mm512_mul_ps(_mm512_mul_ps(_mm512_load_ps(batch.a1 + c), dy), dy));
      const __m512 centre = _mm512_add_ps(_mm512_load_ps(batch.x + c),
                                          _mm512_mul_ps(_mm512_load_ps(batch.k + c), dy));
      const __m512 gap_lo = _mm512_sub_ps(x_lo, centre), gap_hi = _mm512_sub_ps(centre, x_hi);
      __mmask16 ok = _mm512_mask_cmp_ps_mask(in, half2, zero, _CMP_GE_OQ);
      ok &= _mm512_cmp_ps_mask(gap_lo, zero, _CMP_LE_OQ) |
            _mm512_cmp_ps_mask(_mm512_mul_ps(gap_lo, gap_lo), half2, _CMP_LE_OQ);
      ok &= _mm512_cmp_ps_mask(gap_hi, zero, _CMP_LE_OQ) |
            _mm512_cmp_ps_mask(_mm512_mul_ps(gap_hi, gap_hi), half2, _CMP_LE_OQ);
      // Register compress + full store (a compress straight to memory is slow on some cores).
      const __m512i idx =
          _mm512_maskz_compress_epi32(ok, _mm512_add_epi32(lanes, _mm512_set1_epi32(c)));
      _mm512_storeu_si512(list + count, idx);
      count += __builtin_popcount(ok);
    }
    counts[r] = count;
  }
}

}  // namespace macro::gs::raster
