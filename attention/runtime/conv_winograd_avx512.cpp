// AVX-512 Winograd F(2x2, 3x3) fp32 input transform (the WinoInput contract in conv_winograd.h,
// WinoInput::f32) and the shared output transform (conv_winograd_avx512.h): 16 tiles of a run per
// vector, one lane per tile, bit-identical to the scalar twins in conv_winograd.cpp. Input: V of
// one channel in 16 registers, one masked store per xi into the fp32 kernel's B panels; the next
// channel's rows are prefetched first.
// GCC 12's AVX-512 headers trip -W(maybe-)uninitialized on their own _mm512_undefined_*() idiom.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include <cstdint>

#include "attention/runtime/conv_winograd_avx512.h"

namespace macro {
namespace {

void input_f32_avx512(const detail::WinoInput& a) {
  const int64_t hw = a.h * a.w;
  for (int64_t c = a.q0; c < a.q1; ++c) {
    const float* p = a.x + c * hw;
    for (int r = 0; r < a.nruns; ++r) {
      const detail::WinoRun& run = a.runs[r];
      const int64_t iy0 = 2 * run.ty - a.row_phase - a.pad_top;
      const int64_t ix0 = 2 * run.tx0 - a.pad_left;
      if (c + 1 < a.q1) prefetch_patch_rows(p + hw, a.h, a.w, iy0, ix0);  // the next channel
      __m512 v[16];
      input_tiles(p, a.h, a.w, iy0, ix0, v);
      const __mmask16 keep = __mmask16((1u << run.len) - 1u);
      float* dst = reinterpret_cast<float*>(a.v + (run.col / a.nr) * a.k_rows * a.nr + c * a.nr +
                                            run.col % a.nr);
#pragma GCC unroll 16
      for (int xi = 0; xi < 16; ++xi) _mm512_mask_storeu_ps(dst + xi * a.xi_stride, keep, v[xi]);
    }
  }
}

}  // namespace

namespace detail {
const WinogradTransforms* winograd_avx512_transforms() {
  static const WinogradTransforms t{input_f32_avx512, output_avx512, "avx512"};
  return &t;
}
}  // namespace detail

}  // namespace macro
