#include "attention/nets/precision.h"

namespace macro::nets {

Result<Precision> parse_precision(const std::string& name) {
  if (name == "fp32") return Precision::kF32;
  if (name == "bf16") return Precision::kBf16;
  return Status::error("precision: expected fp32 or bf16, found '" + name + "'");
}

const char* precision_name(Precision p) { return p == Precision::kF32 ? "fp32" : "bf16"; }

}  // namespace macro::nets
