// The widened A micro-panel of the shift-widened bf16 kernels (gemm_avx2.cpp, gemm_avx512.cpp):
// a packed A micro-panel of bf16 pair words [kc/2][MR], (even | odd << 16), split once into the
// exact fp32 values of its odd and of its even halves, each [kc/2][MR], so the micro-kernel
// broadcasts fp32 straight from memory (a load, no ALU work beside its FMAs) as the fp32 kernel
// does. One buffer per thread, grown on demand, 64-byte aligned.
#pragma once

#include <cstdint>
#include <memory>

namespace macro::detail {

struct WideA {
  std::unique_ptr<float[]> mem;
  int64_t half = 0;  // floats per array
  float* odd = nullptr;
  float* even = nullptr;
  // Room for `words` pair words (both arrays).
  void reserve(int64_t words) {
    if (words <= half) return;
    half = (words + 15) / 16 * 16;
    mem.reset(new float[size_t(2 * half + 16)]);
    odd = reinterpret_cast<float*>((reinterpret_cast<uintptr_t>(mem.get()) + 63) &
                                   ~uintptr_t(63));
    even = odd + half;
  }
};

}  // namespace macro::detail
