// AVX-512 im2col gather for stride-1 convs (the ConvRows contract in kernels.h): each k row of a
// 32-column B panel is two loads per output-row run straight from the input plane (padding lanes
// masked off, so they come out zero) and two stores. This replaces a
// per-row bounds computation and memcpy; at 128 channels the gather is one value per 128 MACs and
// was the conv's main overhead.
// A run's lanes come by plain loads wherever the 32 words lie inside the input (a whole-panel run,
// or a merge into the lanes it owns): on the Zen 5 VM of 2026-12-06 a masked load of an input
// streamed from L3 or memory cost more than a plain one (the 1x1 convs ~10-20% faster; the
// masked loads remain for runs at the input's two ends).
// GCC 12's AVX-512 headers trip -W(maybe-)uninitialized on their own _mm512_undefined_*() idiom.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>

#include <cstdint>

#include "attention/runtime/kernels.h"

namespace macro {
namespace {

void conv_rows32(const ConvRows& a) {
  const int64_t khw = int64_t(a.kh) * a.kw;
  // Position of row k0 in its order: (plane, dy, dx).
  int64_t plane, tap;
  if (a.tap_major) {
    tap = a.k0 / a.planes;
    plane = a.k0 % a.planes;
  } else {
    plane = a.k0 / khw;
    tap = a.k0 % khw;
  }
  int dy = int(tap / a.kw), dx = int(tap % a.kw);
  const __m512i zero = _mm512_setzero_si512();
  // Words in the input (up to the last plane's h rows).
  const int64_t x_words = (a.planes - 1) * a.hw + a.h * a.w;
  uint32_t* d = a.dst;
  for (int64_t r = 0; r < a.rows_padded; ++r, d += 32) {
    __m512i v0 = zero, v1 = zero;
    if (r < a.nrows) {
      for (int g = 0; g < a.nseg; ++g) {
        const ConvSegment& sg = a.segs[g];
        const int64_t iy = sg.oy + dy - a.pad_top;
        if (iy < 0 || iy >= a.h) continue;
        const int64_t ix0 = sg.ox + dx - a.pad_left;  // input column of the run's first pixel
        const int64_t lo = ix0 < 0 ? -ix0 : 0;
        const int64_t hi = a.w - ix0 < sg.len ? a.w - ix0 : sg.len;
        if (lo >= hi) continue;
        const uint64_t bits = ((uint64_t(1) << hi) - 1) & ~((uint64_t(1) << lo) - 1);
        const uint64_t mask = bits << sg.col;  // lanes [col + lo, col + hi)
        // Lane j of the run reads row[ix0 + j - col], i.e. input word `at` + j; the other lanes
        // keep what they hold (zero, or another run's words).
        const int64_t at = plane * a.hw + iy * a.w + ix0 - sg.col;
        const uint32_t* src = a.x + at;
        if (mask == 0xffffffffu) {  // the common case: plain loads (a masked load costs more)
          v0 = _mm512_loadu_si512(src);
          v1 = _mm512_loadu_si512(src + 16);
        } else if (at >= 0 && at + 32 <= x_words) {
          // The 32 words lie inside the input: plain loads, the run's lanes merged in.
          v0 = _mm512_mask_mov_epi32(v0, __mmask16(mask & 0xffff), _mm512_loadu_si512(src));
          v1 = _mm512_mask_mov_epi32(v1, __mmask16((mask >> 16) & 0xffff),
                                     _mm512_loadu_si512(src + 16));
        } else {  // masked-off lanes are never accessed
          v0 = _mm512_mask_loadu_epi32(v0, __mmask16(mask & 0xffff), src);
          v1 = _mm512_mask_loadu_epi32(v1, __mmask16((mask >> 16) & 0xffff), src + 16);
        }
      }
      // Next row in the order.
      if (a.tap_major) {
        if (++plane == a.planes) {
          plane = 0;
          if (++dx == a.kw) dx = 0, ++dy;
        }
      } else if (++dx == a.kw) {
        dx = 0;
        if (++dy == a.kh) dy = 0, ++plane;
      }
    }
    _mm512_storeu_si512(d, v0);
    _mm512_storeu_si512(d + 16, v1);
  }
}

}  // namespace

namespace detail {
ConvGatherRows32 avx512_conv_rows32() {
  return conv_rows32;
}
}  // namespace detail

}  // namespace macro
