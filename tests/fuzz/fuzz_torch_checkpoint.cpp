// libFuzzer target: macro::fuzz::torch_checkpoint (tests/fuzz/fuzz_targets.h), PyTorch zip
// checkpoints read from memory. Errors are expected; crashes, hangs, sanitizer reports, escaping
// exceptions and allocations beyond the input's own bytes are findings (docs/reliability.md).
// Seeds: the fixtures in data/fixtures/torch/ (tests/fixtures/make_torch_checkpoints.py):
//   build-fuzz/fuzz/fuzz_torch_checkpoint -max_len=65536 corpus-dir data/fixtures/torch
#include "attention/runtime/limits.h"
#include "tests/fuzz/fuzz_targets.h"

// A small per-tensor cap keeps expanded (stride 0) views from spending the run on copies.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  macro::ResourceLimits limits = macro::resource_limits();
  limits.max_tensor_bytes = 1u << 24;
  macro::set_resource_limits(limits);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  (void)macro::fuzz::torch_checkpoint(data, size);
  return 0;
}
