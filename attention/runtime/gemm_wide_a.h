// The widened A micro-panel of the shift-widened bf16 kernels (gemm_avx2.cpp, gemm_avx512.cpp):
// a packed A micro-panel of bf16 pair words [kc/2][MR], (even | odd << 16), split once into the
// exact fp32 values of its odd and of its even halves, each [kc/2][MR], so the micro-kernel
// broadcasts fp32 straight from memory (a load, no ALU work beside its FMAs) as the fp32 kernel
// does. One buffer per thread (scratch.h). The widening is a plain loop with internal linkage: each
// kernel file vectorizes it with its own ISA flags.
#pragma once

#include <bit>
#include <cstdint>

#include "attention/runtime/scratch.h"

namespace macro {
namespace {

struct WideA {
  detail::AlignedScratch mem;
  float* odd = nullptr;
  float* even = nullptr;
};

// The `words` pair words at a into w: odd[i] = the odd element of word i (its high half), even[i]
// the even one (its low half), both as exact fp32.
inline void widen_a_panel(const uint32_t* a, int64_t words, WideA& w) {
  const int64_t half = (words + 15) / 16 * 16;  // keeps `even` 64-byte aligned
  w.odd = static_cast<float*>(w.mem.get(size_t(2 * half) * sizeof(float)));
  w.even = w.odd + half;
  for (int64_t i = 0; i < words; ++i) {
    w.odd[i] = std::bit_cast<float>(a[i] & 0xffff0000u);
    w.even[i] = std::bit_cast<float>(a[i] << 16);
  }
}

}  // namespace
}  // namespace macro
