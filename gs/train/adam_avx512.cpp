// The Adam update on the AVX-512 path (adam_kernels.h): 8 doubles per step, the scalar twin's
// operations one for one. The explicitly rounded forms (_round_pd, round to nearest) are builtins
// the compiler never contracts into FMA, so the bits are the scalar loop's.
// GCC 12's avx512fintrin.h trips -Wmaybe-uninitialized on its own _mm512_undefined_* (a
// false positive, as in attention/runtime/conv_avx512.cpp).
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include "gs/train/adam_kernels.h"

namespace macro::gs::train {
namespace {

constexpr int kRound = _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC;
inline __m512d mul(__m512d a, __m512d b) {
  return _mm512_mul_round_pd(a, b, kRound);
}
inline __m512d add(__m512d a, __m512d b) {
  return _mm512_add_round_pd(a, b, kRound);
}

}  // namespace

void adam_rows_avx512(double* m, double* v, const float* g, float* p, size_t n,
                      const AdamCoefficients& c) {
  const __m512d b1 = _mm512_set1_pd(c.beta1), c1 = _mm512_set1_pd(c.one_minus_beta1);
  const __m512d b2 = _mm512_set1_pd(c.beta2), c2 = _mm512_set1_pd(c.one_minus_beta2);
  const __m512d step = _mm512_set1_pd(c.step_size), bs = _mm512_set1_pd(c.bias2_sqrt);
  const __m512d eps = _mm512_set1_pd(c.eps);
  size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m512d gi = _mm512_cvtps_pd(_mm256_loadu_ps(g + i));
    const __m512d mi = add(mul(b1, _mm512_loadu_pd(m + i)), mul(c1, gi));
    const __m512d vi = add(mul(b2, _mm512_loadu_pd(v + i)), mul(mul(c2, gi), gi));
    _mm512_storeu_pd(m + i, mi);
    _mm512_storeu_pd(v + i, vi);
    const __m512d denom =
        add(_mm512_div_round_pd(_mm512_sqrt_round_pd(vi, kRound), bs, kRound), eps);
    const __m512d pi = _mm512_cvtps_pd(_mm256_loadu_ps(p + i));
    const __m512d out =
        _mm512_sub_round_pd(pi, _mm512_div_round_pd(mul(step, mi), denom, kRound), kRound);
    _mm256_storeu_ps(p + i, _mm512_cvtpd_ps(out));
  }
  if (i < n) adam_rows_scalar(m + i, v + i, g + i, p + i, n - i, c);
}

}  // namespace macro::gs::train
