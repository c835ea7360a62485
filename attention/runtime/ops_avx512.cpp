// AVX-512 vector primitives for ops.h (16 fp32 lanes, masked tails). Scalar twins in ops.cpp.
//
// exp: Cephes-style range reduction x = n ln2 + r, |r| <= ln2/2, degree-6 polynomial, 2^n via
// vscalefps (handles underflow to subnormal/zero). ~1-2 ulp.
// GELU: Phi(x) from erfc(|x|/sqrt2) = t exp(-z^2 + P(t)), t = 1/(1 + z/2) (Numerical Recipes
// erfcc, relative error < 1.2e-7 over all z), so GELU has a small RELATIVE error also for x << 0.
// tanh: odd polynomial for |x| < 0.625 (Cephes tanhf), 1 - 2/(e^{2|x|} + 1) above.
// GCC 12 reports the intrinsics' internal _mm512_undefined_ps() as uninitialised once inlined
// (a known false positive of the header); nothing in this file reads undefined lanes.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#include <immintrin.h>

#include <cmath>

#include "attention/runtime/masked_avx512.h"
#include "attention/runtime/ops.h"

namespace macro::detail {
namespace {

inline __mmask16 tail_mask(int64_t rem) {
  return rem >= 16 ? __mmask16(0xffff) : __mmask16((1u << rem) - 1u);
}

// p[k] = (..((p[k] r[k] + c[0]) r[k] + c[1]) ..) r[k] + c[N - 1] for each of V vectors.
template <int V, int N>
inline void horner_n(__m512 (&p)[V], const __m512 (&r)[V], const float (&c)[N]) {
#pragma GCC unroll 9
  for (int j = 0; j < N; ++j)
#pragma GCC unroll 4
    for (int k = 0; k < V; ++k) p[k] = _mm512_fmadd_ps(p[k], r[k], _mm512_set1_ps(c[j]));
}

// exp and GELU of V vectors, step by step across them: each lane's operations and their order
// do not depend on V (the same bits), but for V > 1 neighbouring instructions are independent, so
// the core overlaps the vectors' long dependency chains (division, polynomials, exponential) that
// one vector at a time leaves waiting on latency.
template <int V>
inline void exp_n(__m512 (&x)[V]) {
  const __m512 lo = _mm512_set1_ps(-104.0f), hi = _mm512_set1_ps(88.7228391f);
  __m512 n[V], r[V], p[V];
#pragma GCC unroll 4
  for (int k = 0; k < V; ++k) {
    x[k] = _mm512_min_ps(hi, _mm512_max_ps(lo, x[k]));  // constant first: NaN passes through
    n[k] = _mm512_roundscale_ps(_mm512_mul_ps(x[k], _mm512_set1_ps(1.44269504088896341f)),
                                _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
  }
#pragma GCC unroll 4
  for (int k = 0; k < V; ++k) {
    r[k] = _mm512_fnmadd_ps(n[k], _mm512_set1_ps(0.693359375f), x[k]);
    r[k] = _mm512_fnmadd_ps(n[k], _mm512_set1_ps(-2.12194440e-4f), r[k]);
    p[k] = _mm512_set1_ps(1.9875691500e-4f);
  }
  const float c[5] = {1.3981999507e-3f, 8.3334519073e-3f, 4.1665795894e-2f, 1.6666665459e-1f,
                      5.0000001201e-1f};
  horner_n(p, r, c);
#pragma GCC unroll 4
  for (int k = 0; k < V; ++k) {
    const __m512 r2 = _mm512_mul_ps(r[k], r[k]);
    const __m512 y = _mm512_fmadd_ps(p[k], r2, _mm512_add_ps(r[k], _mm512_set1_ps(1.0f)));
    x[k] = _mm512_scalef_ps(y, n[k]);
  }
}

inline __m512 exp16(__m512 x) {
  __m512 v[1] = {x};
  exp_n(v);
  return v[0];
}

inline __m512 silu16(__m512 x) {
  const __m512 one = _mm512_set1_ps(1.0f);
  return _mm512_div_ps(x, _mm512_add_ps(one, exp16(_mm512_sub_ps(_mm512_setzero_ps(), x))));
}

// Phi(x) * x, via erfc.
template <int V>
inline void gelu_n(__m512 (&x)[V]) {
  const __m512 one = _mm512_set1_ps(1.0f), half = _mm512_set1_ps(0.5f);
  __m512 z[V], t[V], p[V], e[V];
#pragma GCC unroll 4
  for (int k = 0; k < V; ++k) {
    z[k] = _mm512_mul_ps(_mm512_abs_ps(x[k]), _mm512_set1_ps(0.70710678118654752f));
    t[k] = _mm512_div_ps(one, _mm512_fmadd_ps(half, z[k], one));
    p[k] = _mm512_set1_ps(0.17087277f);
  }
  const float c[9] = {-0.82215223f, 1.48851587f, -1.13520398f, 0.27886807f, -0.18628806f,
                      0.09678418f,  0.37409196f, 1.00002368f,  -1.26551223f};
  horner_n(p, t, c);
#pragma GCC unroll 4
  for (int k = 0; k < V; ++k) e[k] = _mm512_fnmadd_ps(z[k], z[k], p[k]);  // -z^2 + P(t)
  exp_n(e);
#pragma GCC unroll 4
  for (int k = 0; k < V; ++k) {
    const __m512 half_erfc = _mm512_mul_ps(_mm512_mul_ps(half, t[k]), e[k]);
    // x >= 0: Phi = 1 - erfc/2; x < 0: Phi = erfc/2
    const __mmask16 neg = _mm512_cmp_ps_mask(x[k], _mm512_setzero_ps(), _CMP_LT_OQ);
    const __m512 phi = _mm512_mask_blend_ps(neg, _mm512_sub_ps(one, half_erfc), half_erfc);
    x[k] = _mm512_mul_ps(x[k], phi);
  }
}

inline __m512 gelu16(__m512 x) {
  __m512 v[1] = {x};
  gelu_n(v);
  return v[0];
}

inline __m512 tanh16(__m512 x) {
  const __m512 ax = _mm512_abs_ps(x);
  // small: x + x^3 P(x^2)
  const __m512 z = _mm512_mul_ps(x, x);
  __m512 p = _mm512_set1_ps(-5.70498872745e-3f);
  p = _mm512_fmadd_ps(p, z, _mm512_set1_ps(2.06390887954e-2f));
  p = _mm512_fmadd_ps(p, z, _mm512_set1_ps(-5.37397155531e-2f));
  p = _mm512_fmadd_ps(p, z, _mm512_set1_ps(1.33314422036e-1f));
  p = _mm512_fmadd_ps(p, z, _mm512_set1_ps(-3.33332819422e-1f));
  const __m512 small = _mm512_fmadd_ps(_mm512_mul_ps(p, z), x, x);
  // large: sign(x) * (1 - 2 / (exp(2|x|) + 1))
  const __m512 one = _mm512_set1_ps(1.0f);
  const __m512 e = exp16(_mm512_add_ps(ax, ax));
  __m512 big = _mm512_sub_ps(one, _mm512_div_ps(_mm512_set1_ps(2.0f), _mm512_add_ps(e, one)));
  // copy the sign of x
  const __m512i sign =
      _mm512_and_si512(_mm512_castps_si512(x), _mm512_set1_epi32(int(0x80000000u)));
  big = _mm512_castsi512_ps(_mm512_or_si512(_mm512_castps_si512(big), sign));
  const __mmask16 is_small = _mm512_cmp_ps_mask(ax, _mm512_set1_ps(0.625f), _CMP_LT_OQ);
  return _mm512_mask_blend_ps(is_small, big, small);
}

inline __m512 apply_act(__m512 v, Act act) {
  switch (act) {
    case Act::kNone:
      return v;
    case Act::kSilu:
      return silu16(v);
    case Act::kRelu:
      return _mm512_max_ps(v, _mm512_setzero_ps());
    case Act::kGelu:
      return gelu16(v);
    case Act::kTanh:
      return tanh16(v);
  }
  return v;
}

template <Act A>
void act_loop(float* dst, const float* src, int64_t n) {
  for (int64_t i = 0; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    store_lanes(dst + i, m, apply_act(load_lanes(m, src + i), A));
  }
}

void act512(float* dst, const float* src, int64_t n, Act act) {
  switch (act) {
    case Act::kNone:
      act_loop<Act::kNone>(dst, src, n);
      break;
    case Act::kSilu:
      act_loop<Act::kSilu>(dst, src, n);
      break;
    case Act::kRelu:
      act_loop<Act::kRelu>(dst, src, n);
      break;
    case Act::kGelu:
      act_loop<Act::kGelu>(dst, src, n);
      break;
    case Act::kTanh:
      act_loop<Act::kTanh>(dst, src, n);
      break;
  }
}

template <Act A>
void affine_loop(float* dst, const float* src, int64_t n, double mean, float a, float b) {
  const float hi = float(mean), lo = float(mean - double(hi));
  const __m512 vh = _mm512_set1_ps(hi), vl = _mm512_set1_ps(lo);
  const __m512 va = _mm512_set1_ps(a), vb = _mm512_set1_ps(b);
  for (int64_t i = 0; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    const __m512 d = _mm512_sub_ps(_mm512_sub_ps(load_lanes(m, src + i), vh), vl);
    store_lanes(dst + i, m, apply_act(_mm512_fmadd_ps(d, va, vb), A));
  }
}

void affine_act512(float* dst, const float* src, int64_t n, double mean, float a, float b,
                   Act act) {
  switch (act) {
    case Act::kNone:
      affine_loop<Act::kNone>(dst, src, n, mean, a, b);
      break;
    case Act::kSilu:
      affine_loop<Act::kSilu>(dst, src, n, mean, a, b);
      break;
    case Act::kRelu:
      affine_loop<Act::kRelu>(dst, src, n, mean, a, b);
      break;
    case Act::kGelu:
      affine_loop<Act::kGelu>(dst, src, n, mean, a, b);
      break;
    case Act::kTanh:
      affine_loop<Act::kTanh>(dst, src, n, mean, a, b);
      break;
  }
}

void norm_row512(float* dst, const float* src, int64_t n, double mean, float rstd,
                 const float* gamma, const float* beta) {
  const float hi = float(mean), lo = float(mean - double(hi));
  const __m512 vh = _mm512_set1_ps(hi), vl = _mm512_set1_ps(lo), vr = _mm512_set1_ps(rstd);
  for (int64_t i = 0; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    const __m512 d = _mm512_sub_ps(_mm512_sub_ps(load_lanes(m, src + i), vh), vl);
    __m512 y = _mm512_mul_ps(d, vr);
    if (gamma) y = _mm512_mul_ps(y, load_lanes(m, gamma + i));
    if (beta) y = _mm512_add_ps(y, load_lanes(m, beta + i));
    store_lanes(dst + i, m, y);
  }
}

// fp32 lane accumulators over blocks of 1024 values, each block flushed to double. Values are
// summed relative to x[0] so a large common offset (|mean| >> std) costs no accuracy.
double sum512(const float* x, int64_t n) {
  if (n <= 0) return 0.0;
  const __m512 shift = _mm512_set1_ps(x[0]);
  double total = 0;
  for (int64_t b = 0; b < n; b += 1024) {
    const int64_t e = std::min<int64_t>(n, b + 1024);
    __m512 acc0 = _mm512_setzero_ps(), acc1 = _mm512_setzero_ps();
    int64_t i = b;
    for (; i + 32 <= e; i += 32) {
      acc0 = _mm512_add_ps(acc0, _mm512_sub_ps(_mm512_loadu_ps(x + i), shift));
      acc1 = _mm512_add_ps(acc1, _mm512_sub_ps(_mm512_loadu_ps(x + i + 16), shift));
    }
    for (; i < e; i += 16) {
      const __mmask16 m = tail_mask(e - i);
      acc0 = _mm512_add_ps(acc0, _mm512_maskz_sub_ps(m, load_lanes(m, x + i), shift));
    }
    const __m512 acc = _mm512_add_ps(acc0, acc1);
    const __m512d lo = _mm512_cvtps_pd(_mm512_castps512_ps256(acc));
    const __m512d hi =
        _mm512_cvtps_pd(_mm256_castpd_ps(_mm512_extractf64x4_pd(_mm512_castps_pd(acc), 1)));
    total += _mm512_reduce_add_pd(_mm512_add_pd(lo, hi));
  }
  return total + double(n) * double(x[0]);
}

double sum_sq_dev512(const float* x, int64_t n, double mean) {
  double total = 0;
  const __m512 vm = _mm512_set1_ps(float(mean));
  // The float mean's rounding error d = float(mean) - mean adds n*d^2 - 2 d sum(x - fmean)... we
  // keep it exact enough by centring on the float mean and correcting with the block sums.
  double block_sum = 0;  // sum of (x - fmean)
  for (int64_t b = 0; b < n; b += 1024) {
    const int64_t e = std::min<int64_t>(n, b + 1024);
    __m512 acc = _mm512_setzero_ps(), acc_d = _mm512_setzero_ps();
    for (int64_t i = b; i < e; i += 16) {
      const __mmask16 m = tail_mask(e - i);
      const __m512 d = _mm512_maskz_sub_ps(m, load_lanes(m, x + i), vm);
      acc = _mm512_fmadd_ps(d, d, acc);
      acc_d = _mm512_add_ps(acc_d, d);
    }
    total += double(_mm512_reduce_add_ps(acc));
    block_sum += double(_mm512_reduce_add_ps(acc_d));
  }
  // sum (x - mean)^2 = sum (x - fm)^2 + 2 (fm - mean) sum (x - fm) + n (fm - mean)^2
  const double dm = double(float(mean)) - mean;
  return total + 2.0 * dm * block_sum + double(n) * dm * dm;
}

void softmax512(float* dst, const float* src, int64_t n, float scale) {
  if (n == 0) return;
  const __m512 vs = _mm512_set1_ps(scale);
  __m512 vmax = _mm512_set1_ps(-INFINITY);
  for (int64_t i = 0; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    vmax = _mm512_mask_max_ps(vmax, m, vmax, _mm512_mul_ps(load_lanes(m, src + i), vs));
  }
  const __m512 mx = _mm512_set1_ps(_mm512_reduce_max_ps(vmax));
  __m512 vsum = _mm512_setzero_ps();
  for (int64_t i = 0; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    const __m512 e = exp16(_mm512_sub_ps(_mm512_mul_ps(load_lanes(m, src + i), vs), mx));
    store_lanes(dst + i, m, e);
    vsum = _mm512_mask_add_ps(vsum, m, vsum, e);
  }
  const __m512 inv = _mm512_set1_ps(float(1.0 / double(_mm512_reduce_add_ps(vsum))));
  for (int64_t i = 0; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    store_lanes(dst + i, m, _mm512_mul_ps(load_lanes(m, dst + i), inv));
  }
}

// GEGLU takes the GELU of 4 vectors at a time (gelu_n): the GEGLU group of 64 columns.
constexpr int kGeluVectors = 4;

void geglu512(float* dst, const float* v, const float* g, int64_t n) {
  int64_t i = 0;
  for (; i + 16 * kGeluVectors <= n; i += 16 * kGeluVectors) {
    __m512 x[kGeluVectors];
#pragma GCC unroll 4
    for (int k = 0; k < kGeluVectors; ++k) x[k] = _mm512_loadu_ps(g + i + 16 * k);
    gelu_n(x);
#pragma GCC unroll 4
    for (int k = 0; k < kGeluVectors; ++k)
      _mm512_storeu_ps(dst + i + 16 * k, _mm512_mul_ps(_mm512_loadu_ps(v + i + 16 * k), x[k]));
  }
  for (; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    const __m512 y =
        _mm512_mul_ps(load_lanes(m, v + i), gelu16(load_lanes(m, g + i)));
    store_lanes(dst + i, m, y);
  }
}

void axpby512(float* dst, float a, const float* x, float b, const float* y, int64_t n) {
  const __m512 va = _mm512_set1_ps(a), vb = _mm512_set1_ps(b);
  for (int64_t i = 0; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    const __m512 r = _mm512_add_ps(_mm512_mul_ps(va, load_lanes(m, x + i)),
                                   _mm512_mul_ps(vb, load_lanes(m, y + i)));
    store_lanes(dst + i, m, r);
  }
}

// 16 floats to bf16 bits in the low half of each 32-bit lane, as f32_to_bf16: nearest even by
// integer rounding (so denormals are kept, unlike VCVTNEPS2BF16), NaN quieted.
inline __m512i bf16_lanes(__m512 x) {
  const __m512i u = _mm512_castps_si512(x);
  const __m512i lsb = _mm512_and_si512(_mm512_srli_epi32(u, 16), _mm512_set1_epi32(1));
  const __m512i r =
      _mm512_srli_epi32(_mm512_add_epi32(u, _mm512_add_epi32(lsb, _mm512_set1_epi32(0x7fff))), 16);
  const __mmask16 nan = _mm512_cmpgt_epu32_mask(_mm512_and_si512(u, _mm512_set1_epi32(0x7fffffff)),
                                                _mm512_set1_epi32(0x7f800000));
  const __m512i q = _mm512_or_si512(_mm512_srli_epi32(u, 16), _mm512_set1_epi32(0x40));
  return _mm512_mask_blend_epi32(nan, r, q);
}

void pair_words512(uint32_t* dst, const float* lo, const float* hi, int64_t n) {
  for (int64_t i = 0; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    __m512i w = bf16_lanes(load_lanes(m, lo + i));
    if (hi)
      w = _mm512_or_si512(w, _mm512_slli_epi32(bf16_lanes(load_lanes(m, hi + i)), 16));
    store_lanes(dst + i, m, w);
  }
}

void round_bf16_512(float* x, int64_t n) {
  for (int64_t i = 0; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    const __m512i w = _mm512_slli_epi32(bf16_lanes(load_lanes(m, x + i)), 16);
    store_lanes(x + i, m, _mm512_castsi512_ps(w));
  }
}

}  // namespace

void fill_ops_avx512(OpsKernels& t) {
  t.name = "avx512";
  t.act = act512;
  t.affine_act = affine_act512;
  t.norm_row = norm_row512;
  t.sum = sum512;
  t.sum_sq_dev = sum_sq_dev512;
  t.softmax = softmax512;
  t.geglu = geglu512;
  t.axpby = axpby512;
  t.pair_words = pair_words512;
  t.round_bf16 = round_bf16_512;
}

}  // namespace macro::detail
