// The element-wise Adam update of adam.h as a kernel per ISA path, each with the same double
// arithmetic in the same order and no fused multiply-add, so every path gives the scalar twin's
// bits (IEEE sqrt and division are correctly rounded in any vector width):
//   m = b1 m + (1 - b1) g;  v = b2 v + (1 - b2) g^2;  p -= step m / (sqrt(v) / bias2_sqrt + eps)
// Legend: n elements of one parameter group; m, v double [n]; g, p float [n].
#pragma once

#include <cstddef>

#include "attention/runtime/cpu.h"

namespace macro::gs::train {

struct AdamCoefficients {
  double beta1, one_minus_beta1, beta2, one_minus_beta2, step_size, bias2_sqrt, eps;
};
using AdamRowsFn = void (*)(double* m, double* v, const float* g, float* p, size_t n,
                            const AdamCoefficients& c);

void adam_rows_scalar(double* m, double* v, const float* g, float* p, size_t n,
                      const AdamCoefficients& c);
void adam_rows_avx512(double* m, double* v, const float* g, float* p, size_t n,
                      const AdamCoefficients& c);
// The kernel for a path (AVX-512 and above: adam_rows_avx512; else the scalar loop).
AdamRowsFn adam_rows_for(Isa isa);

}  // namespace macro::gs::train
