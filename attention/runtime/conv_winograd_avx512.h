// The AVX-512 traits of the Winograd F(2x2, 3x3) vector transforms (conv_winograd_simd.h), shared
// by the fp32 and bf16 transform files (conv_winograd_avx512.cpp, conv_winograd_avx512bf16.cpp):
// 16 tiles per vector, lane masks as k-registers, even / odd columns split by vpermt2ps.
// Include ONLY from files compiled with AVX-512 flags; internal linkage, so each ISA file keeps
// its own copy compiled with its own flags.
#pragma once

#include <immintrin.h>

#include <cstdint>

#include "attention/runtime/conv_winograd_simd.h"

namespace macro {
namespace {

struct WinoAvx512 {
  using V = __m512;
  using Vi = __m512i;
  using M = __mmask16;
  static constexpr int W = 16;
  // Lanes e in [0, 16) with 0 <= start + e < limit.
  static M lanes(int64_t start, int64_t limit) {
    const int64_t lo = start < 0 ? -start : 0;
    const int64_t hi = limit - start < 16 ? limit - start : 16;
    if (lo >= hi) return 0;
    const uint32_t bits = ((hi >= 16 ? 0x10000u : (1u << hi)) - 1u) & ~((1u << lo) - 1u);
    return M(bits);
  }
  static V load(M m, const float* p) { return _mm512_maskz_loadu_ps(m, p); }
  static void store(float* p, M m, V v) { _mm512_mask_storeu_ps(p, m, v); }
  static void store_words(uint32_t* p, M m, Vi w) { _mm512_mask_storeu_epi32(p, m, w); }
  static V zero() { return _mm512_setzero_ps(); }
  static V set1(float x) { return _mm512_set1_ps(x); }
  static V add(V a, V b) { return _mm512_add_ps(a, b); }
  static V sub(V a, V b) { return _mm512_sub_ps(a, b); }
  static V max(V a, V b) { return _mm512_max_ps(a, b); }
  static V evens(V a, V b) {
    return _mm512_permutex2var_ps(
        a, _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30), b);
  }
  static V odds(V a, V b) {
    return _mm512_permutex2var_ps(
        a, _mm512_setr_epi32(1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31), b);
  }
  static void interleave(V y0, V y1, V* lo, V* hi) {
    *lo = _mm512_permutex2var_ps(
        y0, _mm512_setr_epi32(0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23), y1);
    *hi = _mm512_permutex2var_ps(
        y0, _mm512_setr_epi32(8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31), y1);
  }
};

}  // namespace
}  // namespace macro
