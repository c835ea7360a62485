// The Adam update on the AVX-512 path (adam_kernels.h): 16 floats per step, the scalar twin's
// operations one for one. The explicitly rounded forms (_round_ps, round to nearest) are builtins
// the compiler never contracts into FMA, so the bits are the scalar loop's.
// GCC 12's avx512fintrin.h trips -Wmaybe-uninitialized on its own _mm512_undefined_* (a
// false positive, as in attention/runtime/conv_avx512.cpp).
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#include <immintrin.h>

#include "gs/train/adam_kernels.h"

namespace macro::gs::train {
namespace {

constexpr int kRound = _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC;
inline __m512 mul(__m512 a, __m512 b) {
  return _mm512_mul_round_ps(a, b, kRound);
}
inline __m512 add(__m512 a, __m512 b) {
  return _mm512_add_round_ps(a, b, kRound);
}
inline __m512 sub(__m512 a, __m512 b) {
  return _mm512_sub_round_ps(a, b, kRound);
}

}  // namespace

void adam_rows_avx512(float* m, float* v, const float* g, float* p, size_t n,
                      const AdamCoefficients& c) {
  const __m512 c1 = _mm512_set1_ps(c.one_minus_beta1);
  const __m512 b2 = _mm512_set1_ps(c.beta2), c2 = _mm512_set1_ps(c.one_minus_beta2);
  const __m512 neg_step = _mm512_set1_ps(-c.step_size), bs = _mm512_set1_ps(c.bias2_sqrt);
  const __m512 eps = _mm512_set1_ps(c.eps);
  size_t i = 0;
  for (; i + 16 <= n; i += 16) {
    const __m512 gi = _mm512_loadu_ps(g + i);
    const __m512 m0 = _mm512_loadu_ps(m + i);
    const __m512 mi = add(m0, mul(c1, sub(gi, m0)));
    const __m512 vi = add(mul(b2, _mm512_loadu_ps(v + i)), mul(mul(c2, gi), gi));
    _mm512_storeu_ps(m + i, mi);
    _mm512_storeu_ps(v + i, vi);
    const __m512 denom =
        add(_mm512_div_round_ps(_mm512_sqrt_round_ps(vi, kRound), bs, kRound), eps);
    const __m512 out =
        add(_mm512_loadu_ps(p + i), _mm512_div_round_ps(mul(neg_step, mi), denom, kRound));
    _mm512_storeu_ps(p + i, out);
  }
  if (i < n) adam_rows_scalar(m + i, v + i, g + i, p + i, n - i, c);
}

}  // namespace macro::gs::train
