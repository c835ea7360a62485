// libFuzzer target: PyTorch zip checkpoints (attention/runtime/torch_checkpoint.h), read from memory
// with automatic selection and with an explicit key; every selected tensor is then converted to
// float32. Errors are expected; crashes, hangs, sanitizer reports, escaping exceptions and
// allocations beyond the input's own bytes are findings (docs/reliability.md).
// Seeds: the fixtures in data/fixtures/torch/ (tests/fixtures/make_torch_checkpoints.py):
//   build-fuzz/fuzz/fuzz_torch_checkpoint -max_len=65536 corpus-dir data/fixtures/torch
#include <cstdint>
#include <vector>

#include "attention/runtime/limits.h"
#include "attention/runtime/torch_checkpoint.h"

namespace {

void read_all(const uint8_t* data, size_t size, const char* key) {
  auto r = macro::read_torch_checkpoint_from_memory(data, size, "fuzz.pth", key);
  if (!r.is_ok()) return;
  std::vector<float> out;
  for (const macro::TensorEntry& e : r->tensors) {
    out.resize(e.bytes / macro::dtype_size(e.dtype));
    (void)macro::convert_to_f32(e, out.data(), out.size());
  }
}

}  // namespace

// A small per-tensor cap keeps expanded (stride 0) views from spending the run on copies.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  macro::ResourceLimits limits = macro::resource_limits();
  limits.max_tensor_bytes = 1u << 24;
  macro::set_resource_limits(limits);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  read_all(data, size, "");
  read_all(data, size, "params");
  return 0;
}
