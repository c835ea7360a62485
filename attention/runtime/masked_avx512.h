// Loads and stores of up to 16 fp32 lanes under a mask, the whole-vector case by plain
// instructions: on the Zen 5 VM of 2026-12-06 a masked access of data streamed from L3 or memory
// cost more than a plain one (GroupNorm + SiLU ~30% faster, docs/PERFORMANCE.md). Include ONLY
// from files compiled with AVX-512 flags; internal linkage.
#pragma once

#include <immintrin.h>

#include <cstdint>

namespace macro {
namespace {

inline __m512 load_lanes(__mmask16 m, const float* p) {
  return m == __mmask16(0xffff) ? _mm512_loadu_ps(p) : _mm512_maskz_loadu_ps(m, p);
}

inline void store_lanes(float* p, __mmask16 m, __m512 v) {
  if (m == __mmask16(0xffff))
    _mm512_storeu_ps(p, v);
  else
    _mm512_mask_storeu_ps(p, m, v);
}

inline void store_lanes(uint32_t* p, __mmask16 m, __m512i v) {
  if (m == __mmask16(0xffff))
    _mm512_storeu_si512(p, v);
  else
    _mm512_mask_storeu_epi32(p, m, v);
}

}  // namespace
}  // namespace macro
