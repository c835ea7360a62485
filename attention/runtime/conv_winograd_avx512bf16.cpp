// AVX512-BF16 Winograd F(2x2, 3x3) bf16 input transform (the WinoInput contract in
// conv_winograd.h) and the shared output transform (conv_winograd_avx512.h): 16 tiles of a run
// per vector, one lane per tile, bit-identical to the scalar twins in conv_winograd.cpp.
// Input: V of two channels (16 registers each), rounded to bf16 by one vcvtne2ps2bf16 (nearest
// even, denormals to zero, NaN quiet: the scalar bf16_bits_daz) and interleaved into pair words,
// one masked store per xi; the next pair's rows are prefetched first.
// GCC 12's AVX-512 headers trip -W(maybe-)uninitialized on their own _mm512_undefined_*() idiom.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include <cstdint>

#include "attention/runtime/conv_winograd_avx512.h"

namespace macro {
namespace {

void output_avx512bf16(const detail::WinoOutput& a) { winograd_output<WinoAvx512>(a); }

void input_bf16_avx512(const detail::WinoInput& a) {
  const __m512i pair_idx =
      _mm512_set_epi16(31, 15, 30, 14, 29, 13, 28, 12, 27, 11, 26, 10, 25, 9, 24, 8, 23, 7, 22, 6,
                       21, 5, 20, 4, 19, 3, 18, 2, 17, 1, 16, 0);
  winograd_input_bf16<WinoAvx512>(a, [&](__m512 v0, __m512 v1) {
    // [c0 lanes 0..15 | c1 lanes 0..15] as bf16, interleaved into pair words.
    return _mm512_permutexvar_epi16(pair_idx, (__m512i)_mm512_cvtne2ps_pbh(v1, v0));
  });
}

}  // namespace

namespace detail {
const WinogradTransforms* winograd_avx512bf16_transforms() {
  static const WinogradTransforms t{input_bf16_avx512, output_avx512bf16, "avx512bf16"};
  return &t;
}
}  // namespace detail

}  // namespace macro
