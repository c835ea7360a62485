// The AVX-512 Winograd F(2x2, 3x3) pieces shared by the fp32 and bf16 transforms
// (conv_winograd_avx512.cpp, conv_winograd_avx512bf16.cpp; contracts in conv_winograd.h): the
// input tile transform of 16 tiles of one channel, the bf16 pairs loop and the whole output
// transform. The same fp32 adds in the same order as the scalar twins in conv_winograd.cpp, so the
// results are bit-identical to them.
//   input:  per input row, four masked loads (offsets 0, 16, 2, 18 from the run's first column)
//           split into even/odd columns give d[i][0..3] for 16 tiles; V in 16 registers.
//   output: 16 masked loads of M, A^T M A, then each output row's two columns interleaved back
//           into 32 consecutive pixels (masked at the right edge), + bias, + residual, ReLU;
//           the next channel's output and residual lines are prefetched (the output of a large
//           VAE conv goes to memory, a short stretch per row and channel).
// Include ONLY from files compiled with AVX-512 flags; internal linkage, so each ISA file keeps
// its own copy compiled with its own flags.
#pragma once

#include <immintrin.h>

#include <cstdint>

#include "attention/runtime/conv_winograd.h"
#include "attention/runtime/conv_winograd_simd.h"

namespace macro {
namespace {

struct Ops512 {
  using V = __m512;
  static V add(V a, V b) { return _mm512_add_ps(a, b); }
  static V sub(V a, V b) { return _mm512_sub_ps(a, b); }
};

// Lanes e in [0, 16) with 0 <= start + e < limit.
inline __mmask16 range_mask(int64_t start, int64_t limit) {
  const int64_t lo = start < 0 ? -start : 0;
  const int64_t hi = limit - start < 16 ? limit - start : 16;
  if (lo >= hi) return 0;
  const uint32_t bits = ((hi >= 16 ? 0x10000u : (1u << hi)) - 1u) & ~((1u << lo) - 1u);
  return __mmask16(bits);
}

// V = B^T d B for 16 tiles of one channel (plane p, null = zeros): v[xi], xi = 4 i + j.
inline void input_tiles(const float* p, int64_t h, int64_t w, int64_t iy0, int64_t ix0, __m512* v) {
  const __m512i even = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
  const __m512i odd = _mm512_setr_epi32(1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31);
  __m512 d[16];
  const __mmask16 m0 = range_mask(ix0, w), m16 = range_mask(ix0 + 16, w);
  const __mmask16 m2 = range_mask(ix0 + 2, w), m18 = range_mask(ix0 + 18, w);
  for (int i = 0; i < 4; ++i) {
    const int64_t iy = iy0 + i;
    if (!p || iy < 0 || iy >= h) {
      for (int j = 0; j < 4; ++j) d[i * 4 + j] = _mm512_setzero_ps();
      continue;
    }
    // Lane e of a load at offset o reads column ix0 + o + e; masked-off lanes are not accessed.
    const float* row = p + iy * w + ix0;
    const __m512 a0 = _mm512_maskz_loadu_ps(m0, row), a16 = _mm512_maskz_loadu_ps(m16, row + 16);
    const __m512 a2 = _mm512_maskz_loadu_ps(m2, row + 2),
                 a18 = _mm512_maskz_loadu_ps(m18, row + 18);
    d[i * 4 + 0] = _mm512_permutex2var_ps(a0, even, a16);
    d[i * 4 + 1] = _mm512_permutex2var_ps(a0, odd, a16);
    d[i * 4 + 2] = _mm512_permutex2var_ps(a2, even, a18);
    d[i * 4 + 3] = _mm512_permutex2var_ps(a2, odd, a18);
  }
  winograd_btdb<Ops512>(d, v);
}

// Prefetch the 4 rows x 136 bytes a run's 16 tiles read from plane p (rows iy0 .. iy0 + 3,
// columns from ix0): called for the next channel's plane while this one is transformed. The planes
// lie far apart and a chunk reads a short stretch of each row, too short for the hardware
// prefetchers (the inputs of the large VAE convs come from memory).
inline void prefetch_patch_rows(const float* p, int64_t h, int64_t w, int64_t iy0, int64_t ix0) {
  const int64_t y0 = iy0 < 0 ? 0 : iy0, y1 = iy0 + 4 > h ? h : iy0 + 4;
  const int64_t x0 = ix0 < 0 ? 0 : ix0;
  for (int64_t y = y0; y < y1; ++y) {
    const char* r = reinterpret_cast<const char*>(p + y * w + x0);
    _mm_prefetch(r, _MM_HINT_T0);
    _mm_prefetch(r + 64, _MM_HINT_T0);
    _mm_prefetch(r + 128, _MM_HINT_T0);
  }
}

// The bf16 input transform's loop (the WinoInput contract, bf16 pair words): V of two channels
// (16 registers each) joined by words(v0[xi], v1[xi]) into 16 pair words, one masked store per xi;
// the next pair's rows are prefetched first. words() is the path's rounding.
template <typename Words>
inline void input_bf16_pairs(const detail::WinoInput& a, Words&& words) {
  const int64_t hw = a.h * a.w;
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
      for (int xi = 0; xi < 16; ++xi)
        _mm512_mask_storeu_epi32(dst + xi * a.xi_stride, keep, words(v0[xi], v1[xi]));
    }
  }
}

inline void output_avx512(const detail::WinoOutput& a) {
  const __m512i lo_idx = _mm512_setr_epi32(0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23);
  const __m512i hi_idx =
      _mm512_setr_epi32(8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31);
  const __m512 zero = _mm512_setzero_ps();
  for (int64_t c = a.co0; c < a.co0 + a.nco; ++c) {
    const float* mc = a.m + (c - a.co0) * a.ldm;
    float* yc = a.y + c * a.plane;
    const float* rc = a.residual ? a.residual + c * a.plane : nullptr;
    const __m512 bias = a.bias ? _mm512_set1_ps(a.bias[c]) : zero;
    for (int r = 0; r < a.nruns; ++r) {
      const detail::WinoRun& run = a.runs[r];
      const __mmask16 keep = __mmask16((1u << run.len) - 1u);
      __m512 m[16];
#pragma GCC unroll 16
      for (int xi = 0; xi < 16; ++xi)
        m[xi] = _mm512_maskz_loadu_ps(keep, mc + xi * a.xi_stride + run.col);
      __m512 t[8];
      winograd_atm<Ops512>(m, t);
      const int64_t ox0 = 2 * run.tx0;
      const int64_t valid = 2 * int64_t(run.len) < a.ow - ox0 ? 2 * int64_t(run.len) : a.ow - ox0;
      const __mmask16 klo = range_mask(0, valid), khi = range_mask(16, valid);
      for (int i = 0; i < 2; ++i) {
        const int64_t oy = 2 * run.ty - a.row_phase + i;
        if (oy < 0 || oy >= a.oh) continue;
        __m512 y0, y1;
        winograd_row<Ops512>(t + i * 4, &y0, &y1);
        if (a.bias) {
          y0 = _mm512_add_ps(y0, bias);
          y1 = _mm512_add_ps(y1, bias);
        }
        __m512 lo = _mm512_permutex2var_ps(y0, lo_idx, y1);
        __m512 hi = _mm512_permutex2var_ps(y0, hi_idx, y1);
        const int64_t off = oy * a.ow + ox0;
        if (c + 1 < a.co0 + a.nco) {  // the next channel's lines of this run (as the input's)
          const char* ny = reinterpret_cast<const char*>(yc + a.plane + off);
          _mm_prefetch(ny, _MM_HINT_T0);
          _mm_prefetch(ny + 64, _MM_HINT_T0);
          if (rc) {
            const char* nr = reinterpret_cast<const char*>(rc + a.plane + off);
            _mm_prefetch(nr, _MM_HINT_T0);
            _mm_prefetch(nr + 64, _MM_HINT_T0);
          }
        }
        if (rc) {
          lo = _mm512_add_ps(lo, _mm512_maskz_loadu_ps(klo, rc + off));
          hi = _mm512_add_ps(hi, _mm512_maskz_loadu_ps(khi, rc + off + 16));
        }
        if (a.relu) {
          lo = _mm512_max_ps(lo, zero);
          hi = _mm512_max_ps(hi, zero);
        }
        _mm512_mask_storeu_ps(yc + off, klo, lo);
        _mm512_mask_storeu_ps(yc + off + 16, khi, hi);
      }
    }
  }
}

}  // namespace
}  // namespace macro
