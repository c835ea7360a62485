// AVX-512 (fp32) instantiation of the fused attention block kernel (attention_simd.h).
// Score tile S^T: 6 keys x 4 zmm (64 queries) = 24 accumulators; P V: 6 query rows x 4 zmm
// (64 channels).
// GCC 12's _mm512_undefined_* helpers trip -Wuninitialized once inlined (GCC bug 105593).
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

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

double fma_peak_avx512(int64_t iterations) {
  // 12 independent accumulator chains hide the FMA latency (4 cycles x up to 2 pipes, plus slack).
  __m512 a[12];
  for (int i = 0; i < 12; ++i) a[i] = _mm512_set1_ps(1.0f + 0.001f * i);
  const __m512 x = _mm512_set1_ps(0.999999f), y = _mm512_set1_ps(1e-7f);
  for (int64_t it = 0; it < iterations; ++it) {
    for (int i = 0; i < 12; ++i) a[i] = _mm512_fmadd_ps(a[i], x, y);
  }
  __m512 s = a[0];
  for (int i = 1; i < 12; ++i) s = _mm512_add_ps(s, a[i]);
  volatile float sink = _mm512_reduce_add_ps(s);
  (void)sink;
  return 2.0 * 16 * 12 * double(iterations);
}

}  // namespace

const AttentionKernels& avx512_kernels() {
  static const AttentionKernels k{Isa::kAvx512, Avx512::W, blocks_simd<Avx512>,
                                  score_tile_simd<Avx512>, fma_peak_avx512};
  return k;
}

}  // namespace macro::attention_detail
