// AVX2 + FMA (fp32) instantiation of the fused attention block kernel (attention_simd.h).
// 16 ymm registers: score tile S^T 6 keys x 2 ymm (16 queries per pass) = 12 accumulators; P V
// 6 query rows x 2 ymm (16 channels per pass).
#include <immintrin.h>

#include "attention/runtime/attention_simd.h"

namespace macro::attention_detail {
namespace {

struct Avx2 {
  using V = __m256;
  static constexpr int W = 8;
  static constexpr int kScoreRows = 6, kScoreVecs = 2;
  static constexpr int kPvRows = 6, kPvVecs = 2;

  static V load(const float* p) { return _mm256_loadu_ps(p); }
  static void store(float* p, V v) { _mm256_storeu_ps(p, v); }
  static V set1(float x) { return _mm256_set1_ps(x); }
  static V zero() { return _mm256_setzero_ps(); }
  static V fma(V a, V b, V c) { return _mm256_fmadd_ps(a, b, c); }
  static V mul(V a, V b) { return _mm256_mul_ps(a, b); }
  static V add(V a, V b) { return _mm256_add_ps(a, b); }
  static V sub(V a, V b) { return _mm256_sub_ps(a, b); }
  static V max(V a, V b) { return _mm256_max_ps(a, b); }

  static V exp2(V x) {
    x = _mm256_max_ps(x, _mm256_set1_ps(-127.0f));
    x = _mm256_min_ps(x, _mm256_set1_ps(127.0f));
    const V n = _mm256_round_ps(x, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
    const V f = _mm256_sub_ps(x, n);
    V p = _mm256_set1_ps(kExp2Coef[7]);
    for (int k = 6; k >= 0; --k) p = _mm256_fmadd_ps(p, f, _mm256_set1_ps(kExp2Coef[k]));
    const __m256i e =
        _mm256_slli_epi32(_mm256_add_epi32(_mm256_cvtps_epi32(n), _mm256_set1_epi32(127)), 23);
    return _mm256_mul_ps(p, _mm256_castsi256_ps(e));
  }
  static V mask_tile(V s, const uint8_t* t) {
    const __m256i b = _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(t)));
    const V blocked = _mm256_castsi256_ps(_mm256_cmpeq_epi32(b, _mm256_setzero_si256()));
    return _mm256_blendv_ps(s, _mm256_set1_ps(-__builtin_inff()), blocked);
  }
};

double fma_peak_avx2(int64_t iterations) {
  __m256 a[10];
  for (int i = 0; i < 10; ++i) a[i] = _mm256_set1_ps(1.0f + 0.001f * i);
  const __m256 x = _mm256_set1_ps(0.999999f), y = _mm256_set1_ps(1e-7f);
  for (int64_t it = 0; it < iterations; ++it) {
    for (int i = 0; i < 10; ++i) a[i] = _mm256_fmadd_ps(a[i], x, y);
  }
  __m256 s = a[0];
  for (int i = 1; i < 10; ++i) s = _mm256_add_ps(s, a[i]);
  float buf[8];
  _mm256_storeu_ps(buf, s);
  volatile float sink = buf[0];
  (void)sink;
  return 2.0 * 8 * 10 * double(iterations);
}

}  // namespace

const AttentionKernels& avx2_kernels() {
  static const AttentionKernels k{Isa::kAvx2, Avx2::W, blocks_simd<Avx2>, score_tile_simd<Avx2>,
                                  fma_peak_avx2};
  return k;
}

}  // namespace macro::attention_detail
