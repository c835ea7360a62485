// bf16 pair words from fp32 vectors with one vcvtne2ps2bf16, and a 16 x 16 word transpose: the
// A packers of the AVX512-BF16 and AMX GEMM kernels and the Q / P packing of the bf16 attention
// kernels (attention_bf16_simd.h). Include ONLY from files compiled with AVX512-BF16 flags;
// internal linkage, like gemm_store_avx512.h.
#pragma once

#include <immintrin.h>

#include <cstdint>

namespace macro {
namespace {

// 16 words whose low halves are bf16(lo[i]) and high halves bf16(hi[i]) (nearest even; fp32
// denormal inputs become zero, as the instruction treats them).
inline __m512i bf16_pair_words(__m512 lo, __m512 hi) {
  // cvtne2ps(hi, lo) gives [bf16(lo) x 16, bf16(hi) x 16]; word i needs (lo[i], hi[i]).
  const __m512i idx = _mm512_set_epi16(31, 15, 30, 14, 29, 13, 28, 12, 27, 11, 26, 10, 25, 9, 24, 8,
                                       23, 7, 22, 6, 21, 5, 20, 4, 19, 3, 18, 2, 17, 1, 16, 0);
  return _mm512_permutexvar_epi16(idx, (__m512i)_mm512_cvtne2ps_pbh(hi, lo));
}

// In-register transpose of a 16 x 16 block of 32-bit words: r[i] lane j -> r[j] lane i.
inline void transpose_16x16_words(__m512i* r) {
  __m512i t[16];
  for (int i = 0; i < 16; i += 2) {
    t[i] = _mm512_unpacklo_epi32(r[i], r[i + 1]);
    t[i + 1] = _mm512_unpackhi_epi32(r[i], r[i + 1]);
  }
  for (int i = 0; i < 16; i += 4) {
    r[i] = _mm512_unpacklo_epi64(t[i], t[i + 2]);
    r[i + 1] = _mm512_unpackhi_epi64(t[i], t[i + 2]);
    r[i + 2] = _mm512_unpacklo_epi64(t[i + 1], t[i + 3]);
    r[i + 3] = _mm512_unpackhi_epi64(t[i + 1], t[i + 3]);
  }
  // Each 128-bit lane now holds a transposed 4 x 4 block; two rounds of 128-bit lane shuffles put
  // the blocks in place.
  for (int c = 0; c < 4; ++c) {
    t[c] = _mm512_shuffle_i32x4(r[c], r[4 + c], 0x88);
    t[4 + c] = _mm512_shuffle_i32x4(r[c], r[4 + c], 0xdd);
    t[8 + c] = _mm512_shuffle_i32x4(r[8 + c], r[12 + c], 0x88);
    t[12 + c] = _mm512_shuffle_i32x4(r[8 + c], r[12 + c], 0xdd);
  }
  for (int c = 0; c < 4; ++c) {
    r[c] = _mm512_shuffle_i32x4(t[c], t[8 + c], 0x88);
    r[8 + c] = _mm512_shuffle_i32x4(t[c], t[8 + c], 0xdd);
    r[4 + c] = _mm512_shuffle_i32x4(t[4 + c], t[12 + c], 0x88);
    r[12 + c] = _mm512_shuffle_i32x4(t[4 + c], t[12 + c], 0xdd);
  }
}

}  // namespace
}  // namespace macro
