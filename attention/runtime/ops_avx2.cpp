// AVX2+FMA vector primitives for ops.h (8 fp32 lanes). Same algorithms as ops_avx512.cpp (see
// there for exp/GELU/tanh); tails are processed through an 8-wide stack buffer so every element
// takes the same path. Scalar twins in ops.cpp.
#include <immintrin.h>

#include <cmath>
#include <cstring>

#include "attention/runtime/ops.h"

namespace macro::detail {
namespace {

inline __m256 exp8(__m256 x) {
  x = _mm256_min_ps(_mm256_set1_ps(88.7228391f), _mm256_max_ps(_mm256_set1_ps(-87.3365447f), x));
  const __m256 n = _mm256_round_ps(_mm256_mul_ps(x, _mm256_set1_ps(1.44269504088896341f)),
                                   _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
  __m256 r = _mm256_fnmadd_ps(n, _mm256_set1_ps(0.693359375f), x);
  r = _mm256_fnmadd_ps(n, _mm256_set1_ps(-2.12194440e-4f), r);
  __m256 p = _mm256_set1_ps(1.9875691500e-4f);
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(1.3981999507e-3f));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(8.3334519073e-3f));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(4.1665795894e-2f));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(1.6666665459e-1f));
  p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(5.0000001201e-1f));
  __m256 y = _mm256_fmadd_ps(p, _mm256_mul_ps(r, r), _mm256_add_ps(r, _mm256_set1_ps(1.0f)));
  // 2^n: n in [-126, 128]; split in two factors so n = 128 and n = -126 both stay representable.
  const __m256i ni = _mm256_cvtps_epi32(n);
  const __m256i n1 = _mm256_srai_epi32(ni, 1);
  const __m256i n2 = _mm256_sub_epi32(ni, n1);
  const __m256 s1 =
      _mm256_castsi256_ps(_mm256_slli_epi32(_mm256_add_epi32(n1, _mm256_set1_epi32(127)), 23));
  const __m256 s2 =
      _mm256_castsi256_ps(_mm256_slli_epi32(_mm256_add_epi32(n2, _mm256_set1_epi32(127)), 23));
  return _mm256_mul_ps(_mm256_mul_ps(y, s1), s2);
}

inline __m256 abs8(__m256 x) {
  return _mm256_andnot_ps(_mm256_set1_ps(-0.0f), x);
}

inline __m256 silu8(__m256 x) {
  const __m256 one = _mm256_set1_ps(1.0f);
  return _mm256_div_ps(x, _mm256_add_ps(one, exp8(_mm256_sub_ps(_mm256_setzero_ps(), x))));
}

inline __m256 gelu8(__m256 x) {
  const __m256 one = _mm256_set1_ps(1.0f), half = _mm256_set1_ps(0.5f);
  const __m256 z = _mm256_mul_ps(abs8(x), _mm256_set1_ps(0.70710678118654752f));
  const __m256 t = _mm256_div_ps(one, _mm256_fmadd_ps(half, z, one));
  __m256 p = _mm256_set1_ps(0.17087277f);
  p = _mm256_fmadd_ps(p, t, _mm256_set1_ps(-0.82215223f));
  p = _mm256_fmadd_ps(p, t, _mm256_set1_ps(1.48851587f));
  p = _mm256_fmadd_ps(p, t, _mm256_set1_ps(-1.13520398f));
  p = _mm256_fmadd_ps(p, t, _mm256_set1_ps(0.27886807f));
  p = _mm256_fmadd_ps(p, t, _mm256_set1_ps(-0.18628806f));
  p = _mm256_fmadd_ps(p, t, _mm256_set1_ps(0.09678418f));
  p = _mm256_fmadd_ps(p, t, _mm256_set1_ps(0.37409196f));
  p = _mm256_fmadd_ps(p, t, _mm256_set1_ps(1.00002368f));
  p = _mm256_fmadd_ps(p, t, _mm256_set1_ps(-1.26551223f));
  const __m256 half_erfc = _mm256_mul_ps(_mm256_mul_ps(half, t), exp8(_mm256_fnmadd_ps(z, z, p)));
  const __m256 neg = _mm256_cmp_ps(x, _mm256_setzero_ps(), _CMP_LT_OQ);
  const __m256 phi = _mm256_blendv_ps(_mm256_sub_ps(one, half_erfc), half_erfc, neg);
  return _mm256_mul_ps(x, phi);
}

inline __m256 tanh8(__m256 x) {
  const __m256 ax = abs8(x);
  const __m256 z = _mm256_mul_ps(x, x);
  __m256 p = _mm256_set1_ps(-5.70498872745e-3f);
  p = _mm256_fmadd_ps(p, z, _mm256_set1_ps(2.06390887954e-2f));
  p = _mm256_fmadd_ps(p, z, _mm256_set1_ps(-5.37397155531e-2f));
  p = _mm256_fmadd_ps(p, z, _mm256_set1_ps(1.33314422036e-1f));
  p = _mm256_fmadd_ps(p, z, _mm256_set1_ps(-3.33332819422e-1f));
  const __m256 small = _mm256_fmadd_ps(_mm256_mul_ps(p, z), x, x);
  const __m256 one = _mm256_set1_ps(1.0f);
  const __m256 e = exp8(_mm256_add_ps(ax, ax));
  __m256 big = _mm256_sub_ps(one, _mm256_div_ps(_mm256_set1_ps(2.0f), _mm256_add_ps(e, one)));
  big = _mm256_or_ps(big, _mm256_and_ps(x, _mm256_set1_ps(-0.0f)));
  return _mm256_blendv_ps(big, small, _mm256_cmp_ps(ax, _mm256_set1_ps(0.625f), _CMP_LT_OQ));
}

inline __m256 apply_act(__m256 v, Act act) {
  switch (act) {
    case Act::kNone:
      return v;
    case Act::kSilu:
      return silu8(v);
    case Act::kRelu:
      return _mm256_max_ps(v, _mm256_setzero_ps());
    case Act::kGelu:
      return gelu8(v);
    case Act::kTanh:
      return tanh8(v);
  }
  return v;
}

// Runs body(dst8, src8...) over full vectors and the tail through zero-padded buffers.
template <typename Body>
void for_each8(float* dst, const float* a, const float* b, int64_t n, Body body) {
  int64_t i = 0;
  for (; i + 8 <= n; i += 8)
    _mm256_storeu_ps(
        dst + i, body(_mm256_loadu_ps(a + i), b ? _mm256_loadu_ps(b + i) : _mm256_setzero_ps()));
  if (i < n) {
    alignas(32) float ta[8] = {}, tb[8] = {}, td[8];
    const size_t rem = size_t(n - i);
    std::memcpy(ta, a + i, rem * 4);
    if (b) std::memcpy(tb, b + i, rem * 4);
    _mm256_store_ps(td, body(_mm256_load_ps(ta), _mm256_load_ps(tb)));
    std::memcpy(dst + i, td, rem * 4);
  }
}

void act256(float* dst, const float* src, int64_t n, Act act) {
  for_each8(dst, src, nullptr, n, [act](__m256 x, __m256) { return apply_act(x, act); });
}

void affine_act256(float* dst, const float* src, int64_t n, double mean, float a, float b,
                   Act act) {
  const float hi = float(mean), lo = float(mean - double(hi));
  const __m256 vh = _mm256_set1_ps(hi), vl = _mm256_set1_ps(lo);
  const __m256 va = _mm256_set1_ps(a), vb = _mm256_set1_ps(b);
  for_each8(dst, src, nullptr, n, [&](__m256 x, __m256) {
    const __m256 d = _mm256_sub_ps(_mm256_sub_ps(x, vh), vl);
    return apply_act(_mm256_fmadd_ps(d, va, vb), act);
  });
}

void norm_row256(float* dst, const float* src, int64_t n, double mean, float rstd,
                 const float* gamma, const float* beta) {
  const float hi = float(mean), lo = float(mean - double(hi));
  const __m256 vh = _mm256_set1_ps(hi), vl = _mm256_set1_ps(lo), vr = _mm256_set1_ps(rstd);
  int64_t i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m256 d = _mm256_sub_ps(_mm256_sub_ps(_mm256_loadu_ps(src + i), vh), vl);
    __m256 y = _mm256_mul_ps(d, vr);
    if (gamma) y = _mm256_mul_ps(y, _mm256_loadu_ps(gamma + i));
    if (beta) y = _mm256_add_ps(y, _mm256_loadu_ps(beta + i));
    _mm256_storeu_ps(dst + i, y);
  }
  for (; i < n; ++i) {
    float y = float(double(src[i]) - mean) * rstd;
    if (gamma) y *= gamma[i];
    if (beta) y += beta[i];
    dst[i] = y;
  }
}

inline double hsum8(__m256 v) {
  alignas(32) float t[8];
  _mm256_store_ps(t, v);
  double s = 0;
  for (float x : t) s += x;
  return s;
}

// Summed relative to x[0] (see ops_avx512.cpp).
double sum256(const float* x, int64_t n) {
  if (n <= 0) return 0.0;
  const float s0 = x[0];
  const __m256 shift = _mm256_set1_ps(s0);
  double total = 0;
  for (int64_t b = 0; b < n; b += 1024) {
    const int64_t e = std::min<int64_t>(n, b + 1024);
    __m256 acc = _mm256_setzero_ps();
    int64_t i = b;
    for (; i + 8 <= e; i += 8)
      acc = _mm256_add_ps(acc, _mm256_sub_ps(_mm256_loadu_ps(x + i), shift));
    total += hsum8(acc);
    for (; i < e; ++i) total += double(x[i]) - double(s0);
  }
  return total + double(n) * double(s0);
}

double sum_sq_dev256(const float* x, int64_t n, double mean) {
  const float fm = float(mean);
  const __m256 vm = _mm256_set1_ps(fm);
  double total = 0, dsum = 0;
  for (int64_t b = 0; b < n; b += 1024) {
    const int64_t e = std::min<int64_t>(n, b + 1024);
    __m256 acc = _mm256_setzero_ps(), accd = _mm256_setzero_ps();
    int64_t i = b;
    for (; i + 8 <= e; i += 8) {
      const __m256 d = _mm256_sub_ps(_mm256_loadu_ps(x + i), vm);
      acc = _mm256_fmadd_ps(d, d, acc);
      accd = _mm256_add_ps(accd, d);
    }
    total += hsum8(acc);
    dsum += hsum8(accd);
    for (; i < e; ++i) {
      const double d = double(x[i] - fm);
      total += d * d;
      dsum += d;
    }
  }
  const double dm = double(fm) - mean;
  return total + 2.0 * dm * dsum + double(n) * dm * dm;
}

void softmax256(float* dst, const float* src, int64_t n, float scale) {
  if (n == 0) return;
  float mx = -INFINITY;
  for (int64_t i = 0; i < n; ++i) mx = std::max(mx, src[i] * scale);
  const __m256 vs = _mm256_set1_ps(scale), vmx = _mm256_set1_ps(mx);
  __m256 vsum = _mm256_setzero_ps();
  int64_t i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m256 e = exp8(_mm256_sub_ps(_mm256_mul_ps(_mm256_loadu_ps(src + i), vs), vmx));
    _mm256_storeu_ps(dst + i, e);
    vsum = _mm256_add_ps(vsum, e);
  }
  double sum = hsum8(vsum);
  if (i < n) {
    alignas(32) float t[8];
    std::fill(t, t + 8, -INFINITY);
    for (int64_t j = i; j < n; ++j) t[j - i] = src[j] * scale - mx;
    _mm256_store_ps(t, exp8(_mm256_load_ps(t)));
    for (int64_t j = i; j < n; ++j) {
      dst[j] = t[j - i];
      sum += t[j - i];
    }
  }
  const float inv = float(1.0 / sum);
  for (int64_t j = 0; j < n; ++j) dst[j] *= inv;
}

void geglu256(float* dst, const float* v, const float* g, int64_t n) {
  for_each8(dst, v, g, n, [](__m256 a, __m256 b) { return _mm256_mul_ps(a, gelu8(b)); });
}

void axpby256(float* dst, float a, const float* x, float b, const float* y, int64_t n) {
  const __m256 va = _mm256_set1_ps(a), vb = _mm256_set1_ps(b);
  for_each8(dst, x, y, n, [&](__m256 p, __m256 q) {
    return _mm256_add_ps(_mm256_mul_ps(va, p), _mm256_mul_ps(vb, q));
  });
}

// x rounded to bf16 and back, as f32_to_bf16: nearest even by integer rounding (denormals kept),
// a NaN quieted.
void round_bf16_256(float* x, int64_t n) {
  const __m256i one = _mm256_set1_epi32(1), half = _mm256_set1_epi32(0x7fff);
  const __m256i abs_mask = _mm256_set1_epi32(0x7fffffff), inf = _mm256_set1_epi32(0x7f800000);
  const __m256i high = _mm256_set1_epi32(int(0xffff0000u)), quiet = _mm256_set1_epi32(0x400000);
  for_each8(x, x, nullptr, n, [&](__m256 v, __m256) {
    const __m256i u = _mm256_castps_si256(v);
    const __m256i lsb = _mm256_and_si256(_mm256_srli_epi32(u, 16), one);
    const __m256i r = _mm256_and_si256(_mm256_add_epi32(u, _mm256_add_epi32(lsb, half)), high);
    // NaN: |u| > inf as signed integers (the sign bit is cleared, so the compare is exact).
    const __m256i nan = _mm256_cmpgt_epi32(_mm256_and_si256(u, abs_mask), inf);
    const __m256i q = _mm256_or_si256(_mm256_and_si256(u, high), quiet);
    return _mm256_castsi256_ps(_mm256_blendv_epi8(r, q, nan));
  });
}

}  // namespace

void fill_ops_avx2(OpsKernels& t) {
  t.name = "avx2";
  t.act = act256;
  t.affine_act = affine_act256;
  t.norm_row = norm_row256;
  t.sum = sum256;
  t.sum_sq_dev = sum_sq_dev256;
  t.softmax = softmax256;
  t.geglu = geglu256;
  t.axpby = axpby256;
  t.round_bf16 = round_bf16_256;
}

}  // namespace macro::detail
