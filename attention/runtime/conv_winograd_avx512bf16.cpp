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

void input_bf16_avx512(const detail::WinoInput& a) {
  const int64_t hw = a.h * a.w;
  const __m512i pair_idx =
      _mm512_set_epi16(31, 15, 30, 14, 29, 13, 28, 12, 27, 11, 26, 10, 25, 9, 24, 8, 23, 7, 22, 6,
                       21, 5, 20, 4, 19, 3, 18, 2, 17, 1, 16, 0);
  for (int64_t q = a.q0; q < a.q1; ++q) {
    const int64_t c0 = 2 * q, c1 = c0 + 1;
    const float* p0 = c0 < a.c_in ? a.x + c0 * hw : nullptr;
    const float* p1 = c1 < a.c_in ? a.x + c1 * hw : nullptr;
    for (int r = 0; r < a.nruns; ++r) {
      const detail::WinoRun& run = a.runs[r];
      const int64_t iy0 = 2 * run.ty - a.row_phase - a.pad_top;
      const int64_t ix0 = 2 * run.tx0 - a.pad_left;
      if (q + 1 < a.q1 && 2 * q + 3 < a.c_in) {  // the next pair's planes
        prefetch_patch_rows(p0 + 2 * hw, a.h, a.w, iy0, ix0);
        prefetch_patch_rows(p0 + 3 * hw, a.h, a.w, iy0, ix0);
      }
      __m512 v0[16], v1[16];
      input_tiles(p0, a.h, a.w, iy0, ix0, v0);
      input_tiles(p1, a.h, a.w, iy0, ix0, v1);
      const __mmask16 keep = __mmask16((1u << run.len) - 1u);
      uint32_t* dst = a.v + (run.col / a.nr) * a.k_rows * a.nr + q * a.nr + run.col % a.nr;
#pragma GCC unroll 16
      for (int xi = 0; xi < 16; ++xi) {
        // [c0 lanes 0..15 | c1 lanes 0..15] as bf16, interleaved into pair words.
        const __m512i both = (__m512i)_mm512_cvtne2ps_pbh(v1[xi], v0[xi]);
        _mm512_mask_storeu_epi32(dst + xi * a.xi_stride, keep,
                                 _mm512_permutexvar_epi16(pair_idx, both));
      }
    }
  }
}

}  // namespace

namespace detail {
const WinogradTransforms* winograd_avx512bf16_transforms() {
  static const WinogradTransforms t{input_bf16_avx512, output_avx512, "avx512bf16"};
  return &t;
}
}  // namespace detail

}  // namespace macro
