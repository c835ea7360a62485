// The Winograd F(2x2, 3x3) vector transforms (the WinoInput / WinoOutput contracts in
// conv_winograd.h), written once over a vector-traits type T and instantiated by the AVX2 and
// AVX-512 files (conv_winograd_avx2.cpp, conv_winograd_avx512.h): one lane per tile, T::W tiles
// per step (a run of up to 16 tiles in 16 / W steps). The same fp32 adds in the same order as the
// scalar twins in conv_winograd.cpp, so every width gives their bits.
//   input:  per input row, four masked loads (offsets 0, W, 2, W + 2 from the step's first
//           column) split into even and odd columns give d[i][0..3] for W tiles; V in 16
//           registers, one masked store per xi (fp32 values, or bf16 pair words of two channels
//           joined by the path's words()); the next channel's rows are prefetched first.
//   output: 16 masked loads of M, A^T M A, each output row's two columns interleaved back into
//           2 W consecutive pixels (masked at the right edge), + bias, + residual, ReLU; the next
//           channel's output and residual lines are prefetched (the output of a large VAE conv
//           goes to memory, a short stretch per row and channel).
//
// T provides: V (fp32 vector), Vi (32-bit integer vector), M (lane mask), W (lanes);
//   lanes(start, limit): the lanes e in [0, W) with 0 <= start + e < limit;
//   load(m, p): masked load, masked-off lanes zero and not accessed; store(p, m, v);
//   store_words(p, m, w): masked store of 32-bit words; zero(), set1(x), add, sub,
//   max(v, 0-vector);
//   evens(a, b), odds(a, b): the even and odd elements of the 2 W floats a | b, in order;
//   interleave(y0, y1, lo, hi): y0[0] y1[0] y0[1] y1[1] .. as two vectors.
// Include only from files compiled with the traits' ISA flags (internal linkage: each keeps its
// own copy).
#pragma once

#include <immintrin.h>

#include <cstdint>

#include "attention/runtime/conv_winograd.h"

namespace macro {
namespace {

// V = B^T d B for one lane per tile: d[4 i + j] the patches' rows i, columns j; v[xi],
// xi = 4 i + j.
template <typename T>
inline void winograd_btdb(const typename T::V* d, typename T::V* v) {
  typename T::V r[16];
#pragma GCC unroll 4
  for (int j = 0; j < 4; ++j) {
    r[0 * 4 + j] = T::sub(d[0 * 4 + j], d[2 * 4 + j]);
    r[1 * 4 + j] = T::add(d[1 * 4 + j], d[2 * 4 + j]);
    r[2 * 4 + j] = T::sub(d[2 * 4 + j], d[1 * 4 + j]);
    r[3 * 4 + j] = T::sub(d[1 * 4 + j], d[3 * 4 + j]);
  }
#pragma GCC unroll 4
  for (int i = 0; i < 4; ++i) {
    const typename T::V* ri = r + i * 4;
    v[i * 4 + 0] = T::sub(ri[0], ri[2]);
    v[i * 4 + 1] = T::add(ri[1], ri[2]);
    v[i * 4 + 2] = T::sub(ri[2], ri[1]);
    v[i * 4 + 3] = T::sub(ri[1], ri[3]);
  }
}

// V of W tiles of one channel (plane p, null = zeros) whose patches start at input row iy0 and
// columns ix0, ix0 + 2, ..
template <typename T>
inline void winograd_input_tiles(const float* p, int64_t h, int64_t w, int64_t iy0, int64_t ix0,
                                 typename T::V* v) {
  constexpr int W = T::W;
  typename T::V d[16];
  const typename T::M m0 = T::lanes(ix0, w), mw = T::lanes(ix0 + W, w);
  const typename T::M m2 = T::lanes(ix0 + 2, w), mw2 = T::lanes(ix0 + W + 2, w);
#pragma GCC unroll 4
  for (int i = 0; i < 4; ++i) {
    const int64_t iy = iy0 + i;
    if (!p || iy < 0 || iy >= h) {
      for (int j = 0; j < 4; ++j) d[i * 4 + j] = T::zero();
      continue;
    }
    // Lane e of a load at offset o reads column ix0 + o + e; masked-off lanes are not accessed.
    const float* row = p + iy * w + ix0;
    const typename T::V a0 = T::load(m0, row), aw = T::load(mw, row + W);
    const typename T::V a2 = T::load(m2, row + 2), aw2 = T::load(mw2, row + W + 2);
    d[i * 4 + 0] = T::evens(a0, aw);
    d[i * 4 + 1] = T::odds(a0, aw);
    d[i * 4 + 2] = T::evens(a2, aw2);
    d[i * 4 + 3] = T::odds(a2, aw2);
  }
  winograd_btdb<T>(d, v);
}

// Prefetch the 4 rows x 136 bytes a run's 16 tiles read from plane p (rows iy0 .. iy0 + 3,
// columns from ix0): called for the next channel's plane while this one is transformed. The planes
// lie far apart and a chunk reads a short stretch of each row, too short for the hardware
// prefetchers (the inputs of the large VAE convs come from memory).
inline void winograd_prefetch_patch_rows(const float* p, int64_t h, int64_t w, int64_t iy0,
                                         int64_t ix0) {
  const int64_t y0 = iy0 < 0 ? 0 : iy0, y1 = iy0 + 4 > h ? h : iy0 + 4;
  const int64_t x0 = ix0 < 0 ? 0 : ix0;
  for (int64_t y = y0; y < y1; ++y) {
    const char* r = reinterpret_cast<const char*>(p + y * w + x0);
    _mm_prefetch(r, _MM_HINT_T0);
    _mm_prefetch(r + 64, _MM_HINT_T0);
    _mm_prefetch(r + 128, _MM_HINT_T0);
  }
}

// The fp32 input transform: V of channel q as fp32 values in the fp32 kernel's B panels.
template <typename T>
inline void winograd_input_f32(const detail::WinoInput& a) {
  const int64_t hw = a.h * a.w;
  for (int64_t c = a.q0; c < a.q1; ++c) {
    const float* p = a.x + c * hw;
    for (int r = 0; r < a.nruns; ++r) {
      const detail::WinoRun& run = a.runs[r];
      const int64_t iy0 = 2 * run.ty - a.row_phase - a.pad_top;
      const int64_t ix0 = 2 * run.tx0 - a.pad_left;
      if (c + 1 < a.q1) winograd_prefetch_patch_rows(p + hw, a.h, a.w, iy0, ix0);
      for (int s = 0; s < run.len; s += T::W) {
        typename T::V v[16];
        winograd_input_tiles<T>(p, a.h, a.w, iy0, ix0 + 2 * s, v);
        const typename T::M keep = T::lanes(0, run.len - s);
        const int col = run.col + s;
        float* dst = reinterpret_cast<float*>(a.v + (col / a.nr) * a.k_rows * a.nr + c * a.nr +
                                              col % a.nr);
#pragma GCC unroll 16
        for (int xi = 0; xi < 16; ++xi) T::store(dst + xi * a.xi_stride, keep, v[xi]);
      }
    }
  }
}

// The bf16 input transform: V of channels 2q and 2q + 1 joined by words(v0[xi], v1[xi]) (the
// path's rounding) into pair words; the next pair's rows are prefetched first.
template <typename T, typename Words>
inline void winograd_input_bf16(const detail::WinoInput& a, Words&& words) {
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
        winograd_prefetch_patch_rows(p0 + 2 * hw, a.h, a.w, iy0, ix0);
        winograd_prefetch_patch_rows(p0 + 3 * hw, a.h, a.w, iy0, ix0);
      }
      for (int s = 0; s < run.len; s += T::W) {
        typename T::V v0[16], v1[16];
        winograd_input_tiles<T>(p0, a.h, a.w, iy0, ix0 + 2 * s, v0);
        winograd_input_tiles<T>(p1, a.h, a.w, iy0, ix0 + 2 * s, v1);
        const typename T::M keep = T::lanes(0, run.len - s);
        const int col = run.col + s;
        uint32_t* dst = a.v + (col / a.nr) * a.k_rows * a.nr + q * a.nr + col % a.nr;
#pragma GCC unroll 16
        for (int xi = 0; xi < 16; ++xi)
          T::store_words(dst + xi * a.xi_stride, keep, words(v0[xi], v1[xi]));
      }
    }
  }
}

template <typename T>
inline void winograd_output(const detail::WinoOutput& a) {
  using V = typename T::V;
  constexpr int W = T::W;
  const V zero = T::zero();
  for (int64_t c = a.co0; c < a.co0 + a.nco; ++c) {
    const float* mc = a.m + (c - a.co0) * a.ldm;
    float* yc = a.y + c * a.plane;
    const float* rc = a.residual ? a.residual + c * a.plane : nullptr;
    const V bias = a.bias ? T::set1(a.bias[c]) : zero;
    for (int r = 0; r < a.nruns; ++r) {
      const detail::WinoRun& run = a.runs[r];
      for (int s = 0; s < run.len; s += W) {
        const typename T::M keep = T::lanes(0, run.len - s);
        V m[16];
#pragma GCC unroll 16
        for (int xi = 0; xi < 16; ++xi) m[xi] = T::load(keep, mc + xi * a.xi_stride + run.col + s);
        V t[8];  // the first half of A^T M A
#pragma GCC unroll 4
        for (int j = 0; j < 4; ++j) {
          t[0 * 4 + j] = T::add(T::add(m[0 * 4 + j], m[1 * 4 + j]), m[2 * 4 + j]);
          t[1 * 4 + j] = T::sub(T::sub(m[1 * 4 + j], m[2 * 4 + j]), m[3 * 4 + j]);
        }
        const int64_t ox0 = 2 * (run.tx0 + s);
        const int64_t len = run.len - s < W ? run.len - s : W;
        const int64_t valid = 2 * len < a.ow - ox0 ? 2 * len : a.ow - ox0;
        const typename T::M klo = T::lanes(0, valid), khi = T::lanes(W, valid);
        for (int i = 0; i < 2; ++i) {
          const int64_t oy = 2 * run.ty - a.row_phase + i;
          if (oy < 0 || oy >= a.oh) continue;
          const V* ti = t + i * 4;
          V y0 = T::add(T::add(ti[0], ti[1]), ti[2]);
          V y1 = T::sub(T::sub(ti[1], ti[2]), ti[3]);
          if (a.bias) {
            y0 = T::add(y0, bias);
            y1 = T::add(y1, bias);
          }
          V lo, hi;
          T::interleave(y0, y1, &lo, &hi);
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
            lo = T::add(lo, T::load(klo, rc + off));
            hi = T::add(hi, T::load(khi, rc + off + W));
          }
          if (a.relu) {
            lo = T::max(lo, zero);
            hi = T::max(hi, zero);
          }
          T::store(yc + off, klo, lo);
          T::store(yc + off + W, khi, hi);
        }
      }
    }
  }
}

}  // namespace
}  // namespace macro
