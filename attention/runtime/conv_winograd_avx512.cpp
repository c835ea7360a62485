// AVX-512 Winograd F(2x2, 3x3) input transforms (the WinoInput contract in conv_winograd.h) and the
// shared output transform (conv_winograd_avx512.h): 16 tiles of a run per vector, one lane per
// tile, bit-identical to the scalar twins in conv_winograd.cpp. fp32 input: V of one channel in 16
// registers, one masked store per xi into the fp32 kernel's B panels; the next channel's rows are
// prefetched first. bf16 input (for CPUs without AVX512-BF16): V of two channels rounded to bf16
// in integer ops and joined into pair words.
// GCC 12's AVX-512 headers trip -W(maybe-)uninitialized on their own _mm512_undefined_*() idiom.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include <cstdint>

#include "attention/runtime/conv_winograd_avx512.h"

namespace macro {
namespace {

void input_f32_avx512(const detail::WinoInput& a) { winograd_input_f32<WinoAvx512>(a); }

void output_avx512(const detail::WinoOutput& a) { winograd_output<WinoAvx512>(a); }

// bf16 bits of 16 floats in 32-bit lanes, as the scalar bf16_bits_daz (and vcvtne2ps2bf16) round:
// nearest even, NaN quiet, fp32 denormals to signed zero.
inline __m512i bf16_bits_daz16(__m512 v) {
  const __m512i u = _mm512_castps_si512(v);
  const __m512i one = _mm512_set1_epi32(1);
  const __m512i r = _mm512_srli_epi32(
      _mm512_add_epi32(_mm512_add_epi32(u, _mm512_set1_epi32(0x7fff)),
                       _mm512_and_si512(_mm512_srli_epi32(u, 16), one)),
      16);
  const __m512i top = _mm512_srli_epi32(u, 16);
  const __mmask16 nan = _mm512_cmpgt_epu32_mask(
      _mm512_and_si512(u, _mm512_set1_epi32(0x7fffffff)), _mm512_set1_epi32(0x7f800000));
  const __mmask16 tiny =
      _mm512_testn_epi32_mask(u, _mm512_set1_epi32(0x7f800000));  // exponent field zero
  __m512i out = _mm512_mask_or_epi32(r, nan, top, _mm512_set1_epi32(0x40));
  out = _mm512_mask_and_epi32(out, tiny, top, _mm512_set1_epi32(0x8000));
  return out;
}

// The bf16 input transform without AVX512-BF16 (the WinoInput contract, bf16 pair words): the
// rounding in integer ops (bf16_bits_daz16), the two channels' bits joined by a shift and an OR;
// the same bits as the scalar twin and as the AVX512-BF16 transform.
void input_bf16_avx512f(const detail::WinoInput& a) {
  winograd_input_bf16<WinoAvx512>(a, [](__m512 v0, __m512 v1) {
    return _mm512_or_si512(bf16_bits_daz16(v0), _mm512_slli_epi32(bf16_bits_daz16(v1), 16));
  });
}

}  // namespace

namespace detail {
const WinogradTransforms* winograd_avx512_transforms() {
  static const WinogradTransforms t{input_f32_avx512, output_avx512, "avx512"};
  return &t;
}
const WinogradTransforms* winograd_avx512_bf16_transforms() {
  static const WinogradTransforms t{input_bf16_avx512f, output_avx512,
                                    "avx512 (bf16 rounded in integer ops)"};
  return &t;
}
}  // namespace detail

}  // namespace macro
