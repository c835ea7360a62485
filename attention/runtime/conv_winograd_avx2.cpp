// AVX2 Winograd F(2x2, 3x3) transforms (the WinoInput / WinoOutput contracts in conv_winograd.h):
// the vector transforms of conv_winograd_simd.h with 8 tiles per vector (a run of up to 16 tiles
// in two steps), bit-identical to the scalar twins in conv_winograd.cpp. fp32 input: V of one
// channel; bf16 input: V of two channels rounded to bf16 in integer ops (nearest even, NaN quiet,
// denormals to zero: the scalar bf16_bits_daz) and joined into pair words (even channel low).
#include <immintrin.h>

#include <algorithm>
#include <cstdint>

#include "attention/runtime/conv_winograd_simd.h"

namespace macro {
namespace {

struct WinoAvx2 {
  using V = __m256;
  using Vi = __m256i;
  using M = __m256i;  // lanes with all bits set (vmaskmovps / vpmaskmovd)
  static constexpr int W = 8;
  // Lanes e in [0, 8) with 0 <= start + e < limit.
  static M lanes(int64_t start, int64_t limit) {
    const __m256i e = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    const int lo = int(std::clamp<int64_t>(-start, 0, 8));           // first lane inside
    const int hi = int(std::clamp<int64_t>(limit - start, -1, 8));  // lanes below it inside
    return _mm256_andnot_si256(_mm256_cmpgt_epi32(_mm256_set1_epi32(lo), e),
                               _mm256_cmpgt_epi32(_mm256_set1_epi32(hi), e));
  }
  static V load(M m, const float* p) { return _mm256_maskload_ps(p, m); }
  static void store(float* p, M m, V v) { _mm256_maskstore_ps(p, m, v); }
  static void store_words(uint32_t* p, M m, Vi w) {
    _mm256_maskstore_epi32(reinterpret_cast<int*>(p), m, w);
  }
  static V zero() { return _mm256_setzero_ps(); }
  static V set1(float x) { return _mm256_set1_ps(x); }
  static V add(V a, V b) { return _mm256_add_ps(a, b); }
  static V sub(V a, V b) { return _mm256_sub_ps(a, b); }
  static V max(V a, V b) { return _mm256_max_ps(a, b); }
  // (a0 a2 a4 a6 b0 b2 b4 b6): per 128-bit half, then the 64-bit quarters put in order.
  static V evens(V a, V b) {
    const __m256 t = _mm256_shuffle_ps(a, b, _MM_SHUFFLE(2, 0, 2, 0));
    return _mm256_castpd_ps(_mm256_permute4x64_pd(_mm256_castps_pd(t), _MM_SHUFFLE(3, 1, 2, 0)));
  }
  static V odds(V a, V b) {
    const __m256 t = _mm256_shuffle_ps(a, b, _MM_SHUFFLE(3, 1, 3, 1));
    return _mm256_castpd_ps(_mm256_permute4x64_pd(_mm256_castps_pd(t), _MM_SHUFFLE(3, 1, 2, 0)));
  }
  static void interleave(V y0, V y1, V* lo, V* hi) {
    const __m256 u = _mm256_unpacklo_ps(y0, y1), w = _mm256_unpackhi_ps(y0, y1);
    *lo = _mm256_permute2f128_ps(u, w, 0x20);
    *hi = _mm256_permute2f128_ps(u, w, 0x31);
  }
};

// bf16 bits of 8 floats in 32-bit lanes, as the scalar bf16_bits_daz rounds: nearest even, NaN
// quiet, fp32 denormals to signed zero.
inline __m256i bf16_bits_daz8(__m256 v) {
  const __m256i u = _mm256_castps_si256(v);
  const __m256i top = _mm256_srli_epi32(u, 16);
  const __m256i r = _mm256_srli_epi32(
      _mm256_add_epi32(_mm256_add_epi32(u, _mm256_set1_epi32(0x7fff)),
                       _mm256_and_si256(top, _mm256_set1_epi32(1))),
      16);
  // |u| > inf as signed 32-bit integers (both sides non-negative).
  const __m256i nan = _mm256_cmpgt_epi32(_mm256_and_si256(u, _mm256_set1_epi32(0x7fffffff)),
                                         _mm256_set1_epi32(0x7f800000));
  const __m256i tiny = _mm256_cmpeq_epi32(_mm256_and_si256(u, _mm256_set1_epi32(0x7f800000)),
                                          _mm256_setzero_si256());  // exponent field zero
  __m256i out = _mm256_blendv_epi8(r, _mm256_or_si256(top, _mm256_set1_epi32(0x40)), nan);
  return _mm256_blendv_epi8(out, _mm256_and_si256(top, _mm256_set1_epi32(0x8000)), tiny);
}

void input_f32_avx2(const detail::WinoInput& a) { winograd_input_f32<WinoAvx2>(a); }

void input_bf16_avx2(const detail::WinoInput& a) {
  winograd_input_bf16<WinoAvx2>(a, [](__m256 v0, __m256 v1) {
    return _mm256_or_si256(bf16_bits_daz8(v0), _mm256_slli_epi32(bf16_bits_daz8(v1), 16));
  });
}

void output_avx2(const detail::WinoOutput& a) { winograd_output<WinoAvx2>(a); }

}  // namespace

namespace detail {
const WinogradTransforms* winograd_avx2_transforms(bool f32) {
  static const WinogradTransforms tf{input_f32_avx2, output_avx2, "avx2"};
  static const WinogradTransforms tb{input_bf16_avx2, output_avx2,
                                     "avx2 (bf16 rounded in integer ops)"};
  return f32 ? &tf : &tb;
}
}  // namespace detail

}  // namespace macro
