// AVX-512 (fp32) instantiation of the fused attention block kernel (attention_simd.h).
// Score tile S^T: 6 keys x 4 zmm (64 queries) = 24 accumulators; P V: 6 query rows x 4 zmm
// (64 channels).
#include "attention/runtime/attention_avx512_traits.h"
#include "attention/runtime/attention_simd.h"

namespace macro::attention_detail {
namespace {

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
