// The AVX-512 fp32 vector traits of the attention block kernel (attention_simd.h), shared by the
// fp32 (attention_avx512.cpp) and bf16 (attention_avx512bf16.cpp) instantiations. Include it only
// from *_avx512*.cpp files (it uses AVX-512F intrinsics).
#pragma once
// GCC 12's _mm512_undefined_* helpers trip -Wuninitialized once inlined (GCC bug 105593).
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include <cstdint>

#include "attention/runtime/attention_simd.h"

namespace macro::attention_detail {
namespace {

struct Avx512 {
  using V = __m512;
  static constexpr int W = 16;
  static constexpr int kScoreRows = 6, kScoreVecs = 4;
  static constexpr int kPvRows = 6, kPvVecs = 4;

  static V load(const float* p) { return _mm512_loadu_ps(p); }
  static void store(float* p, V v) { _mm512_storeu_ps(p, v); }
  static V set1(float x) { return _mm512_set1_ps(x); }
  static V zero() { return _mm512_setzero_ps(); }
  static V fma(V a, V b, V c) { return _mm512_fmadd_ps(a, b, c); }
  static V mul(V a, V b) { return _mm512_mul_ps(a, b); }
  static V add(V a, V b) { return _mm512_add_ps(a, b); }
  static V sub(V a, V b) { return _mm512_sub_ps(a, b); }
  static V max(V a, V b) { return _mm512_max_ps(a, b); }

  static V exp2(V x) {
    x = _mm512_max_ps(x, _mm512_set1_ps(-127.0f));
    x = _mm512_min_ps(x, _mm512_set1_ps(127.0f));
    const V n = _mm512_roundscale_ps(x, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
    const V f = _mm512_sub_ps(x, n);
    V p = _mm512_set1_ps(kExp2Coef[7]);
    for (int k = 6; k >= 0; --k) p = _mm512_fmadd_ps(p, f, _mm512_set1_ps(kExp2Coef[k]));
    // 2^n from the exponent field; n = -127 gives the bit pattern of 0.0f.
    const __m512i e =
        _mm512_slli_epi32(_mm512_add_epi32(_mm512_cvtps_epi32(n), _mm512_set1_epi32(127)), 23);
    return _mm512_mul_ps(p, _mm512_castsi512_ps(e));
  }
  static V mask_tile(V s, const uint8_t* t) {
    const __m128i b = _mm_loadu_si128(reinterpret_cast<const __m128i*>(t));
    const __mmask16 allowed = _mm_test_epi8_mask(b, b);
    return _mm512_mask_blend_ps(allowed, _mm512_set1_ps(-__builtin_inff()), s);
  }
};

}  // namespace
}  // namespace macro::attention_detail
