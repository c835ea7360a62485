// Compute precision of a network run, shared by every network.
//   kF32   the reference path (matches the float32/float64 goldens to rel L2 1e-4).
//   kBf16  bf16 weights and matmul/conv operands, fp32 accumulation, norms and softmax.
#pragma once

#include <string>

#include "attention/runtime/status.h"

namespace macro::nets {

enum class Precision { kF32, kBf16 };
Result<Precision> parse_precision(const std::string& name);  // "fp32" | "bf16"
const char* precision_name(Precision p);

}  // namespace macro::nets
