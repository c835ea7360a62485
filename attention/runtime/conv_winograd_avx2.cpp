// AVX2 Winograd F(2x2, 3x3) transforms (the WinoInput / WinoOutput contracts in conv_winograd.h):
// a run's tiles (at most 16) in halves of 8, one lane per tile, with the same fp32 adds in the
// same order as the scalar twins in conv_winograd.cpp, so the results are bit-identical to them.
//   input:  per input row, four masked loads (offsets 0, 8, 2, 10 from the half's first column)
//           split into even and odd columns give d[i][0..3] for 8 tiles; V in 16 registers, one
//           masked store per xi. fp32: the values; bf16: two channels rounded to bf16 in integer
//           ops (nearest even, NaN quiet, denormals to zero: the scalar bf16_bits_daz) and joined
//           into pair words (even channel low).
//   output: 16 masked loads of M, A^T M A, each output row's two columns interleaved back into
//           16 consecutive pixels (masked at the right edge), + bias, + residual, ReLU.
#include <immintrin.h>

#include <algorithm>
#include <cstdint>

#include "attention/runtime/conv_winograd.h"
#include "attention/runtime/conv_winograd_simd.h"

namespace macro {
namespace {

struct Ops256 {
  using V = __m256;
  static V add(V a, V b) { return _mm256_add_ps(a, b); }
  static V sub(V a, V b) { return _mm256_sub_ps(a, b); }
};

// Lanes e in [0, 8) with 0 <= start + e < limit, as a maskload / maskstore mask (all bits set).
inline __m256i lane_mask(int64_t start, int64_t limit) {
  const __m256i e = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const int lo = int(std::clamp<int64_t>(-start, 0, 8));           // first lane inside
  const int hi = int(std::clamp<int64_t>(limit - start, -1, 8));  // lanes below it inside
  return _mm256_andnot_si256(_mm256_cmpgt_epi32(_mm256_set1_epi32(lo), e),
                             _mm256_cmpgt_epi32(_mm256_set1_epi32(hi), e));
}

// Even and odd elements of the 16 floats a | b: (a0 a2 .. a6 b0 .. b6) and (a1 .. a7 b1 .. b7).
inline __m256 evens(__m256 a, __m256 b) {
  const __m256 t = _mm256_shuffle_ps(a, b, _MM_SHUFFLE(2, 0, 2, 0));
  return _mm256_castpd_ps(_mm256_permute4x64_pd(_mm256_castps_pd(t), _MM_SHUFFLE(3, 1, 2, 0)));
}
inline __m256 odds(__m256 a, __m256 b) {
  const __m256 t = _mm256_shuffle_ps(a, b, _MM_SHUFFLE(3, 1, 3, 1));
  return _mm256_castpd_ps(_mm256_permute4x64_pd(_mm256_castps_pd(t), _MM_SHUFFLE(3, 1, 2, 0)));
}

// V = B^T d B for 8 tiles of one channel (plane p, null = zeros) whose patches start at input row
// iy0 and columns ix0, ix0 + 2, ..: v[xi], xi = 4 i + j.
inline void input_tiles(const float* p, int64_t h, int64_t w, int64_t iy0, int64_t ix0, __m256* v) {
  __m256 d[16];
  const __m256i m0 = lane_mask(ix0, w), m8 = lane_mask(ix0 + 8, w);
  const __m256i m2 = lane_mask(ix0 + 2, w), m10 = lane_mask(ix0 + 10, w);
#pragma GCC unroll 4
  for (int i = 0; i < 4; ++i) {
    const int64_t iy = iy0 + i;
    if (!p || iy < 0 || iy >= h) {
      for (int j = 0; j < 4; ++j) d[i * 4 + j] = _mm256_setzero_ps();
      continue;
    }
    // Lane e of a load at offset o reads column ix0 + o + e; masked-off lanes are not accessed.
    const float* row = p + iy * w + ix0;
    const __m256 a0 = _mm256_maskload_ps(row, m0), a8 = _mm256_maskload_ps(row + 8, m8);
    const __m256 a2 = _mm256_maskload_ps(row + 2, m2), a10 = _mm256_maskload_ps(row + 10, m10);
    d[i * 4 + 0] = evens(a0, a8);
    d[i * 4 + 1] = odds(a0, a8);
    d[i * 4 + 2] = evens(a2, a10);
    d[i * 4 + 3] = odds(a2, a10);
  }
  winograd_btdb<Ops256>(d, v);
}

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

void input_f32_avx2(const detail::WinoInput& a) {
  const int64_t hw = a.h * a.w;
  for (int64_t c = a.q0; c < a.q1; ++c) {
    const float* p = a.x + c * hw;
    for (int r = 0; r < a.nruns; ++r) {
      const detail::WinoRun& run = a.runs[r];
      const int64_t iy0 = 2 * run.ty - a.row_phase - a.pad_top;
      for (int h0 = 0; h0 < run.len; h0 += 8) {
        __m256 v[16];
        input_tiles(p, a.h, a.w, iy0, 2 * (run.tx0 + h0) - a.pad_left, v);
        const __m256i keep = lane_mask(0, run.len - h0);
        const int col = run.col + h0;
        float* dst = reinterpret_cast<float*>(a.v + (col / a.nr) * a.k_rows * a.nr + c * a.nr +
                                              col % a.nr);
#pragma GCC unroll 16
        for (int xi = 0; xi < 16; ++xi) _mm256_maskstore_ps(dst + xi * a.xi_stride, keep, v[xi]);
      }
    }
  }
}

void input_bf16_avx2(const detail::WinoInput& a) {
  const int64_t hw = a.h * a.w;
  for (int64_t q = a.q0; q < a.q1; ++q) {
    const int64_t c0 = 2 * q, c1 = c0 + 1;
    const float* p0 = c0 < a.c_in ? a.x + c0 * hw : nullptr;
    const float* p1 = c1 < a.c_in ? a.x + c1 * hw : nullptr;
    for (int r = 0; r < a.nruns; ++r) {
      const detail::WinoRun& run = a.runs[r];
      const int64_t iy0 = 2 * run.ty - a.row_phase - a.pad_top;
      for (int h0 = 0; h0 < run.len; h0 += 8) {
        const int64_t ix0 = 2 * (run.tx0 + h0) - a.pad_left;
        __m256 v0[16], v1[16];
        input_tiles(p0, a.h, a.w, iy0, ix0, v0);
        input_tiles(p1, a.h, a.w, iy0, ix0, v1);
        const __m256i keep = lane_mask(0, run.len - h0);
        const int col = run.col + h0;
        int* dst = reinterpret_cast<int*>(a.v + (col / a.nr) * a.k_rows * a.nr + q * a.nr +
                                          col % a.nr);
#pragma GCC unroll 16
        for (int xi = 0; xi < 16; ++xi)
          _mm256_maskstore_epi32(dst + xi * a.xi_stride, keep,
                                 _mm256_or_si256(bf16_bits_daz8(v0[xi]),
                                                 _mm256_slli_epi32(bf16_bits_daz8(v1[xi]), 16)));
      }
    }
  }
}

void output_avx2(const detail::WinoOutput& a) {
  const __m256 zero = _mm256_setzero_ps();
  for (int64_t c = a.co0; c < a.co0 + a.nco; ++c) {
    const float* mc = a.m + (c - a.co0) * a.ldm;
    float* yc = a.y + c * a.plane;
    const float* rc = a.residual ? a.residual + c * a.plane : nullptr;
    const __m256 bias = a.bias ? _mm256_set1_ps(a.bias[c]) : zero;
    for (int r = 0; r < a.nruns; ++r) {
      const detail::WinoRun& run = a.runs[r];
      for (int h0 = 0; h0 < run.len; h0 += 8) {
        const __m256i keep = lane_mask(0, run.len - h0);
        __m256 m[16];
#pragma GCC unroll 16
        for (int xi = 0; xi < 16; ++xi)
          m[xi] = _mm256_maskload_ps(mc + xi * a.xi_stride + run.col + h0, keep);
        __m256 t[8];
        winograd_atm<Ops256>(m, t);
        const int64_t ox0 = 2 * (run.tx0 + h0);
        const int64_t valid = std::min<int64_t>(2 * std::min(8, run.len - h0), a.ow - ox0);
        const __m256i klo = lane_mask(0, valid), khi = lane_mask(8, valid);
        for (int i = 0; i < 2; ++i) {
          const int64_t oy = 2 * run.ty - a.row_phase + i;
          if (oy < 0 || oy >= a.oh) continue;
          __m256 y0, y1;
          winograd_row<Ops256>(t + i * 4, &y0, &y1);
          if (a.bias) {
            y0 = _mm256_add_ps(y0, bias);
            y1 = _mm256_add_ps(y1, bias);
          }
          // Pixels 2 l + 0 and 2 l + 1 of tile l: (y0[l], y1[l]) in order.
          const __m256 u = _mm256_unpacklo_ps(y0, y1), w = _mm256_unpackhi_ps(y0, y1);
          __m256 lo = _mm256_permute2f128_ps(u, w, 0x20), hi = _mm256_permute2f128_ps(u, w, 0x31);
          const int64_t off = oy * a.ow + ox0;
          if (rc) {
            lo = _mm256_add_ps(lo, _mm256_maskload_ps(rc + off, klo));
            hi = _mm256_add_ps(hi, _mm256_maskload_ps(rc + off + 8, khi));
          }
          if (a.relu) {
            lo = _mm256_max_ps(lo, zero);
            hi = _mm256_max_ps(hi, zero);
          }
          _mm256_maskstore_ps(yc + off, klo, lo);
          _mm256_maskstore_ps(yc + off + 8, khi, hi);
        }
      }
    }
  }
}

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
