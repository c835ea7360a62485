// The element-wise Adam update of adam.h as a kernel per ISA path, each with the same float
// arithmetic in the same order and no fused multiply-add, so every path gives the scalar twin's
// bits (IEEE sqrt and division are correctly rounded in any vector width). The operations are
// torch's (Tensor.lerp_, mul_ + addcmul_, sqrt / + eps, addcdiv_), one rounding each:
//   m = m + (1 - b1) (g - m);  v = b2 v + ((1 - b2) g) g;
//   p = p + ((-step) m) / (sqrt(v) / bias2_sqrt + eps)
// Legend: n elements of one parameter group; m, v, g, p float [n].
#pragma once

#include <cstddef>

#include "attention/runtime/cpu.h"

namespace macro::gs::train {

// The step's constants, rounded to float once (step_size = lr / (1 - b1^t), bias2_sqrt =
// sqrt(1 - b2^t), computed in double).
struct AdamCoefficients {
  float one_minus_beta1, beta2, one_minus_beta2, step_size, bias2_sqrt, eps;
};
using AdamRowsFn = void (*)(float* m, float* v, const float* g, float* p, size_t n,
                            const AdamCoefficients& c);

void adam_rows_scalar(float* m, float* v, const float* g, float* p, size_t n,
                      const AdamCoefficients& c);
void adam_rows_avx512(float* m, float* v, const float* g, float* p, size_t n,
                      const AdamCoefficients& c);
// The kernel for a path (AVX-512 and above: adam_rows_avx512; else the scalar loop).
AdamRowsFn adam_rows_for(Isa isa);

}  // namespace macro::gs::train
