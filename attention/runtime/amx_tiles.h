// The engine's one AMX tile configuration, shared by the AMX GEMM micro-kernel (gemm_amx.cpp) and
// the AMX attention kernel (attention_amx.cpp): palette 1, all eight tiles 16 rows x 64 bytes
// (fp32 C tiles 16 x 16, bf16 A tiles 16 x 32, VNNI B tiles 16 k-pairs x 16 columns).
// Include it only from *_amx.cpp files.
#pragma once

#include <immintrin.h>

#include <cstdint>

namespace macro::detail {

// Loads the configuration on the calling thread unless that thread already holds it. It survives
// context switches (XSAVE), so each thread loads it once; nothing else in the engine configures
// tiles, and amx_tiles_release() (the peak probe) makes the next call load it again.
void amx_tiles_ready();
void amx_tiles_release();

// One K step of 32 on a 2 x 2 block of C tiles (0, 1 = rows 0-15, 2, 3 = rows 16-31; even = the
// first 16 columns): A tiles 4, 5 from a0, a1 (rows a_stride bytes apart), VNNI B tiles 6, 7 from
// b and b + 64 bytes (rows b_stride bytes apart), then C(i, j) += A_i B_j.
inline void amx_step_2x2(const void* a0, const void* a1, int64_t a_stride, const void* b,
                         int64_t b_stride) {
  _tile_loadd(4, a0, a_stride);
  _tile_loadd(5, a1, a_stride);
  _tile_loadd(6, b, b_stride);
  _tile_loadd(7, static_cast<const char*>(b) + 64, b_stride);
  _tile_dpbf16ps(0, 4, 6);
  _tile_dpbf16ps(1, 4, 7);
  _tile_dpbf16ps(2, 5, 6);
  _tile_dpbf16ps(3, 5, 7);
}

// C tiles 0-3 from / to a row-major fp32 block at c (row stride ld floats): tile 0 at c, 1 at
// c + 16, 2 at c + 16 ld, 3 at c + 16 ld + 16 (a load with ld 0 repeats the row at c).
inline void amx_load_c_2x2(const float* c, int64_t ld) {
  _tile_loadd(0, c, ld * 4);
  _tile_loadd(1, c + 16, ld * 4);
  _tile_loadd(2, c + 16 * ld, ld * 4);
  _tile_loadd(3, c + 16 * ld + 16, ld * 4);
}
inline void amx_store_c_2x2(float* c, int64_t ld) {
  _tile_stored(0, c, ld * 4);
  _tile_stored(1, c + 16, ld * 4);
  _tile_stored(2, c + 16 * ld, ld * 4);
  _tile_stored(3, c + 16 * ld + 16, ld * 4);
}
inline void amx_zero_c_2x2() {
  _tile_zero(0);
  _tile_zero(1);
  _tile_zero(2);
  _tile_zero(3);
}

}  // namespace macro::detail
