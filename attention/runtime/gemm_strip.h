// The tiles of a strip (the MicroStripKernel contract in kernels.h): tile q of a strip starting at
// t0 covers columns [q NR, min(ncols, (q + 1) NR)), B at t0.b + q * b_stride bytes, C, bias_n and
// res advanced by q NR. ISA-free; each kernel file instantiates it with its own tile function.
#pragma once

#include <cstdint>

#include "attention/runtime/kernels.h"

namespace macro::detail {

template <int NR, typename Tile>
inline void for_each_strip_tile(const MicroTile& t0, int64_t ncols, int64_t b_stride, Tile&& tile) {
  MicroTile t = t0;
  const unsigned char* b = static_cast<const unsigned char*>(t0.b);
  for (int64_t j = 0; j < ncols; j += NR, b += b_stride) {
    t.b = b;
    t.n = int(ncols - j < NR ? ncols - j : NR);
    t.c = t0.c + j;
    t.bias_n = t0.bias_n ? t0.bias_n + j : nullptr;
    t.res = t0.res ? t0.res + j : nullptr;
    tile(t);
  }
}

}  // namespace macro::detail
