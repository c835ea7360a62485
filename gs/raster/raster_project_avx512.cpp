// AVX-512 projection geometry: 16 Gaussians per step (contract in gs/raster/raster_kernels.h; the scalar
// twin is geometry_one in raster_project.cpp). The arithmetic mirrors the scalar code operation
// for operation (no FMA contraction; division and sqrt are exact in both), so every field but the
// cutoff-derived ones (ext_x, ext_y, row_a0) is bit-identical; those use a polynomial log
// (relative error ~1e-7) instead of logf and only move the culling ellipse, which carries a 1e-3
// margin.
// GCC 12's avx512fintrin.h seeds unmasked intrinsics with _mm512_undefined_ps(), which trips
// -W(maybe-)uninitialized on every inlined use; the warnings are about the header, not this code.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
// Mirror the scalar twin: no fusing of the separate multiplies and adds into FMAs (GCC would
// otherwise contract the intrinsics; det = sxx syy - sxy^2 cancels, so fusing is visible there).
#pragma GCC optimize("fp-contract=off")
#include <immintrin.h>

#include <algorithm>

#include "gs/raster/raster_kernels.h"

namespace macro::gs::raster {
namespace {

using V = __m512;
using M = __mmask16;

inline V set(float v) {
  return _mm512_set1_ps(v);
}
inline V add(V a, V b) {
  return _mm512_add_ps(a, b);
}
inline V sub(V a, V b) {
  return _mm512_sub_ps(a, b);
}
inline V mul(V a, V b) {
  return _mm512_mul_ps(a, b);
}
inline V div(V a, V b) {
  return _mm512_div_ps(a, b);
}
// std::min(a, b) = b < a ? b : a;  std::max(a, b) = a < b ? b : a (finite inputs here).
inline V smin(V a, V b) {
  return _mm512_mask_mov_ps(a, _mm512_cmp_ps_mask(b, a, _CMP_LT_OQ), b);
}
inline V smax(V a, V b) {
  return _mm512_mask_mov_ps(a, _mm512_cmp_ps_mask(a, b, _CMP_LT_OQ), b);
}
inline M nonfinite(V v) {
  return _mm512_fpclass_ps_mask(v, 0x01 | 0x08 | 0x10 | 0x80);
}

// Natural log for x > 0: x = m 2^e with m in [sqrt(1/2), sqrt(2)), log m = 2 atanh(t),
// t = (m-1)/(m+1), series to t^9 (|t| < 0.172: truncation < 1e-9).
inline V log_pos(V x) {
  V m = _mm512_getmant_ps(x, _MM_MANT_NORM_1_2, _MM_MANT_SIGN_src);
  V e = _mm512_getexp_ps(x);
  const M big = _mm512_cmp_ps_mask(m, set(1.41421356f), _CMP_GT_OQ);
  m = _mm512_mask_mul_ps(m, big, m, set(0.5f));
  e = _mm512_mask_add_ps(e, big, e, set(1.f));
  const V t = div(sub(m, set(1.f)), add(m, set(1.f)));
  const V t2 = mul(t, t);
  V p = set(1.f / 9.f);
  p = _mm512_fmadd_ps(p, t2, set(1.f / 7.f));
  p = _mm512_fmadd_ps(p, t2, set(1.f / 5.f));
  p = _mm512_fmadd_ps(p, t2, set(1.f / 3.f));
  p = _mm512_fmadd_ps(p, t2, set(1.f));
  return _mm512_fmadd_ps(e, set(0.693147180559945f), mul(set(2.f), mul(t, p)));
}

}  // namespace

void project_geometry_avx512(const ProjectInput& in, size_t begin, size_t end, TileSplat* out,
                             uint8_t* fate) {
  const CameraF& cam = *in.cam;
  const __m512i lanes = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
  const __m512i idx3 = _mm512_mullo_epi32(lanes, _mm512_set1_epi32(3));
  const __m512i idx4 = _mm512_slli_epi32(lanes, 2);
  const V zero = _mm512_setzero_ps(), one = set(1.f), two = set(2.f);
  const float eps = in.mode == kModeMip ? kMipKernelSize : kEps2d;
  alignas(64) float f[16][16];  // [field][lane]
  for (size_t g0 = begin; g0 < end; g0 += 16) {
    const int cnt = int(std::min<size_t>(16, end - g0));
    const M lane_mask = cnt == 16 ? M(0xffff) : M((1u << cnt) - 1u);
    const float* pb = in.position + 3 * g0;
    const float* sb = in.scale + 3 * g0;
    const float* qb = in.rotation + 4 * g0;
    auto g3 = [&](const float* base, int c) {
      return _mm512_mask_i32gather_ps(zero, lane_mask, _mm512_add_epi32(idx3, _mm512_set1_epi32(c)),
                                      base, 4);
    };
    auto g4 = [&](const float* base, int c) {
      return _mm512_mask_i32gather_ps(zero, lane_mask, _mm512_add_epi32(idx4, _mm512_set1_epi32(c)),
                                      base, 4);
    };
    const V p0 = g3(pb, 0), p1 = g3(pb, 1), p2 = g3(pb, 2);
    const V s0 = g3(sb, 0), s1 = g3(sb, 1), s2 = g3(sb, 2);
    const V q0 = g4(qb, 0), q1 = g4(qb, 1), q2 = g4(qb, 2), q3 = g4(qb, 3);
    V opacity = _mm512_maskz_loadu_ps(lane_mask, in.opacity + g0);
    const M bad_input = nonfinite(p0) | nonfinite(p1) | nonfinite(p2) | nonfinite(s0) |
                        nonfinite(s1) | nonfinite(s2) | nonfinite(q0) | nonfinite(q1) |
                        nonfinite(q2) | nonfinite(q3) | nonfinite(opacity);

    const float* R = cam.R;
    const V tx =
        add(add(add(mul(set(R[0]), p0), mul(set(R[1]), p1)), mul(set(R[2]), p2)), set(cam.t[0]));
    const V ty =
        add(add(add(mul(set(R[3]), p0), mul(set(R[4]), p1)), mul(set(R[5]), p2)), set(cam.t[1]));
    const V tz =
        add(add(add(mul(set(R[6]), p0), mul(set(R[7]), p1)), mul(set(R[8]), p2)), set(cam.t[2]));
    const M in_depth = _mm512_cmp_ps_mask(tz, set(in.near_plane), _CMP_GT_OQ) &
                       _mm512_cmp_ps_mask(tz, set(in.far_plane), _CMP_LT_OQ);

    const V qn = _mm512_sqrt_ps(add(add(add(mul(q0, q0), mul(q1, q1)), mul(q2, q2)), mul(q3, q3)));
    const M bad_quat = ~_mm512_cmp_ps_mask(qn, zero, _CMP_GT_OQ) | nonfinite(qn);
    const V iq = div(one, qn);
    const V w = mul(q0, iq), x = mul(q1, iq), y = mul(q2, iq), z = mul(q3, iq);
    const V Rq[9] = {
        sub(one, mul(two, add(mul(y, y), mul(z, z)))), mul(two, sub(mul(x, y), mul(w, z))),
        mul(two, add(mul(x, z), mul(w, y))),           mul(two, add(mul(x, y), mul(w, z))),
        sub(one, mul(two, add(mul(x, x), mul(z, z)))), mul(two, sub(mul(y, z), mul(w, x))),
        mul(two, sub(mul(x, z), mul(w, y))),           mul(two, add(mul(y, z), mul(w, x))),
        sub(one, mul(two, add(mul(x, x), mul(y, y))))};

    const V rz = div(one, tz), rz2 = mul(rz, rz);
    const V txc = mul(tz, smin(set(cam.lim_x_pos), smax(set(-cam.lim_x_neg), mul(tx, rz))));
    const V tyc = mul(tz, smin(set(cam.lim_y_pos), smax(set(-cam.lim_y_neg), mul(ty, rz))));
    const V j00 = mul(set(cam.fx), rz), j02 = mul(mul(set(-cam.fx), txc), rz2);
    const V j11 = mul(set(cam.fy), rz), j12 = mul(mul(set(-cam.fy), tyc), rz2);
    V JW[6];
    for (int k = 0; k < 3; ++k) {
      JW[k] = add(mul(j00, set(R[k])), mul(j02, set(R[6 + k])));
      JW[3 + k] = add(mul(j11, set(R[3 + k])), mul(j12, set(R[6 + k])));
    }
    const V sc[3] = {s0, s1, s2};
    V A[6];
    for (int r = 0; r < 2; ++r)
      for (int k = 0; k < 3; ++k)
        A[3 * r + k] = mul(add(add(mul(JW[3 * r], Rq[k]), mul(JW[3 * r + 1], Rq[3 + k])),
                               mul(JW[3 * r + 2], Rq[6 + k])),
                           sc[k]);
    V sxx = add(add(mul(A[0], A[0]), mul(A[1], A[1])), mul(A[2], A[2]));
    const V sxy = add(add(mul(A[0], A[3]), mul(A[1], A[4])), mul(A[2], A[5]));
    V syy = add(add(mul(A[3], A[3]), mul(A[4], A[4])), mul(A[5], A[5]));
    const V det0 = sub(mul(sxx, syy), mul(sxy, sxy));
    sxx = add(sxx, set(eps));
    syy = add(syy, set(eps));
    const V det = sub(mul(sxx, syy), mul(sxy, sxy));
    const M bad_cov = ~_mm512_cmp_ps_mask(det, zero, _CMP_GT_OQ) | nonfinite(det) | nonfinite(sxx) |
                      nonfinite(syy);

    if (in.mode == kModeAntialiased) {
      opacity = mul(opacity, _mm512_sqrt_ps(smax(set(kAaCompFloor), div(det0, det))));
    } else if (in.mode == kModeMip) {
      const V d0 = smax(set(kMipDetEps), det0), d1 = smax(set(kMipDetEps), det);
      V coef = _mm512_sqrt_ps(add(div(d0, add(d1, set(kMipDetEps))), set(kMipDetEps)));
      const M degenerate = _mm512_cmp_ps_mask(d0, set(kMipDetEps), _CMP_LE_OQ) |
                           _mm512_cmp_ps_mask(d1, set(kMipDetEps), _CMP_LE_OQ);
      coef = _mm512_mask_mov_ps(coef, degenerate, zero);
      opacity = mul(opacity, coef);
    }
    const M faint = ~_mm512_cmp_ps_mask(opacity, set(kMinAlpha), _CMP_GE_OQ);
    // Safe argument for the log on lanes that are culled anyway.
    const V ratio = _mm512_mask_mov_ps(one, ~faint, div(opacity, set(kMinAlpha)));
    const V cutoff =
        add(mul(mul(two, log_pos(ratio)), set(1.f + kCutoffRelMargin)), set(kCutoffAbsMargin));

    const V mx = add(mul(mul(set(cam.fx), tx), rz), set(cam.cx));
    const V my = add(mul(mul(set(cam.fy), ty), rz), set(cam.cy));
    const V inv_det = div(one, det);
    const V ca = mul(syy, inv_det), cb = mul(sub(zero, sxy), inv_det), cc = mul(sxx, inv_det);
    const V ext_x = _mm512_sqrt_ps(mul(cutoff, sxx)), ext_y = _mm512_sqrt_ps(mul(cutoff, syy));
    const V inv_syy = div(one, syy);
    const V row_k = mul(sxy, inv_syy);
    const V row_a0 = mul(mul(cutoff, det), inv_syy);
    const V row_a1 = mul(mul(det, inv_syy), inv_syy);
    const M bad_out = nonfinite(mx) | nonfinite(my) | nonfinite(ca) | nonfinite(cb) |
                      nonfinite(cc) | nonfinite(ext_x) | nonfinite(ext_y);
    const M offscreen =
        _mm512_cmp_ps_mask(add(mx, ext_x), set(0.5f), _CMP_LT_OQ) |
        _mm512_cmp_ps_mask(sub(mx, ext_x), set(float(cam.width) - 0.5f), _CMP_GT_OQ) |
        _mm512_cmp_ps_mask(add(my, ext_y), set(0.5f), _CMP_LT_OQ) |
        _mm512_cmp_ps_mask(sub(my, ext_y), set(float(cam.height) - 0.5f), _CMP_GT_OQ);

    // Fates in the scalar order of checks: the first failing one wins.
    const V outs[16] = {mx,   my, ca, cb,    cc,    opacity, zero,   zero,
                        zero, tz, rz, ext_x, ext_y, row_k,   row_a0, row_a1};
    for (int k = 0; k < 16; ++k) _mm512_store_ps(f[k], outs[k]);
    for (int i = 0; i < cnt; ++i) {
      const uint32_t bit = 1u << i;
      uint8_t fa = kFateVisible;
      if (bad_input & bit)
        fa = kFateInvalid;
      else if (!(in_depth & bit))
        fa = kFateDepth;
      else if (bad_quat & bit)
        fa = kFateInvalid;
      else if (bad_cov & bit)
        fa = kFateInvalid;
      else if (faint & bit)
        fa = kFateFaint;
      else if (bad_out & bit)
        fa = kFateInvalid;
      else if (offscreen & bit)
        fa = kFateOffscreen;
      fate[g0 + size_t(i) - begin] = fa;
      if (fa != kFateVisible) continue;
      TileSplat& s = out[g0 + size_t(i)];
      s.x = f[0][i];
      s.y = f[1][i];
      s.a = f[2][i];
      s.b = f[3][i];
      s.c = f[4][i];
      s.opacity = f[5][i];
      s.z = f[9][i];
      s.inv_z = f[10][i];
      s.ext_x = f[11][i];
      s.ext_y = f[12][i];
      s.row_k = f[13][i];
      s.row_a0 = f[14][i];
      s.row_a1 = f[15][i];
    }
  }
}

}  // namespace macro::gs::raster
